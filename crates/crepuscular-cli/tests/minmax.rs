//! `minmax` on the built-in scenes through the tool's render path: quality against `reference`
//! with thresholds from the measured table (docs/quality.toml), the projective map on a
//! side-lit sun (host-rasterized under the nearest filter), and the walk's cost per scene (nodes per ray) on both backends.

use crepuscular::frame::surface_transmittance;
use crepuscular::gpu::{GpuContext, test_gpu};
use crepuscular::techniques::reference::ReferenceSettings;
use crepuscular::tonemap::{ToneMap, composite};
use crepuscular::{Light, TechniqueSettings};
use crepuscular_cli::metrics::compare;
use crepuscular_cli::render::{RenderOptions, parse_technique, render};
use crepuscular_scene::{Scene, builtin};
use glam::Vec3;

fn scene_at(name: &str) -> Scene {
    let mut s = builtin::builtin(name).expect("built-in scene");
    s.render.width = 160;
    s.render.height = 90;
    s.render.shadow.size = 1024;
    s
}

/// The scene with its sun turned to the side of the view: the projective map, rasterized by
/// the host (Klehm et al. 2014 §4.2).
fn side_lit(mut scene: Scene) -> Scene {
    let Light::Directional { color, intensity, .. } = scene.lights[0].light.clone() else { panic!("not a sun") };
    let f = scene.camera.look_at - scene.camera.position;
    let right = Vec3::new(f.x, 0.0, f.z).normalize().cross(Vec3::Y);
    scene.lights[0].light = Light::Directional { direction: (right - Vec3::Y * 0.45).normalize(), color, intensity };
    scene.name = format!("{} (side-lit)", scene.name);
    scene
}

fn quality(backend: &str, gpu: Option<&GpuContext>) {
    let mut failures = vec![];
    let mut scenes: Vec<Scene> = builtin::one_light_names().iter().map(|n| scene_at(n)).collect();
    scenes.push(side_lit(scene_at("terrain")));
    // … and under the nearest filter, where the walk reads the host's rectified raster.
    let mut nearest = side_lit(scene_at("terrain"));
    nearest.render.shadow.filter = crepuscular::ShadowFilter::Nearest;
    nearest.name = "terrain (side-lit, nearest)".into();
    scenes.push(nearest);
    for scene in scenes {
        let opts = |technique| RenderOptions { technique, progress: &|_, _| {} };
        // On the backend's own host frame (the GPU host's depth and shadow maps for "gpu": the
        // CPU reference runs over the maps the GPU drew), so a row measures the technique,
        // not the two hosts' rasterization.
        let reference =
            render(&scene, gpu, &opts(TechniqueSettings::Reference(ReferenceSettings { steps: 512, seed: 1 })))
                .unwrap();
        // The side-lit sun: the projective map (auto keeps the built-in scenes' deep frusta on the
        // epipolar one, see `max_projective_depth_ratio`).
        let set =
            if scene.name.contains("side-lit") { vec!["rectification=\"projective\"".to_string()] } else { vec![] };
        let settings = parse_technique("minmax", &scene, &set).unwrap();
        let out = render(&scene, gpu, &opts(settings)).unwrap();
        assert!(out.inscatter.all_finite(), "{}", scene.name);
        let tone = ToneMap::new(scene.render.exposure);
        let psnr = compare(&reference.inscatter, &out.inscatter, &tone).unwrap().psnr_db;
        let t = surface_transmittance(&scene.frame_desc().unwrap(), &reference.depth);
        let flip = compare(
            &composite(&reference.surface, &reference.inscatter, &t),
            &composite(&reference.surface, &out.inscatter, &t),
            &tone,
        )
        .unwrap()
        .flip_mean;
        let x = &out.stats.technique.extra;
        eprintln!(
            "{backend} {}: PSNR {psnr:.2} dB, FLIP {flip:.4}; {} map, nodes per ray {:.1} (max {}), lit {:.1}, shadowed {:.1}, over budget {}",
            scene.name,
            if x["projective"] == 1.0 { "projective" } else { "epipolar" },
            x["nodes_per_ray"],
            x["max_nodes_per_ray"],
            x["lit_nodes_per_ray"],
            x["shadowed_nodes_per_ray"],
            x["rays_over_budget"]
        );
        assert_eq!(x["rays_over_budget"], 0.0, "{}: the default budget is never reached here", scene.name);
        assert!(x["nodes_per_ray"] >= 1.0 && x["rays"] > 0.0, "{}: no walk counted", scene.name);
        if scene.name.contains("side-lit") {
            // The host's rectified raster is the nearest test at the rectified resolution: it
            // is used under the nearest filter only (`minmax::reads_host_raster`).
            let nearest = scene.render.shadow.filter == crepuscular::ShadowFilter::Nearest;
            assert_eq!((x["projective"], x["host_rasterized"]), (1.0, nearest as u32 as f64), "{}", scene.name);
        }
        if let Err(e) = crepuscular_cli::quality::check("minmax", &scene.name, backend, psnr, flip) {
            failures.push(format!("{e:#}"));
        }
    }
    assert!(failures.is_empty(), "{backend}: {failures:#?}");
}

#[test]
fn minmax_vs_reference_on_every_builtin_scene_cpu() {
    quality("cpu", None);
}

#[test]
fn minmax_vs_reference_on_every_builtin_scene_gpu() {
    let Some(gpu) = test_gpu("minmax_vs_reference_on_every_builtin_scene_gpu") else { return };
    quality("gpu", Some(&gpu));
}
