//! The engine's camera: the same view with a standard [0, 1] projection and with a reversed-Z
//! infinite one (each depth buffer rendered accordingly, by the GPU host and by the CPU
//! rasterizer) gives the same in-scattering for every technique, GPU and CPU, up to the
//! rounding of the two depth buffers; and a projection jittered by one pixel shifts the image
//! by exactly one pixel (the per-pixel techniques).

use crepuscular::frame::FrameDesc;
use crepuscular::gpu::{GpuContext, test_gpu};
use crepuscular::{CpuFrame, DepthConvention, FrameCamera, Image, TechniqueSettings};
use crepuscular_cli::render::{frame_desc, parse_technique, render_cpu, render_gpu, scattering};
use crepuscular_scene::{GpuHost, Scene, builtin, host, host_cpu};
use glam::{Mat4, Vec3};

fn small(name: &str) -> Scene {
    let mut s = builtin::builtin(name).expect("built-in scene");
    s.render.width = 96;
    s.render.height = 54;
    s.render.shadow.size = 256;
    s
}

/// The scene's view through a reversed-Z infinite projection (the medium still ends at the
/// scene camera's far distance).
fn reversed(scene: &Scene, desc: &FrameDesc) -> FrameDesc {
    let c = &scene.camera;
    let proj = Mat4::perspective_infinite_reverse_rh(c.fov_y_degrees.to_radians(), desc.aspect(), c.near);
    let camera = FrameCamera::new(c.view(), proj, DepthConvention::Reversed, Some(c.far)).unwrap();
    FrameDesc { camera, ..desc.clone() }
}

/// The standard projection shifted right by `pixels` (as a TAA jitter is applied).
fn jittered(desc: &FrameDesc, pixels: f32) -> FrameDesc {
    let shift = Mat4::from_translation(Vec3::new(2.0 * pixels / desc.width as f32, 0.0, 0.0));
    let c = &desc.camera;
    let camera = FrameCamera::new(c.view, shift * c.projection, c.depth, Some(c.far)).unwrap();
    FrameDesc { camera, ..desc.clone() }
}

fn techniques(scene: &Scene) -> Vec<TechniqueSettings> {
    let list = [
        ("brute-force", &["steps=32"][..]),
        ("interleaved", &["steps=32"]),
        ("subsampled", &["steps=32"]),
        ("epipolar", &["slices=64", "samples=64"]),
        ("prefiltered", &["map_size=[128, 128]"]),
        ("minmax", &["map_size=[128, 128]"]),
        ("reference", &["steps=64"]),
    ];
    // Every registered technique is here: a new one fails this test until it is given settings.
    for info in crepuscular::techniques::TECHNIQUES.iter() {
        assert!(list.iter().any(|(t, _)| *t == info.name), "no test settings for `{}`", info.name);
    }
    list.iter()
        .map(|(t, set)| parse_technique(t, scene, &set.iter().map(|s| s.to_string()).collect::<Vec<_>>()).unwrap())
        .collect()
}

/// The GPU host's frame for `desc`, the technique's in-scattering and the depth buffer.
fn gpu_frame(gpu: &GpuContext, scene: &Scene, desc: &FrameDesc, settings: &TechniqueSettings) -> (Image, Vec<f32>) {
    let host = GpuHost::for_scene(gpu, scene).unwrap();
    let tex = host.render(gpu, desc).unwrap();
    let depth = gpu.read_texture_f32(&tex.depth, 0).unwrap();
    let img = match scattering(gpu, settings).unwrap() {
        Some(mut sc) => {
            let out = gpu.create_output_texture(desc.width, desc.height);
            let views = tex.views();
            render_gpu(&mut sc, Some(&host), &views.frame(desc), &out.create_view(&Default::default())).unwrap();
            gpu.read_image(&out).unwrap()
        }
        None => {
            let surface = gpu.read_image(&tex.surface).unwrap();
            let sm = host::read_shadow_maps(gpu, &tex, desc).unwrap();
            let frame = CpuFrame { desc, depth: &depth, shadow_maps: &sm, surface: Some(&surface) };
            render_cpu(settings, &frame, Some(&scene.geometry), &|_, _| {}).unwrap().0
        }
    };
    (img, depth)
}

fn cpu_frame(scene: &Scene, desc: &FrameDesc, settings: &TechniqueSettings) -> (Image, Vec<f32>) {
    let h = host_cpu::render(&scene.geometry, &scene.shading(), desc);
    let frame = CpuFrame { desc, depth: &h.depth, shadow_maps: &h.shadow_maps, surface: Some(&h.surface) };
    (render_cpu(settings, &frame, Some(&scene.geometry), &|_, _| {}).unwrap().0, h.depth)
}

/// Relative differences of the luminance of `a` against `b` (floored at 0.1 % of `b`'s peak):
/// (share of pixels off by more than 1 %, 99th percentile, max). Panics on a black `b`.
fn differences(a: &Image, b: &Image) -> (f64, f64, f64) {
    let lum = |p: &[f32; 4]| 0.2126 * p[0] as f64 + 0.7152 * p[1] as f64 + 0.0722 * p[2] as f64;
    let peak = b.pixels.iter().map(lum).fold(0.0, f64::max);
    assert!(peak > 1e-3, "a black frame");
    let mut d: Vec<f64> =
        a.pixels.iter().zip(&b.pixels).map(|(p, q)| (lum(p) - lum(q)).abs() / lum(q).max(1e-3 * peak)).collect();
    d.sort_by(f64::total_cmp);
    let over = d.iter().filter(|&&x| x > 1e-2).count() as f64 / d.len() as f64;
    (over, d[d.len() * 99 / 100], *d.last().unwrap())
}

#[test]
fn reversed_z_infinite_projection_gives_the_standard_in_scattering() {
    let gpu = test_gpu("reversed_z_infinite_projection_gives_the_standard_in_scattering");
    for scene_name in ["colonnade", "cage", "stained-glass"] {
        let scene = small(scene_name);
        let standard = frame_desc(&scene).unwrap();
        let rev = reversed(&scene, &standard);
        assert_eq!(rev.camera.far, standard.camera.far);
        assert!((rev.camera.near - standard.camera.near).abs() < 1e-5);
        for settings in techniques(&scene) {
            let name = settings.name();
            let mut runs = vec![("cpu", cpu_frame(&scene, &standard, &settings), cpu_frame(&scene, &rev, &settings))];
            if let Some(gpu) = &gpu {
                runs.push((
                    "gpu",
                    gpu_frame(gpu, &scene, &standard, &settings),
                    gpu_frame(gpu, &scene, &rev, &settings),
                ));
            }
            for (backend, (a, da), (b, db)) in runs {
                // The depth buffers differ (reversed-Z keeps far depths precise); empty pixels
                // hold each convention's clear value.
                assert!(da.contains(&1.0) && db.contains(&0.0), "{scene_name}: no sky in the frame");
                assert!(a.all_finite() && b.all_finite());
                let (over, p99, max) = differences(&b, &a);
                eprintln!(
                    "{scene_name} {name} {backend}: reversed-Z infinite vs standard: {:.2} % of pixels off by > 1 %, p99 {p99:.1e}, max {max:.1e}",
                    100.0 * over
                );
                // The frames are the same up to the two depth buffers' rounding (a standard
                // f32 depth buffer holds far view distances to ~1e-4): measured on llvmpipe and
                // the CPU, 99 % of pixels within 2.5e-4 (1.0e-3 for epipolar on the CPU's cage).
                // At silhouettes a depth-weighted upsampler, a discontinuity test or a shadow
                // edge may take the other side for a rare pixel: measured at most 0.69 % of the
                // pixels off by more than 1 % (subsampled, llvmpipe, colonnade). Bounds: 3× that.
                assert!(p99 < 3e-3, "{scene_name} {name} {backend}: 99th percentile {p99}");
                assert!(over < 2e-2, "{scene_name} {name} {backend}: {over} of the pixels off by > 1 %");
            }
        }
    }
}

#[test]
fn a_projection_jittered_by_whole_pixels_shifts_the_image_by_them() {
    let gpu = test_gpu("a_projection_jittered_by_whole_pixels_shifts_the_image_by_them");
    for scene_name in ["colonnade", "stained-glass"] {
        let scene = small(scene_name);
        let desc = frame_desc(&scene).unwrap();
        // The per-pixel march by one pixel; the screen-space patterns by their period (the
        // interleaving block M, the subsampling factor f: their patterns are fixed to the
        // screen, so only a shift by whole periods moves the same samples onto the same
        // content). The reference's stratified samples are seeded per pixel, so a shifted
        // pixel draws other samples; epipolar's lines end on the screen's border and the
        // rectifications follow the view frustum, so their samples move with a jitter.
        for (t, set, pixels) in
            [("brute-force", "steps=32", 1u32), ("interleaved", "block=4", 4), ("subsampled", "factor=4", 4)]
        {
            let shifted = jittered(&desc, pixels as f32);
            let settings = parse_technique(t, &scene, &["steps=32".to_string(), set.to_string()]).unwrap();
            let mut runs =
                vec![("cpu", cpu_frame(&scene, &desc, &settings).0, cpu_frame(&scene, &shifted, &settings).0)];
            if let Some(gpu) = &gpu {
                runs.push((
                    "gpu",
                    gpu_frame(gpu, &scene, &desc, &settings).0,
                    gpu_frame(gpu, &scene, &shifted, &settings).0,
                ));
            }
            for (backend, a, b) in runs {
                let (w, h, k) = (desc.width, desc.height, pixels);
                // b(x + k, y) = a(x, y), away from the side borders by one period, where the
                // patterns' windows and grids are clamped to the image.
                let m = if k > 1 { k } else { 0 };
                let cols = w - k - 2 * m;
                let mut left = Image::new(cols, h);
                let mut right = Image::new(cols, h);
                for y in 0..h {
                    for i in 0..cols {
                        let x = m + i;
                        left.pixels[(y * cols + i) as usize] = a.pixels[(y * w + x) as usize];
                        right.pixels[(y * cols + i) as usize] = b.pixels[(y * w + x + k) as usize];
                    }
                }
                let (over, p99, max) = differences(&right, &left);
                let (unshifted, _, _) = differences(&b, &a);
                eprintln!(
                    "{scene_name} {t} {backend}: jittered by {k} pixel(s) vs shifted back: {:.2} % of pixels off by > 1 %, p99 {p99:.1e}, max {max:.1e} (not shifted back: {:.1} % off)",
                    100.0 * over,
                    100.0 * unshifted
                );
                // The CPU host rasterizes the shifted view to the same depths; the GPU's
                // rasterizer snaps the shifted vertices to its sub-pixel grid, so a silhouette
                // pixel's depth may differ. Brute-force sees that pixel alone; subsampled's
                // depth-compatibility test may then blend a different set of grid samples
                // around it. Bounds: brute-force and interleaved (and every CPU run) 1e-3 at
                // the 99th percentile and 0.5 % of pixels; subsampled on the GPU, measured on
                // llvmpipe (colonnade 1.6 % of pixels, p99 2.0e-2), 2.5× that.
                let (p99_max, over_max) =
                    if t == "subsampled" && backend == "gpu" { (5e-2, 4e-2) } else { (1e-3, 5e-3) };
                assert!(p99 < p99_max && over < over_max, "{scene_name} {t} {backend}: p99 {p99}, {over} off by > 1 %");
                // And the jitter did move the image (so the comparison above can fail).
                assert!(unshifted > 0.02, "{scene_name} {t} {backend}: the jitter moved nothing ({unshifted})");
            }
        }
    }
}

/// The frame with its shadow map in the reversed-Z convention: each layer's world → clip matrix
/// followed by z ↦ w − z (the light's projection with near and far swapped: d ↦ 1 − d).
fn reversed_shadows(desc: &FrameDesc) -> FrameDesc {
    let flip = Mat4::from_cols(
        glam::Vec4::X,
        glam::Vec4::Y,
        glam::Vec4::new(0.0, 0.0, -1.0, 0.0),
        glam::Vec4::new(0.0, 0.0, 1.0, 1.0),
    );
    let mut d = desc.clone();
    d.lights[0].shadow.view_proj = d.lights[0].shadow.view_proj.map(|m| flip * m);
    d.lights[0].shadow.depth = DepthConvention::Reversed;
    d
}

#[test]
fn reversed_z_shadow_maps_give_the_standard_in_scattering() {
    let gpu = test_gpu("reversed_z_shadow_maps_give_the_standard_in_scattering");
    for scene_name in ["colonnade", "cage", "stained-glass"] {
        let scene = small(scene_name);
        let standard = frame_desc(&scene).unwrap();
        let rev = reversed_shadows(&standard);
        for settings in techniques(&scene) {
            let name = settings.name();
            let (a, _) = cpu_frame(&scene, &standard, &settings);
            let (b, _) = cpu_frame(&scene, &rev, &settings);
            let mut runs = vec![("cpu", a, b)];
            if let Some(gpu) = &gpu {
                runs.push((
                    "gpu",
                    gpu_frame(gpu, &scene, &standard, &settings).0,
                    gpu_frame(gpu, &scene, &rev, &settings).0,
                ));
            }
            for (backend, a, b) in runs {
                let (over, p99, max) = differences(&b, &a);
                eprintln!(
                    "{scene_name} {name} {backend}: reversed-Z shadow map vs standard: {:.2} % of pixels off by > 1 %, p99 {p99:.1e}, max {max:.1e}",
                    100.0 * over
                );
                // The binary shadow tests give identical pixels (measured: 0 difference for
                // every technique but prefiltered and minmax). Prefiltered filters the stored depths
                // themselves, so it sees the standard map's rounding (most likely: a perspective
                // map's depths near its far plane round to the clear value 1 and read as "no
                // occluder", where the reversed map keeps them — not verified texel by texel). Measured on stained-glass
                // (the spot): p99 1.4e-2 and 1.37 % of pixels off by > 1 % on llvmpipe, 2.8e-3
                // and 0.10 % on the CPU; elsewhere ≤ 7.3e-4 and 0 %. Bounds: 2–3× that.
                // minmax solves its span ends in closed form from the stored depths (its level-0
                // bounds and each mixed texel's lit interval), so the two conventions' rounding
                // moves them slightly: measured p99 ≤ 8.3e-6 and no pixel off by > 1 % (CPU
                // and llvmpipe, 2026-12-02; cage on llvmpipe the worst). Bound: 6× that.
                let (p99_bound, over_bound) = match name {
                    "prefiltered" => (3e-2, 3e-2),
                    "minmax" => (5e-5, 1e-6),
                    _ => (1e-6, 1e-6),
                };
                assert!(p99 <= p99_bound, "{scene_name} {name} {backend}: 99th percentile {p99}");
                assert!(over <= over_bound, "{scene_name} {name} {backend}: {over} of the pixels off by > 1 %");
            }
        }
    }
}
