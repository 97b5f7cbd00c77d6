//! Mirror tests (docs/MODEL.md §4, rung 3): the GPU and the CPU compute the same thing, pass by
//! pass, on small images — the host renderer's depth and shadow maps, and `brute-force` run on
//! identical inputs, for every light kind.

use crepuscular::gpu::{UploadedFrame, test_gpu};
use crepuscular::march::SpotSteps;
use crepuscular::march::{MarchSettings, StepPolicy};
use crepuscular::techniques::brute_force::{self, BruteForceSettings};
use crepuscular::testing::gpu_render;
use crepuscular::{CpuFrame, TechniqueSettings};
use crepuscular_cli::render::frame_desc;
use crepuscular_scene::{GpuHost, builtin, host, host_cpu};

fn small(name: &str) -> crepuscular_scene::Scene {
    let mut s = builtin::builtin(name).expect("built-in scene");
    s.render.width = 160;
    s.render.height = 90;
    s.render.shadow.size = 512;
    s
}

/// Fraction of entries that differ by more than `tol`.
fn mismatch(a: &[f32], b: &[f32], tol: f32) -> f64 {
    assert_eq!(a.len(), b.len());
    a.iter().zip(b).filter(|(x, y)| (*x - *y).abs() > tol).count() as f64 / a.len() as f64
}

/// The fraction of two images' RGB values that differ by more than 1e-3 of `peak`.
fn mismatch_of_peak(a: &crepuscular::Image, b: &crepuscular::Image, peak: f32) -> f64 {
    let rgb = |i: &crepuscular::Image| -> Vec<f32> {
        i.pixels.iter().flat_map(|p| p[..3].iter().map(|v| v / peak)).collect()
    };
    mismatch(&rgb(a), &rgb(b), 1e-3)
}

#[test]
fn host_depth_and_shadow_maps_match_between_gpu_and_cpu() {
    let Some(gpu) = test_gpu("host_depth_and_shadow_maps_match_between_gpu_and_cpu") else { return };
    for (name, _) in builtin::builtin_names() {
        let scene = small(name);
        let desc = frame_desc(&scene).unwrap();
        let cpu = host_cpu::render(&scene.geometry, &scene.shading(), &desc);
        let tex = GpuHost::for_scene(&gpu, &scene).unwrap().render(&gpu, &desc).unwrap();
        let depth = gpu.read_texture_f32(&tex.depth, 0).unwrap();
        let sm = host::read_shadow_maps(&gpu, &tex, &desc).unwrap();
        // Rasterization rules agree except on a few silhouette pixels (sub-pixel snapping of
        // clipped vertices); depths agree to float rounding elsewhere.
        let d = mismatch(&depth, &cpu.depth, 1e-5);
        let s = sm.iter().zip(&cpu.shadow_maps).map(|(g, c)| mismatch(&g.depth, &c.depth, 1e-5)).fold(0.0, f64::max);
        eprintln!("{name}: depth mismatch {:.4}%, shadow-map mismatch {:.4}%", d * 100.0, s * 100.0);
        assert!(d < 0.005, "{name}: {:.3}% of depth pixels differ", d * 100.0);
        assert!(s < 0.005, "{name}: {:.3}% of shadow-map texels differ", s * 100.0);
        // Surface radiance: same shading, so the images agree except where coverage differs.
        let surf = gpu.read_image(&tex.surface).unwrap();
        let bad = surf
            .pixels
            .iter()
            .zip(&cpu.surface.pixels)
            .filter(|(a, b)| (0..3).any(|c| (a[c] - b[c]).abs() > 1e-3 + 1e-3 * b[c].abs()))
            .count() as f64
            / surf.pixels.len() as f64;
        eprintln!("{name}: surface mismatch {:.4}%", bad * 100.0);
        assert!(bad < 0.02, "{name}: {:.2}% of surface pixels differ", bad * 100.0);
    }
}

#[test]
fn brute_force_gpu_matches_its_cpu_mirror() {
    let Some(gpu) = test_gpu("brute_force_gpu_matches_its_cpu_mirror") else { return };
    for (name, _) in builtin::builtin_names() {
        let scene = small(name);
        let desc = frame_desc(&scene).unwrap();
        let h = host_cpu::render(&scene.geometry, &scene.shading(), &desc);
        let frame = CpuFrame { desc: &desc, depth: &h.depth, shadow_maps: &h.shadow_maps, surface: None };
        let spot = |spot_steps| BruteForceSettings {
            ray_march: MarchSettings { steps: 32, ..Default::default() },
            policy: StepPolicy { spot: spot_steps, ..Default::default() },
            ..Default::default()
        };
        for settings in [
            BruteForceSettings::default(),
            BruteForceSettings {
                ray_march: MarchSettings { steps: 17, jitter: true, frame_index: 7, ..Default::default() },
                ..Default::default()
            },
            spot(SpotSteps::ExactCone),
            spot(SpotSteps::AppendixBConstant),
            spot(SpotSteps::AppendixBSmoothstep),
        ] {
            let (cpu, _) = brute_force::cpu::march(&frame, &settings).unwrap();
            let up = UploadedFrame::new(&gpu, &frame).unwrap();
            let out = gpu.create_output_texture(desc.width, desc.height);
            let bf = TechniqueSettings::BruteForce(settings.clone());
            let (_, stats) = gpu_render(&gpu, bf, &up.frame(&desc), &out.create_view(&Default::default())).unwrap();
            let img = gpu.read_image(&out).unwrap();
            assert_eq!(stats.raymarched_samples, cpu.pixels.len() as u64 * settings.ray_march.steps as u64);
            // Same samples, same shadow map: a sample may land on the other side of a shadow
            // edge through float rounding, so allow a step's worth of difference on rare pixels.
            let peak = cpu.pixels.iter().flat_map(|p| p[..3].iter().copied()).fold(0.0f32, f32::max);
            let mut bad = 0;
            let mut worst = 0.0f32;
            for (a, b) in img.pixels.iter().zip(&cpu.pixels) {
                for c in 0..3 {
                    let e = (a[c] - b[c]).abs() / (b[c].abs() + 1e-3 * peak);
                    worst = worst.max((a[c] - b[c]).abs() / peak);
                    if e > 1e-3 {
                        bad += 1;
                    }
                }
            }
            let frac = bad as f64 / (img.pixels.len() * 3) as f64;
            eprintln!("{name} {settings:?}: {:.4}% differ > 1e-3, worst |Δ|/peak {worst:.2e}", frac * 100.0);
            assert!(frac < 0.003, "{name}: {:.3}% of values differ by > 0.1%", frac * 100.0);
            // Where they differ, only a sample or two of the pixel flipped across a shadow edge
            // (f32 rounding in the shadow-map lookup differs between GPU and CPU). A step's
            // weight is ∫T over the step, up to ~max(1/N, σt·Δ) of the pixel: near-camera leaf
            // edges in the forest reach ~9 % of the peak. A real divergence would show in the
            // fraction above, and as errors far beyond a few steps' weight here.
            assert!(worst < 0.2, "{name}: worst |Δ|/peak {worst}");
        }
    }
}

/// Both step layouts of local lights (docs/MODEL.md §9, `local_steps = "equiangular"`, the
/// default, and `"uniform"`) for every technique on the point-light and spot-light scenes: the
/// GPU's layout (common.wgsl `Steps`) is the CPU's (march.rs `Steps`), for the marches,
/// prefiltered's quadrature and minmax's segments alike, each layout on its own held to 0.5 % of
/// values (prefiltered 2 %); and the two layouts differ (the setting reaches both backends).
#[test]
fn equiangular_steps_match_between_gpu_and_cpu_for_every_technique() {
    let Some(gpu) = test_gpu("equiangular_steps_match_between_gpu_and_cpu_for_every_technique") else { return };
    for name in ["cage", "stained-glass"] {
        let mut scene = small(name);
        scene.render.width = 96;
        scene.render.height = 54;
        let desc = frame_desc(&scene).unwrap();
        let h = host_cpu::render(&scene.geometry, &scene.shading(), &desc);
        let frame = CpuFrame { desc: &desc, depth: &h.depth, shadow_maps: &h.shadow_maps, surface: None };
        let up = UploadedFrame::new(&gpu, &frame).unwrap();
        for t in ["brute-force", "interleaved", "subsampled", "epipolar", "prefiltered", "minmax"] {
            let parse = |v: &str| {
                crepuscular_cli::render::parse_technique(t, &scene, &[format!("local_steps=\"{v}\"")]).unwrap()
            };
            let on_gpu = |settings: TechniqueSettings| {
                let out = gpu.create_output_texture(desc.width, desc.height);
                gpu_render(&gpu, settings, &up.frame(&desc), &out.create_view(&Default::default())).unwrap();
                gpu.read_image(&out).unwrap()
            };
            let settings = parse("equiangular");
            let (cpu, _) = settings.render_cpu(&frame, &[], &|_, _| {}).unwrap();
            let (uniform, _) = parse("uniform").render_cpu(&frame, &[], &|_, _| {}).unwrap();
            let img = on_gpu(settings);
            let uniform_gpu = on_gpu(parse("uniform"));
            let peak = cpu.pixels.iter().flat_map(|p| p[..3].iter().copied()).fold(0.0f32, f32::max);
            let rel = |a: &crepuscular::Image, b: &crepuscular::Image| mismatch_of_peak(a, b, peak);
            let (gpu_vs_cpu, vs_uniform) = (rel(&img, &cpu), rel(&uniform, &cpu));
            // The uniform layout's own GPU/CPU agreement (prefiltered's filtered visibility
            // rounds differently on the two backends near the spot's texture edges).
            let uniform_gpu_vs_cpu = rel(&uniform_gpu, &uniform);
            eprintln!(
                "{name} {t}: GPU vs CPU {:.3}% of values differ > 1e-3 of the peak (uniform steps: {:.3}%); uniform vs equiangular {:.1}%",
                gpu_vs_cpu * 100.0,
                uniform_gpu_vs_cpu * 100.0,
                vs_uniform * 100.0
            );
            // Each layout's GPU picture is its CPU mirror's, on its own (a bug shared by both
            // layouts must not pass by loosening the other's bound). Measured 2026-12-07
            // (llvmpipe): 0.000 % for every technique but prefiltered under both layouts;
            // prefiltered 1.13 % (equiangular) and 1.10 % (uniform) on stained-glass, 0 on cage.
            let bound = if t == "prefiltered" { 0.02 } else { 0.005 };
            assert!(
                gpu_vs_cpu < bound,
                "{name} {t}: GPU and CPU equiangular steps differ on {:.3}% (uniform: {:.3}%)",
                gpu_vs_cpu * 100.0,
                uniform_gpu_vs_cpu * 100.0
            );
            assert!(
                uniform_gpu_vs_cpu < bound,
                "{name} {t}: GPU and CPU uniform steps differ on {:.3}% (equiangular: {:.3}%)",
                uniform_gpu_vs_cpu * 100.0,
                gpu_vs_cpu * 100.0
            );
            assert!(vs_uniform > 0.001, "{name} {t}: equiangular steps change nothing ({:.3}%)", vs_uniform * 100.0);
        }
    }
}

/// The 2×2 bilinear shadow filter (`ShadowFilter::Bilinear`, docs/MODEL.md §1 "Visibility") on
/// every built-in scene — directional, spot and point (cube) maps: each marching technique's
/// GPU picture is its CPU mirror's under each filter, each held on its own, the filter
/// changes the pictures of the marches and of `minmax`'s walk (the setting reaches both
/// backends); `prefiltered`, which keeps its own visibility, is held only to the mirror.
#[test]
fn bilinear_shadow_filter_matches_between_gpu_and_cpu() {
    use crepuscular::ShadowFilter;
    let Some(gpu) = test_gpu("bilinear_shadow_filter_matches_between_gpu_and_cpu") else { return };
    let mut most_changed = 0.0f64;
    for (name, _) in builtin::builtin_names() {
        let mut scene = small(name);
        scene.render.width = 96;
        scene.render.height = 54;
        let (mut nearest, mut bilinear) = (frame_desc(&scene).unwrap(), frame_desc(&scene).unwrap());
        for (n, b) in nearest.lights.iter_mut().zip(&mut bilinear.lights) {
            (n.shadow_filter, b.shadow_filter) = (ShadowFilter::Nearest, ShadowFilter::Bilinear);
        }
        let h = host_cpu::render(&scene.geometry, &scene.shading(), &nearest);
        let frame = |desc| CpuFrame { desc, depth: &h.depth, shadow_maps: &h.shadow_maps, surface: None };
        let (fb, fne) = (frame(&bilinear), frame(&nearest));
        let up = UploadedFrame::new(&gpu, &fb).unwrap();
        for t in ["brute-force", "interleaved", "subsampled", "epipolar", "minmax", "prefiltered"] {
            let settings = crepuscular_cli::render::parse_technique(t, &scene, &[]).unwrap();
            let on_gpu = |desc: &crepuscular::frame::FrameDesc| {
                let out = gpu.create_output_texture(desc.width, desc.height);
                gpu_render(&gpu, settings.clone(), &up.frame(desc), &out.create_view(&Default::default())).unwrap();
                gpu.read_image(&out).unwrap()
            };
            let (cpu_b, _) = settings.render_cpu(&fb, &[], &|_, _| {}).unwrap();
            let (cpu_n, _) = settings.render_cpu(&fne, &[], &|_, _| {}).unwrap();
            let (gpu_b, gpu_n) = (on_gpu(&bilinear), on_gpu(&nearest));
            let peak = cpu_n.pixels.iter().flat_map(|p| p[..3].iter().copied()).fold(0.0f32, f32::max);
            let rel = |a: &crepuscular::Image, b: &crepuscular::Image| mismatch_of_peak(a, b, peak);
            let (b, n) = (rel(&gpu_b, &cpu_b), rel(&gpu_n, &cpu_n));
            let (changed, gpu_changed) = (rel(&cpu_b, &cpu_n), rel(&gpu_b, &gpu_n));
            eprintln!(
                "{name} {t}: GPU vs CPU {:.3}% differ > 1e-3 of the peak with the bilinear filter ({:.3}% nearest); \
                 bilinear vs nearest {:.2}% (CPU), {:.2}% (GPU)",
                b * 100.0,
                n * 100.0,
                changed * 100.0,
                gpu_changed * 100.0
            );
            // Each filter's GPU picture is its CPU mirror's, on its own (a broken nearest path
            // must not loosen the bilinear bound, nor the reverse). Measured 2026-12-07
            // (llvmpipe): 0.000 % for the marches and minmax under both filters; prefiltered,
            // whose filtered visibility rounds differently on the two backends, 0–7.4 % under
            // both (forest 7.40 %, atrium 3.04 %, colonnade 1.73 %).
            let bound = if t == "prefiltered" { 0.09 } else { 0.005 };
            assert!(b < bound, "{name} {t}: bilinear GPU and CPU differ on {:.3}%", b * 100.0);
            assert!(n < bound, "{name} {t}: nearest GPU and CPU differ on {:.3}%", n * 100.0);
            if t == "prefiltered" {
                // Its own visibility (filtered maps) ignores the filter; only the epipole disc,
                // a plain march, reads it: the picture may or may not change. (minmax's walk
                // reads it since 2026-12-07, docs/MODEL.md §8, and is held to the check below.)
                continue;
            }
            // The GPU must honour it as the CPU does: where the filter changes the CPU's picture,
            // it changes the GPU's as much (a GPU that ignored the filter would keep its nearest
            // picture). Scenes whose shadow edges are finer than a pixel change little.
            if changed > 0.001 {
                assert!(
                    gpu_changed > 0.5 * changed,
                    "{name} {t}: the filter changes {:.3}% of the CPU's pixels but {:.3}% of the GPU's",
                    changed * 100.0,
                    gpu_changed * 100.0
                );
            }
            most_changed = most_changed.max(changed);
        }
    }
    // Colonnade's and forest's shafts are edged by shadow-map texels: the filter must show there
    // (measured: 49–75 % of the marches' pixels move by more than 1e-3 of the peak).
    assert!(most_changed > 0.2, "the bilinear filter changes at most {:.2}% of any picture", most_changed * 100.0);
}
