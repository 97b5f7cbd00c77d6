//! Mirror tests (docs/MODEL.md §4, rung 3): the GPU and the CPU compute the same thing, pass by
//! pass, on small images — the host renderer's depth and shadow maps, and `brute-force` run on
//! identical inputs, for every light kind.

use crepuscular::gpu::{UploadedFrame, test_gpu};
use crepuscular::march::SpotSteps;
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
        let spot = |spot_steps| BruteForceSettings { steps: 32, spot_steps, ..Default::default() };
        for settings in [
            BruteForceSettings::default(),
            BruteForceSettings { steps: 17, jitter: true, frame_index: 7, ..Default::default() },
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
            assert_eq!(stats.raymarched_samples, cpu.pixels.len() as u64 * settings.steps as u64);
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
