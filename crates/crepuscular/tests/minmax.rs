//! `minmax` against what it must equal (docs/MODEL.md §8): the closed form on an occluder-free
//! frame at any map size and number of levels; a dense march through the standard shadow map on
//! a shadowed one (exact at the standard map's resolution); its GPU passes against the CPU
//! mirror, pass by pass; and its settings' errors.

mod common;

use crepuscular::frame::FrameDesc;
use crepuscular::gpu::{UploadedFrame, test_gpu};
use crepuscular::march::LocalSteps;
use crepuscular::march::StepPolicy;
use crepuscular::model::segment_transmittance;
use crepuscular::techniques::AnyGpuTechnique;
use crepuscular::techniques::minmax::{MinmaxSettings, cpu};
use crepuscular::testing::{gpu_render, half_plane_frame, wall_closed_form, wall_frame, wall_media};
use crepuscular::{Image, Light, TechniqueSettings};
use glam::Vec3;

const W: u32 = 64;
const H: u32 = 36;

use common::{cpu_frame, sun};

fn closed_form(desc: &FrameDesc) -> Image {
    common::image_of(W, H, |x, y| wall_closed_form(desc, x, y))
}

fn settings(map: [u32; 2], levels: u32) -> MinmaxSettings {
    MinmaxSettings { map_size: map, levels, ..Default::default() }
}

/// With no occluder every ray is one lit span from the camera to the wall, integrated in
/// closed form: the closed form at any map size and number of levels, up to f32 rounding.
#[test]
fn an_unshadowed_sun_is_the_closed_form_at_any_map_size() {
    for m in wall_media() {
        let (d, depth, sm) = wall_frame(sun(), m.clone(), W, H);
        let exact = closed_form(&d);
        for (map, levels) in [([8, 8], 0), ([64, 16], 6), ([1024, 1024], 13)] {
            let (img, _) = cpu::render_with(&cpu_frame(&d, &depth, &sm), &settings(map, levels), None).unwrap();
            let e = common::max_rel(&img, &exact, 1e-9);
            assert!(e < 1e-4, "{m:?}, map {map:?}, {levels} levels: off the closed form by {e}");
        }
    }
}

#[test]
fn an_unshadowed_sun_is_the_closed_form_on_the_gpu() {
    let Some(gpu) = test_gpu("an_unshadowed_sun_is_the_closed_form_on_the_gpu") else { return };
    for m in wall_media() {
        let (d, depth, sm) = wall_frame(sun(), m.clone(), W, H);
        let exact = closed_form(&d);
        for (map, levels) in [([8, 8], 0), ([256, 64], 13)] {
            let s = TechniqueSettings::Minmax(settings(map, levels));
            let img = common::gpu_technique(&gpu, &cpu_frame(&d, &depth, &sm), s);
            let e = common::max_rel(&img, &exact, 1e-9);
            assert!(e < 1e-3, "{m:?}, map {map:?}: GPU off the closed form by {e}");
        }
    }
}

/// A point light with no occluder: the quadrature over the ray's lit interval converges as its
/// segments grow (the light is evaluated once per segment, transmittance exactly).
#[test]
fn an_unshadowed_point_light_converges_with_its_segments() {
    let lamp = Light::Point { position: Vec3::new(0.0, 12.0, -14.0), color: Vec3::new(1.0, 0.8, 0.6), intensity: 50.0 };
    let m = wall_media()[0].clone();
    let (d, depth, sm) = wall_frame(lamp, m, W, H);
    let frame = cpu_frame(&d, &depth, &sm);
    // Each layout against its own 1024-segment answer. Equal steps converge fastest on this
    // smooth frame; equal angles (the default) put their segments where the ray passes the
    // light and are coarser far from it, so the worst pixel converges more slowly
    // (docs/MODEL.md §9). Measured at 64 segments: uniform 1.2e-4, equiangular 4.0e-3.
    for (local, bound) in [(LocalSteps::Uniform, 3e-4), (LocalSteps::Equiangular, 1e-2)] {
        let s = |n: u32| MinmaxSettings {
            policy: StepPolicy { local: local, ..Default::default() },
            light_steps: n,
            ..settings([256, 256], 13)
        };
        let (fine, _) = cpu::render_with(&frame, &s(1024), None).unwrap();
        let mut last = f32::MAX;
        for steps in [4, 16, 64] {
            let (img, _) = cpu::render_with(&frame, &s(steps), None).unwrap();
            let e = common::max_rel(&img, &fine, 1e-9);
            eprintln!("{local:?}, {steps} segments: {e}");
            assert!(e < last, "{local:?}: the error must fall with more segments: {e} after {last}");
            last = e;
        }
        assert!(last < bound, "{local:?}, 64 segments: {last}");
    }
}

/// On a shadowed frame (a sun over a half-plane), every pixel equals a dense march of its own
/// ray through the standard shadow map — each of 20 000 steps makes the reference's test
/// (`ShadowMap::visibility` at its midpoint) —, i.e. minmax is exact at the standard map's
/// resolution: its rectified map (coarser here than the standard map, 256 columns against 512)
/// only bounds the texels (conservative level 0), and the rays a texel leaves undecided are
/// resolved against the standard map in closed form. The tree changes nothing (levels 0 and 8
/// give the same picture).
#[test]
fn a_shadowed_frame_equals_a_dense_march_through_the_standard_map() {
    let m = wall_media()[1].clone();
    let (d, depth, sm, _) = half_plane_frame(m, 48, 27, 512);
    let frame = cpu_frame(&d, &depth, &sm);
    let s = MinmaxSettings { epipole_radius: 0, ..settings([256, 128], 8) };
    let (p, _) = cpu::passes(&frame, &s, None).unwrap();
    let (flat, _) = cpu::passes(&frame, &MinmaxSettings { levels: 0, ..s.clone() }, None).unwrap();
    assert_eq!(p.image.pixels, flat.image.pixels, "the tree must not change the answer");
    eprintln!("tree {} nodes, linear {}, mixed {}", p.totals.nodes, flat.totals.nodes, p.totals.mixed);
    assert!(p.totals.nodes < flat.totals.nodes / 3, "tree {} nodes, linear {}", p.totals.nodes, flat.totals.nodes);
    assert!(p.totals.mixed > 0, "the edge must leave texels mixed");
    // The `nodes` debug view counts exactly the walks the frame made.
    assert_eq!(p.nodes.iter().map(|&n| n as u64).sum::<u64>(), p.totals.nodes);
    assert_eq!(p.nodes.iter().copied().max(), Some(p.totals.max_nodes));
    let st = d.medium.extinction();
    let fl = &d.lights[0];
    let (l_in, wl) = crepuscular::integrand::light_incident(fl, &d.medium, d.camera.position);
    let (mut worst, mut shadowed_pixels) = (0.0f32, 0);
    for y in (0..27).step_by(2) {
        for x in (0..48).step_by(3) {
            let dir = d.pixel_ray(x, y);
            let s_end = d.view_distance(depth[(y * 48 + x) as usize], dir);
            let f = d.medium.scattering * d.medium.phase.eval(wl.dot(-dir)) * l_in;
            let n = 20_000;
            let delta = s_end / n as f32;
            let mut sum = Vec3::ZERO;
            let mut dark = 0;
            for i in 0..n {
                let t = (i as f32 + 0.5) * delta;
                if sm.visibility(Vec3::ZERO, d.camera.position + dir * t, fl.shadow_bias, fl.shadow_filter) > 0.0 {
                    sum += f * (-st * (i as f32 * delta)).exp() * segment_transmittance(st, delta);
                } else {
                    dark += 1;
                }
            }
            shadowed_pixels += (dark > n / 10) as u32;
            let got = p.image.pixels[(y * 48 + x) as usize];
            let scale = f.max_element() * segment_transmittance(st, s_end).max_element();
            let e = (0..3).map(|k| (got[k] - sum[k]).abs() / scale).fold(0.0, f32::max);
            worst = worst.max(e);
        }
    }
    eprintln!("worst {worst} of the unshadowed radiance over {shadowed_pixels} shadowed rays");
    assert!(shadowed_pixels > 20, "the frame must have shadowed rays: {shadowed_pixels}");
    assert!(worst < 5e-4, "off the dense march through the standard map by {worst} of the unshadowed radiance");
}

/// Level 0 is conservative: for every rectified texel, each of 8×8 light lines spread over its
/// patch finds its occluder in the standard map (pass `rectify`'s lookup) at a rectified depth
/// inside the texel's bounds (1 where the line has none).
#[test]
fn level_zero_bounds_every_line_through_its_texel() {
    use crepuscular::techniques::prefiltered::rectify::line_occluder;
    let m = wall_media()[0].clone();
    let (d, depth, sm, _) = half_plane_frame(m, 48, 27, 512);
    let frame = cpu_frame(&d, &depth, &sm);
    let s = settings([64, 32], 6);
    let rect = crepuscular::techniques::prefiltered::Rectification::new(&d, &s.rectify_options());
    let tree = cpu::build(&frame, &rect, None, 6);
    let (mut mixed, mut outside) = (0, 0);
    for row in 0..rect.height {
        for col in 0..rect.width {
            let [lo, hi] = tree[(row * 2 * rect.width + col) as usize];
            mixed += (lo < hi) as u32;
            for k in 0..64 {
                let (c, r) = (col as f32 + (k % 8) as f32 / 7.0, row as f32 + (k / 8) as f32 / 7.0);
                let (p, dir) = rect.texel_line(c, r);
                let z = line_occluder(&sm, Vec3::ZERO, p, dir, d.lights[0].shadow_bias)
                    .map_or(1.0, |o| rect.occluder_depth(c, o));
                if !(lo - 1e-5 <= z && z <= hi + 1e-5) {
                    outside += 1;
                    eprintln!("texel ({col}, {row}) [{lo}, {hi}]: line ({c}, {r}) at {z}");
                }
            }
        }
    }
    assert!(mixed > 0, "the edge must make some texels mixed");
    assert_eq!(outside, 0, "lines outside their texel's bounds");
}

/// The GPU passes against the CPU mirror: the tree's bounds (read from the standard map on
/// each side) agree node for node up to f32 rounding where a footprint's edge meets a texel's;
/// the picture and the walk counts agree up to f32 rounding where a texel's depth meets a ray's.
#[test]
fn the_gpu_passes_mirror_the_cpu() {
    let Some(gpu) = test_gpu("the_gpu_passes_mirror_the_cpu") else { return };
    let m = wall_media()[1].clone();
    let (d, depth, sm, _) = half_plane_frame(m, 96, 54, 512);
    let frame = cpu_frame(&d, &depth, &sm);
    let s = settings([256, 128], 13);
    let (p, _) = cpu::passes(&frame, &s, None).unwrap();
    let up = UploadedFrame::new(&gpu, &frame).unwrap();
    let out = gpu.create_output_texture(96, 54);
    let (sc, stats) =
        gpu_render(&gpu, TechniqueSettings::Minmax(s.clone()), &up.frame(&d), &out.create_view(&Default::default()))
            .unwrap();
    let AnyGpuTechnique::Minmax(t) = sc.technique() else { panic!("not minmax") };
    let g_tree = t.read_tree(&gpu).unwrap();
    assert_eq!(g_tree.len(), p.tree.len());
    let off =
        g_tree.iter().zip(&p.tree).filter(|(a, b)| (a[0] - b[0]).abs() > 1e-4 || (a[1] - b[1]).abs() > 1e-4).count();
    eprintln!("{off} of {} tree nodes differ by more than 1e-4", g_tree.len());
    assert!(off * 1000 < g_tree.len(), "{off} of {} tree nodes differ", g_tree.len());
    let img = gpu.read_image(&out).unwrap();
    let peak = p.image.pixels.iter().map(|q| q[1]).fold(0.0f32, f32::max);
    let bad = img.pixels.iter().zip(&p.image.pixels).filter(|(a, b)| (a[1] - b[1]).abs() > 1e-3 * peak).count();
    assert!(bad * 100 < img.pixels.len(), "{bad} pixels differ by more than 0.1 % of the peak");
    let nodes = stats.extra["nodes_per_ray"];
    let cpu_nodes = p.totals.nodes as f64 / p.totals.rays as f64;
    assert!((nodes - cpu_nodes).abs() < 0.01 * cpu_nodes, "GPU {nodes} nodes per ray, CPU {cpu_nodes}");
    let mixed = stats.extra["mixed_texels_per_ray"];
    let cpu_mixed = p.totals.mixed as f64 / p.totals.rays as f64;
    assert!(
        cpu_mixed > 0.0 && (mixed - cpu_mixed).abs() < 0.02 * cpu_mixed,
        "GPU {mixed} mixed texels per ray, CPU {cpu_mixed}"
    );
    assert_eq!(stats.extra["rays"], p.totals.rays as f64);
}

/// Bad settings are refused with the setting and value named.
#[test]
fn bad_settings_name_the_setting() {
    for (s, key) in [
        (MinmaxSettings { map_size: [1000, 512], ..Default::default() }, "minmax.map_size"),
        (MinmaxSettings { map_size: [1024, 4], ..Default::default() }, "minmax.map_size"),
        (MinmaxSettings { levels: 14, ..Default::default() }, "minmax.levels"),
        (MinmaxSettings { max_nodes: 0, ..Default::default() }, "minmax.max_nodes"),
        (MinmaxSettings { light_steps: 0, ..Default::default() }, "minmax.light_steps"),
        (MinmaxSettings { max_projective_angle: f32::NAN, ..Default::default() }, "minmax.max_projective_angle"),
        (
            MinmaxSettings { policy: StepPolicy { denominator: -1.0, ..Default::default() }, ..Default::default() },
            "minmax.spot_denominator",
        ),
    ] {
        let e = s.validate().unwrap_err().to_string();
        assert!(e.contains(key), "{e}");
    }
    assert!(MinmaxSettings::default().validate().is_ok());
    use crepuscular::techniques::epipolar::EpipolarSettings;
    let e = EpipolarSettings { minmax_map_size: [100, 64], ..Default::default() }.validate().unwrap_err().to_string();
    assert!(e.contains("epipolar.minmax_map_size") && e.contains("[100, 64]"), "{e}");
}

/// `epipolar` with `march = "minmax"`: its samples walk the tree (Yusov 2013). On the shadowed
/// frame the GPU agrees with the CPU mirror, and against the exact image it does at least as
/// well as its stepped march at the default 64 steps (its samples have no step error).
#[test]
fn epipolar_with_the_minmax_march_mirrors_and_beats_its_steps() {
    use crepuscular::techniques::epipolar::{EpipolarMarch, EpipolarSettings, cpu as ecpu};
    let m = wall_media()[1].clone();
    let (w, h) = (96, 54);
    let (d, depth, sm, plane) = half_plane_frame(m, w, h, 1024);
    let frame = cpu_frame(&d, &depth, &sm);
    let exact = common::image_of(w, h, |x, y| plane.closed_form(&d, x, y));
    let peak = exact.pixels.iter().map(|p| p[1]).fold(0.0f32, f32::max);
    let mean_err = |img: &Image| {
        img.pixels.iter().zip(&exact.pixels).map(|(a, b)| (a[1] - b[1]).abs()).sum::<f32>()
            / img.pixels.len() as f32
            / peak
    };
    let stepped = EpipolarSettings::default();
    let walked = EpipolarSettings { march: EpipolarMarch::Minmax, ..Default::default() };
    let (img_steps, _) = ecpu::render(&frame, &stepped).unwrap();
    let (img_walk, stats) = ecpu::render(&frame, &walked).unwrap();
    let names: Vec<_> = stats.passes.iter().map(|p| p.name.as_str()).collect();
    assert!(names.contains(&"build") && !names.contains(&"rectify"), "{names:?}");
    let (e_steps, e_walk) = (mean_err(&img_steps), mean_err(&img_walk));
    eprintln!("mean error / peak: steps {e_steps:.5}, min-max march {e_walk:.5}");
    assert!(e_walk <= e_steps * 1.05, "the min-max march ({e_walk}) is worse than 64 steps ({e_steps})");
    let Some(gpu) = test_gpu("epipolar_with_the_minmax_march_mirrors_and_beats_its_steps") else { return };
    let g = common::gpu_technique(&gpu, &frame, TechniqueSettings::Epipolar(walked));
    let bad = g.pixels.iter().zip(&img_walk.pixels).filter(|(a, b)| (a[1] - b[1]).abs() > 1e-3 * peak).count();
    assert!(bad * 100 < g.pixels.len(), "{bad} pixels differ by more than 0.1 % of the peak between GPU and CPU");
}
