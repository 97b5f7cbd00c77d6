//! Technique `interleaved` (Tóth & Umenhoffer 2009, §4.1): its shaders validate and its
//! uniforms match their WGSL layout; the GPU matches the CPU mirror pass by pass; it matches
//! the directional closed form within a bound derived from the method; with M = 1 it is
//! `brute-force`; its quality against `reference` on every built-in scene; the phase table's
//! error; settings validation.

use crepuscular::frame::{FrameDesc, surface_transmittance};
use crepuscular::gpu::{GpuContext, UploadedFrame, test_gpu};
use crepuscular::march::SpotSteps;
use crepuscular::march::{MarchSettings, StepPolicy};
use crepuscular::stats::TechniqueStats;
use crepuscular::techniques::brute_force::{self, BruteForceSettings};
use crepuscular::techniques::interleaved::{InterleavedSettings, PhaseLut, cpu};
use crepuscular::techniques::reference::{self, ReferenceSettings};
use crepuscular::testing::{gpu_render, gpu_scattering, wall_frame};
use crepuscular::tonemap::{ToneMap, composite};
use crepuscular::{AnyGpuTechnique, CpuFrame, GpuFrame, Image, Light, Medium, Phase, Scattering, TechniqueSettings};
use crepuscular_cli::metrics::compare;
use crepuscular_cli::render::frame_desc;
use crepuscular_scene::{GpuHost, builtin, host, host_cpu};
use glam::{DVec3, Vec3};

// ---- Helpers -----------------------------------------------------------------------------

fn small(name: &str, shadow: u32) -> crepuscular_scene::Scene {
    let mut s = builtin::builtin(name).expect("built-in scene");
    s.render.width = 160;
    s.render.height = 90;
    s.render.shadow.size = shadow;
    s
}

/// What the GPU produced: the march and row-pass textures, the output, the stats.
struct GpuRun {
    march: Image,
    rows: Image,
    out: Image,
    stats: TechniqueStats,
}

/// `interleaved` at `s` on `gpu` (wall-clock stats).
fn interleaved_gpu(gpu: &GpuContext, s: &InterleavedSettings) -> Scattering {
    gpu_scattering(gpu, TechniqueSettings::Interleaved(s.clone())).expect("pipelines")
}

fn run_gpu(gpu: &GpuContext, sc: &mut Scattering, frame: &GpuFrame) -> GpuRun {
    let out = gpu.create_output_texture(frame.desc.width, frame.desc.height);
    let stats = sc.render(frame, &out.create_view(&Default::default())).expect("render");
    let AnyGpuTechnique::Interleaved(il) = sc.technique() else { panic!("not interleaved") };
    GpuRun {
        march: gpu.read_image(il.march_texture().expect("march texture")).unwrap(),
        rows: gpu.read_image(il.rows_texture().expect("rows texture")).unwrap(),
        out: gpu.read_image(&out).unwrap(),
        stats,
    }
}

/// Runs `interleaved` on the GPU over exactly the CPU frame's depth and shadow map.
fn gpu_on_cpu_frame(gpu: &GpuContext, frame: &CpuFrame, s: &InterleavedSettings) -> GpuRun {
    let up = UploadedFrame::new(gpu, frame).expect("upload");
    run_gpu(gpu, &mut interleaved_gpu(gpu, s), &up.frame(frame.desc))
}

/// Brute-force's mirror criterion on rgb: (fraction of values differing by more than 1e-3
/// relative, with a floor of 1e-3 of the peak; worst |Δ| / peak).
fn rgb_diff(a: &Image, b: &Image) -> (f64, f32) {
    let peak = b.pixels.iter().flat_map(|p| p[..3].iter().copied()).fold(0.0f32, f32::max).max(1e-30);
    let mut bad = 0;
    let mut worst = 0.0f32;
    for (p, q) in a.pixels.iter().zip(&b.pixels) {
        for c in 0..3 {
            let e = (p[c] - q[c]).abs() / (q[c].abs() + 1e-3 * peak);
            worst = worst.max((p[c] - q[c]).abs() / peak);
            if e > 1e-3 {
                bad += 1;
            }
        }
    }
    (bad as f64 / (a.pixels.len() * 3) as f64, worst)
}

/// Largest |a − b| / (|b| + floor·peak) over the channels `channels`.
fn max_rel(a: &Image, b: &Image, channels: std::ops::Range<usize>, floor: f32) -> f32 {
    let peak = b.pixels.iter().flat_map(|p| p[channels.clone()].iter().copied()).fold(0.0f32, f32::max);
    a.pixels
        .iter()
        .zip(&b.pixels)
        .flat_map(|(p, q)| channels.clone().map(move |c| (p[c] - q[c]).abs() / (q[c].abs() + floor * peak).max(1e-30)))
        .fold(0.0f32, f32::max)
}

// (1) Shader validation and the Params layout: tests/shaders.rs.

// ---- (2) GPU vs CPU mirror, pass by pass ---------------------------------------------------

fn mirror_settings() -> Vec<InterleavedSettings> {
    let d = InterleavedSettings::default;
    vec![
        d(),
        InterleavedSettings { depth_aware: false, ..d() },
        InterleavedSettings { ray_march: MarchSettings { steps: 17, ..Default::default() }, block: 2, ..d() },
        InterleavedSettings {
            ray_march: MarchSettings { steps: 17, jitter: true, frame_index: 7, ..Default::default() },
            block: 3,
            ..d()
        },
        InterleavedSettings { phase_lut: true, ..d() },
        InterleavedSettings {
            ray_march: MarchSettings { steps: 32, ..Default::default() },
            policy: StepPolicy { spot: SpotSteps::ExactCone, ..Default::default() },
            ..d()
        },
    ]
}

#[test]
fn interleaved_gpu_matches_its_cpu_mirror_pass_by_pass() {
    let Some(gpu) = test_gpu("interleaved_gpu_matches_its_cpu_mirror_pass_by_pass") else { return };
    for (name, _) in builtin::builtin_names() {
        let scene = small(name, 512);
        let desc = frame_desc(&scene).unwrap();
        let h = host_cpu::render(&scene.geometry, &scene.shading(), &desc);
        let frame = CpuFrame { desc: &desc, depth: &h.depth, shadow_maps: &h.shadow_maps, surface: None };
        let up = UploadedFrame::new(&gpu, &frame).unwrap();
        // One GPU object for every setting: settings changes, texture reuse and table rebuilds.
        let mut il = interleaved_gpu(&gpu, &InterleavedSettings::default());
        for s in mirror_settings() {
            let cpu_march = cpu::march(&frame, &s).unwrap();
            let cpu_rows = cpu::sum_rows(&frame, &s, &cpu_march);
            let cpu_out = cpu::sum_columns(&frame, &s, &cpu_march, &cpu_rows);
            let (cpu_full, cpu_stats) = cpu::render(&frame, &s).unwrap();
            assert_eq!(cpu_full, cpu_out, "cpu::render runs the three passes");
            assert!(il.update(&TechniqueSettings::Interleaved(s.clone())).unwrap(), "the same technique");
            let g = run_gpu(&gpu, &mut il, &up.frame(&desc));
            let label = format!(
                "{name} M={} N={} depth_aware={} lut={} jitter={} {:?}",
                s.block, s.ray_march.steps, s.depth_aware, s.phase_lut, s.ray_march.jitter, s.policy.spot
            );

            // Stats: the exact count of terms, the same on both backends.
            let counted: u64 = (0..desc.height)
                .flat_map(|y| (0..desc.width).map(move |x| (x, y)))
                .map(|(x, y)| cpu::offset_terms(&s, x, y) as u64)
                .sum();
            assert_eq!(g.stats.raymarched_samples, counted, "{label}");
            assert_eq!(cpu_stats.raymarched_samples, counted, "{label}");
            let names: Vec<_> = g.stats.passes.iter().map(|p| p.name.as_str()).collect();
            assert_eq!(names, ["march", "sum_rows", "sum_columns"]);
            assert_eq!(g.stats.extra.get("block"), Some(&(s.block as f64)));
            assert_eq!(g.stats.extra.contains_key("phase_lut_max_rel_error"), s.phase_lut, "{label}");
            // `Scattering` adds the count of lights that reach the view; the rest is the technique's.
            let mut ge = g.stats.extra.clone();
            assert_eq!(ge.remove("lights"), Some(desc.scattering_lights().len() as f64), "{label}");
            assert_eq!(cpu_stats.extra, ge, "{label}");

            // March pass: brute-force's mirror criterion (same samples, same shadow map; a
            // sample may fall on the other side of a shadow edge through f32 rounding). Alpha:
            // the view distance, computed alike on both sides.
            let (frac, worst) = rgb_diff(&g.march, &cpu_march);
            let alpha = max_rel(&g.march, &cpu_march, 3..4, 0.0);
            eprintln!(
                "{label}: march {:.4}% differ > 1e-3, worst |Δ|/peak {worst:.2e}, distance {alpha:.1e}",
                frac * 100.0
            );
            // 0.5 %: with the exact-cone default on stained-glass, 0.30 % of values differ by
            // just over 1e-3, the worst by 1.0e-3 of the peak (the cone chord's and the step
            // offset's exp/log round differently on the GPU).
            assert!(frac < 0.005, "{label}: march {:.3}% of values differ by > 0.1%", frac * 100.0);
            assert!(worst < 0.2, "{label}: march worst |Δ|/peak {worst}");
            assert!(alpha < 1e-4, "{label}: view distances differ by {alpha}");

            // The sum passes alone, on the GPU's own march output: the same additions in the
            // same order and the same accept decisions, so only the last bits may differ.
            let rows_on_gpu_march = cpu::sum_rows(&frame, &s, &g.march);
            let rows_err = max_rel(&g.rows, &rows_on_gpu_march, 0..3, 1e-6);
            assert!(
                g.rows.pixels.iter().zip(&rows_on_gpu_march.pixels).all(|(a, b)| a[3] == b[3]),
                "{label}: term counts differ"
            );
            let out_on_gpu = cpu::sum_columns(&frame, &s, &g.march, &g.rows);
            let out_err = max_rel(&g.out, &out_on_gpu, 0..3, 1e-6);
            assert!(rows_err < 1e-5 && out_err < 1e-5, "{label}: sum_rows off by {rows_err}, sum_columns by {out_err}");

            // End to end: a march difference spreads over the up to M×M outputs whose window
            // holds that pixel, so up to M² times as many values differ. Measured 2026-11-22 on
            // llvmpipe: march ≤ 0.18 % of values (stained-glass: bilinear spot texture and shadow
            // edges, as for brute-force), final ≤ 0.47 %, worst |Δ|/peak 5e-2 (march) and 8e-3
            // (final); the sum passes alone agree exactly.
            let (frac, worst) = rgb_diff(&g.out, &cpu_out);
            let m2 = (s.block * s.block) as f64;
            eprintln!(
                "{label}: sums {rows_err:.1e}/{out_err:.1e}; final {:.4}% differ > 1e-3, worst |Δ|/peak {worst:.2e}",
                frac * 100.0
            );
            assert!(frac < 0.003 * m2, "{label}: final {:.3}% of values differ by > 0.1%", frac * 100.0);
            assert!(worst < 0.2, "{label}: final worst |Δ|/peak {worst}");
            assert!(g.out.all_finite() && cpu_out.all_finite(), "{label}: non-finite output");
        }
    }
}

// ---- (3) Closed form ---------------------------------------------------------------------

fn sun() -> Light {
    Light::Directional {
        direction: Vec3::new(0.3, -0.2, 1.0).normalize(),
        color: Vec3::new(1.0, 0.9, 0.8),
        intensity: 4.0,
    }
}

use crepuscular::testing::wall_media as media;

/// Per pixel of the sunlit wall frame, in f64: the closed form σs·p·E·(1 − e^(−σt·s))/σt
/// (`exact`); the value interleaved sampling computes in exact arithmetic (`ideal`: term i of
/// eq. 1 taken from the window pixel whose offset is i mod M², times N/terms); and the bracket
/// [`lo`, `hi`] = Σᵢ min/max over the window of term i. Term i of pixel q is
/// σs·p(θ_q)·E·e^(−σt·iΔ_q)·∫₀^Δ_q e^(−σt t) dt with Δ_q = s_q/N — exact per step for a constant
/// integrand. Both `exact` (its own pixel's terms) and, for a complete window, `ideal` (one
/// window pixel's term per i) lie in [lo, hi], so |ideal − exact| ≤ hi − lo: that is the
/// method's error bound, and it grows with the variation of p(θ) and s across the window.
struct WallTruth {
    exact: Vec<DVec3>,
    ideal: Vec<DVec3>,
    lo: Vec<DVec3>,
    hi: Vec<DVec3>,
}

fn wall_truth(desc: &FrameDesc, s: &InterleavedSettings) -> WallTruth {
    let Light::Directional { direction, color, intensity } = &desc.lights[0].light else { unreachable!() };
    let (w, h) = (desc.width, desc.height);
    let st = desc.medium.extinction().as_dvec3();
    let ss = desc.medium.scattering.as_dvec3();
    let e = color.as_dvec3() * *intensity as f64;
    let inv = desc.camera.view_proj().as_dmat4().inverse();
    let n = s.ray_march.steps as usize;
    // Per pixel: amplitude σs·p·E, the step's ∫T, and the per-step ratio e^(−σt·Δ).
    let per_pixel: Vec<(DVec3, DVec3, DVec3)> = (0..h)
        .flat_map(|y| (0..w).map(move |x| (x, y)))
        .map(|(x, y)| {
            let ndc_x = (x as f64 + 0.5) / w as f64 * 2.0 - 1.0;
            let ndc_y = 1.0 - (y as f64 + 0.5) / h as f64 * 2.0;
            let dir = inv.project_point3(DVec3::new(ndc_x, ndc_y, 1.0)).normalize();
            let dist = 30.0 / dir.dot(DVec3::NEG_Z);
            let delta = dist / n as f64;
            let p = DVec3::from(desc.medium.phase.eval_f64(-direction.as_dvec3().normalize().dot(dir)));
            let seg = DVec3::from_array(
                st.to_array().map(|k| if k * delta < 1e-9 { delta } else { (1.0 - (-k * delta).exp()) / k }),
            );
            (ss * p * e, seg, (-st * delta).exp())
        })
        .collect();
    let term = |q: usize, i: usize| {
        let (a, seg, r) = per_pixel[q];
        a * seg * r.powf(i as f64)
    };
    let mut out = WallTruth { exact: vec![], ideal: vec![], lo: vec![], hi: vec![] };
    let m2 = (s.block * s.block) as usize;
    for y in 0..h {
        for x in 0..w {
            let (x0, y0) = (cpu::window_start(s, x, w), cpu::window_start(s, y, h));
            let window: Vec<(u32, u32)> = (y0..(y0 + s.block).min(h))
                .flat_map(|qy| (x0..(x0 + s.block).min(w)).map(move |qx| (qx, qy)))
                .collect();
            let idx = |(qx, qy): (u32, u32)| (qy * w + qx) as usize;
            let exact: DVec3 = (0..n).map(|i| term(idx((x, y)), i)).sum();
            let (mut ideal, mut terms) = (DVec3::ZERO, 0u32);
            for &q in &window {
                let k = cpu::block_offset(s, q.0, q.1) as usize;
                ideal += (k..n).step_by(m2).map(|i| term(idx(q), i)).sum::<DVec3>();
                terms += cpu::offset_terms(s, q.0, q.1);
            }
            let (mut lo, mut hi) = (DVec3::ZERO, DVec3::ZERO);
            for i in 0..n {
                let t: Vec<DVec3> = window.iter().map(|&q| term(idx(q), i)).collect();
                lo += t.iter().copied().reduce(DVec3::min).unwrap();
                hi += t.iter().copied().reduce(DVec3::max).unwrap();
            }
            out.exact.push(exact);
            out.ideal.push(ideal * (n as f64 / terms as f64));
            out.lo.push(lo);
            out.hi.push(hi);
        }
    }
    out
}

fn closed_form_settings() -> Vec<InterleavedSettings> {
    let d = InterleavedSettings::default;
    vec![
        d(),
        InterleavedSettings { depth_aware: false, ..d() },
        InterleavedSettings { ray_march: MarchSettings { steps: 17, ..Default::default() }, block: 2, ..d() },
        InterleavedSettings {
            ray_march: MarchSettings { steps: 17, jitter: true, frame_index: 3, ..Default::default() },
            block: 3,
            ..d()
        },
        // Across 8 pixels near the image edge s = 30/cos φ changes by more than 10 %, so the
        // depth test would drop neighbours (a case `ideal` does not model): off here.
        InterleavedSettings {
            ray_march: MarchSettings { steps: 128, ..Default::default() },
            block: 8,
            depth_aware: false,
            ..d()
        },
        InterleavedSettings { phase_lut: true, ..d() },
    ]
}

/// Checks an image against the wall truth; returns (max error vs ideal, max error vs the
/// closed form), both relative.
fn check_wall(label: &str, img: &Image, t: &WallTruth, tol_ideal: f64, bracket: bool) -> (f64, f64) {
    let (mut e_ideal, mut e_exact) = (0.0f64, 0.0f64);
    for (i, p) in img.pixels.iter().enumerate() {
        let got = DVec3::new(p[0] as f64, p[1] as f64, p[2] as f64);
        for c in 0..3 {
            let floor = 1e-12;
            let ei = (got[c] - t.ideal[i][c]).abs() / t.ideal[i][c].max(floor);
            let ee = (got[c] - t.exact[i][c]).abs() / t.exact[i][c].max(floor);
            e_ideal = e_ideal.max(ei);
            e_exact = e_exact.max(ee);
            // The method's bound: exact and ideal both lie in [lo, hi] (complete windows).
            if !bracket {
                continue;
            }
            let bound = (t.hi[i][c] - t.lo[i][c]) + tol_ideal * t.exact[i][c] + floor;
            assert!(
                (got[c] - t.exact[i][c]).abs() <= bound,
                "{label}: pixel {i} channel {c}: {} vs closed form {} beyond the window bracket [{}, {}]",
                got[c],
                t.exact[i][c],
                t.lo[i][c],
                t.hi[i][c]
            );
        }
    }
    assert!(e_ideal < tol_ideal, "{label}: off the exact-arithmetic interleaved sum by {e_ideal}");
    (e_ideal, e_exact)
}

#[test]
fn directional_interleaved_matches_the_closed_form() {
    // 64×36 pixels, 60° vertical field of view: 1.7° per pixel, the sun 20° off the view axis and
    // in the picture. The closed form varies across an M×M window through p(θ) and s = 30/cos φ,
    // and the sum takes M² − 1 of every M² terms from the neighbours' rays, so it is not the
    // pixel's own closed form. Justified tolerance, checked per pixel and channel: the result
    // and the closed form both lie in the window bracket [lo, hi] (see `WallTruth`), so they
    // differ by at most hi − lo (+ f32 rounding). Against the exact-arithmetic interleaved sum
    // (`ideal`) only f32 rounding remains (measured ≤ 1.5e-5; asserted < 1e-4), plus the table's
    // error with `phase_lut` (≤ 2.1e-4 measured).
    //
    // The largest relative errors vs the closed form, measured 2026-11-22 (CPU; the GPU agrees
    // to 1e-5), are set by how fast p(θ) changes near the sun — HG g = 0.7 changes by up to
    // ~10 % per pixel around θ ≈ 15°, and Hoffman–Preetham's Mie part (g = 0.76) by ~16 % — and
    // by the window's offset: even M centres the window half a pixel off (x − M/2 … x + M/2 − 1),
    // so the error is first order in the gradient, while odd M cancels it to first order:
    //
    // | medium (media())      | M=2, N=17 | M=3, N=17 | M=4, N=64 | M=8, N=128 |
    // | HG 0.7                | 0.108     | 0.104     | 0.164     | 0.349      |
    // | isotropic             | 0.0028    | 0.0068    | 0.0064    | 0.0148     |
    // | Rayleigh              | 0.0129    | 0.0183    | 0.0262    | 0.0509     |
    // | Hoffman–Preetham 0.76 | 0.138     | 0.108     | 0.218     | 0.498      |
    // | HG −0.3 (σt = 0 in R) | 0.0130    | 0.0200    | 0.0302    | 0.0602     |
    //
    // Asserted below with ~30 % margin.
    const BOUNDS: [[f64; 4]; 5] = [
        [0.14, 0.135, 0.21, 0.45],
        [0.0037, 0.0088, 0.0083, 0.019],
        [0.017, 0.024, 0.034, 0.066],
        [0.18, 0.14, 0.28, 0.65],
        [0.017, 0.026, 0.039, 0.078],
    ];
    let block_column = |m: u32| [2, 3, 4, 8].iter().position(|&b| b == m).unwrap();
    let gpu = test_gpu("directional_interleaved_matches_the_closed_form");
    let mut worst = [[0.0f64; 4]; 5];
    for (mi, m) in media().into_iter().enumerate() {
        let (d, depth, sm) = wall_frame(sun(), m.clone(), 64, 36);
        let frame = CpuFrame { desc: &d, depth: &depth, shadow_maps: std::slice::from_ref(&sm), surface: None };
        for s in closed_form_settings() {
            let t = wall_truth(&d, &s);
            let lut_err = if s.phase_lut { PhaseLut::new(&m.phase, s.phase_lut_size).max_rel_error } else { 0.0 };
            let tol = 1e-4 + lut_err;
            let label = format!(
                "{:?} M={} N={} depth_aware={} lut={}",
                m.phase, s.block, s.ray_march.steps, s.depth_aware, s.phase_lut
            );
            let (img, _) = cpu::render(&frame, &s).unwrap();
            let (ei, ee) = check_wall(&format!("cpu {label}"), &img, &t, tol, true);
            eprintln!("cpu {label}: vs ideal {ei:.2e}, vs closed form {ee:.3e}");
            let w = &mut worst[mi][block_column(s.block)];
            *w = w.max(ee);
            if let Some(gpu) = &gpu
                && (s.block == 4 || s.block == 3)
            {
                let g = gpu_on_cpu_frame(gpu, &frame, &s);
                let (ei, ee) = check_wall(&format!("gpu {label}"), &g.out, &t, tol, true);
                eprintln!("gpu {label}: vs ideal {ei:.2e}, vs closed form {ee:.3e}");
                let w = &mut worst[mi][block_column(s.block)];
                *w = w.max(ee);
            }
        }
    }
    eprintln!("worst relative error vs the closed form, per medium, M = 2, 3, 4, 8: {worst:.4?}");
    for (mi, row) in worst.iter().enumerate() {
        for (bi, &e) in row.iter().enumerate() {
            let bound = BOUNDS[mi][bi];
            assert!(e < bound, "medium {mi}, M = {}: {e} off the closed form (bound {bound})", [2, 3, 4, 8][bi]);
        }
    }
}

#[test]
fn images_smaller_than_a_block_renormalise_by_the_offsets_covered() {
    // 3×2 pixels with M = 4: every window is the whole image and holds 6 of the 16 offsets
    // (24 of the 64 terms); the sum is scaled by 64/24. The pixels are 20° apart, so s differs
    // by more than 10 % between them and the depth test would drop some: it is off where the
    // result is checked against `ideal`, and on for a finiteness check.
    let gpu = test_gpu("images_smaller_than_a_block_renormalise_by_the_offsets_covered");
    let (d, depth, sm) = wall_frame(sun(), media()[0].clone(), 3, 2);
    let frame = CpuFrame { desc: &d, depth: &depth, shadow_maps: std::slice::from_ref(&sm), surface: None };
    let d4 = || InterleavedSettings { depth_aware: false, ..Default::default() };
    for s in [
        d4(),
        InterleavedSettings { ray_march: MarchSettings { steps: 1, ..Default::default() }, ..d4() },
        InterleavedSettings { ray_march: MarchSettings { steps: 4096, ..Default::default() }, block: 16, ..d4() },
        InterleavedSettings::default(),
    ] {
        let label = format!("3×2 M={} N={} depth_aware={}", s.block, s.ray_march.steps, s.depth_aware);
        let (img, stats) = cpu::render(&frame, &s).unwrap();
        let positive = |img: &Image| img.pixels.iter().all(|p| p[..3].iter().all(|c| c.is_finite() && *c > 0.0));
        assert!(positive(&img), "{label}: {:?}", img.pixels);
        let expected: u64 =
            (0..2).flat_map(|y| (0..3).map(move |x| (x, y))).map(|(x, y)| cpu::offset_terms(&s, x, y) as u64).sum();
        assert_eq!(stats.raymarched_samples, expected);
        let g = gpu.as_ref().map(|gpu| gpu_on_cpu_frame(gpu, &frame, &s));
        if let Some(g) = &g {
            assert!(positive(&g.out), "{label} gpu: {:?}", g.out.pixels);
        }
        if s.depth_aware {
            continue;
        }
        let t = wall_truth(&d, &s);
        let (ei, ee) = check_wall(&label, &img, &t, 1e-4, false);
        eprintln!("{label}: vs ideal {ei:.2e}, vs closed form {ee:.2e}");
        if let Some(g) = &g {
            check_wall(&format!("{label} gpu"), &g.out, &t, 1e-4, false);
        }
    }
}

// ---- (4) M = 1 is brute-force ----------------------------------------------------------------

#[test]
fn block_one_is_brute_force() {
    let gpu = test_gpu("block_one_is_brute_force");
    for (name, _) in builtin::builtin_names() {
        let scene = small(name, 512);
        let desc = frame_desc(&scene).unwrap();
        let h = host_cpu::render(&scene.geometry, &scene.shading(), &desc);
        let frame = CpuFrame { desc: &desc, depth: &h.depth, shadow_maps: &h.shadow_maps, surface: None };
        let up = gpu.as_ref().map(|g| UploadedFrame::new(g, &frame).unwrap());
        for (steps, jitter, spot_steps) in [(64, false, SpotSteps::Fixed), (17, true, SpotSteps::ExactCone)] {
            let il = InterleavedSettings {
                ray_march: MarchSettings { steps: steps, jitter: jitter, frame_index: 7, ..Default::default() },
                policy: StepPolicy { spot: spot_steps, ..Default::default() },
                block: 1,
                ..Default::default()
            };
            let bf = BruteForceSettings {
                ray_march: MarchSettings { steps: steps, jitter: jitter, frame_index: 7, ..Default::default() },
                policy: StepPolicy { spot: spot_steps, ..Default::default() },
                ..Default::default()
            };
            let (a, _) = cpu::render(&frame, &il).unwrap();
            let (b, _) = brute_force::cpu::march(&frame, &bf).unwrap();
            // The same samples in the same order, a window of one pixel, a factor N/N = 1:
            // identical bits on the CPU.
            let e = max_rel(&a, &b, 0..3, 0.0);
            eprintln!("{name} N={steps}: cpu max rel {e:e}");
            assert_eq!(
                a.pixels.iter().map(|p| &p[..3]).collect::<Vec<_>>(),
                b.pixels.iter().map(|p| &p[..3]).collect::<Vec<_>>(),
                "{name} N={steps}: cpu differs"
            );
            if let (Some(gpu), Some(up)) = (&gpu, &up) {
                let g = run_gpu(gpu, &mut interleaved_gpu(gpu, &il), &up.frame(&desc));
                let out = gpu.create_output_texture(desc.width, desc.height);
                let bf = TechniqueSettings::BruteForce(bf.clone());
                gpu_render(gpu, bf, &up.frame(&desc), &out.create_view(&Default::default())).unwrap();
                let b = gpu.read_image(&out).unwrap();
                let e = max_rel(&g.out, &b, 0..3, 1e-6);
                eprintln!("{name} N={steps}: gpu max rel {e:e}");
                assert!(e <= 1e-6, "{name} N={steps}: gpu interleaved M = 1 vs brute-force {e}");
            }
        }
    }
}

// ---- (5) Quality vs reference ----------------------------------------------------------------

// Measured figures (PSNR dB, FLIP mean) for interleaved at its defaults (M = 4, N = 64,
// depth-aware), 160×90, 1024² shadow map, reference at 512 steps. Measured on 2026-11-22 (the
// CPU backend and llvmpipe agree to 0.01 dB / 0.0002):
//
// | scene         | interleaved    | no depth test  | brute-force 4  | brute-force 64 |
// | colonnade     | 29.01 / 0.0634 | 26.19 / 0.0879 | 25.80 / 0.1886 | 35.89 / 0.0301 |
// | forest        | 24.16 / 0.1576 | 23.79 / 0.1909 | 17.70 / 0.2770 | 33.52 / 0.0594 |
// | stained-glass | 28.29 / 0.0297 | 28.91 / 0.0300 | 27.03 / 0.0564 | 32.68 / 0.0115 |
// | cage          | 45.24 / 0.0571 | 43.09 / 0.0625 | 36.30 / 0.1355 | 59.29 / 0.0354 |
// | terrain       | 37.05 / 0.0455 | 35.29 / 0.0482 | 27.82 / 0.1427 | 49.52 / 0.0125 |
//
// (PSNR dB / FLIP; brute-force 4 has the same ray-marching cost per pixel, N/M² = 4 steps.)
// At 160×90 a 4×4 window is large against the shafts, so interleaved sits between the two
// brute-force columns.
// The thresholds come from the quality table, docs/quality.toml (crepuscular_cli::quality).

const REFERENCE: ReferenceSettings = ReferenceSettings { steps: 512, seed: 1 };

/// PSNR on the linear in-scattering, FLIP on the composited final images.
fn metrics(frame: &CpuFrame, surface: &Image, reference: &Image, test: &Image, exposure: f32) -> (f64, f64) {
    let tone = ToneMap::new(exposure);
    let t = surface_transmittance(frame.desc, frame.depth);
    let lin = compare(reference, test, &tone).unwrap();
    let fin = compare(&composite(surface, reference, &t), &composite(surface, test, &t), &tone).unwrap();
    (lin.psnr_db, fin.flip_mean)
}

/// Against the quality table (docs/quality.toml, crepuscular_cli::quality).
fn check_quality(name: &str, backend: &str, psnr: f64, flip: f64) {
    eprintln!("{backend} {name}: interleaved PSNR {psnr:.2} dB (in-scattering), FLIP {flip:.4} (final)");
    crepuscular_cli::quality::check("interleaved", name, backend, psnr, flip).unwrap_or_else(|e| panic!("{e:#}"));
}

#[test]
fn interleaved_vs_reference_on_every_builtin_scene_cpu() {
    // The one-light scenes (the several-light ones are tests/lights.rs's).
    for name in builtin::one_light_names() {
        let scene = small(name, 1024);
        let desc = frame_desc(&scene).unwrap();
        let h = host_cpu::render(&scene.geometry, &scene.shading(), &desc);
        let frame = CpuFrame { desc: &desc, depth: &h.depth, shadow_maps: &h.shadow_maps, surface: Some(&h.surface) };
        let (rf, _) = reference::render(&frame, &REFERENCE, &|_, _| {}).unwrap();
        let (il, _) = cpu::render(&frame, &InterleavedSettings::default()).unwrap();
        let (psnr, flip) = metrics(&frame, &h.surface, &rf, &il, scene.render.exposure);
        // For context: brute-force at the same N and at the same per-pixel cost (N/M² = 4
        // steps), and interleaved without depth awareness.
        let bf = |steps| {
            brute_force::cpu::march(
                &frame,
                &BruteForceSettings {
                    ray_march: MarchSettings { steps: steps, ..Default::default() },
                    ..Default::default()
                },
            )
            .unwrap()
            .0
        };
        let (p64, f64_) = metrics(&frame, &h.surface, &rf, &bf(64), scene.render.exposure);
        let (p4, f4) = metrics(&frame, &h.surface, &rf, &bf(4), scene.render.exposure);
        let no_da = cpu::render(&frame, &InterleavedSettings { depth_aware: false, ..Default::default() }).unwrap().0;
        let (pn, fna) = metrics(&frame, &h.surface, &rf, &no_da, scene.render.exposure);
        eprintln!(
            "cpu {name}: brute-force 64 {p64:.2} dB / {f64_:.4}, brute-force 4 {p4:.2} / {f4:.4}, \
             interleaved without depth awareness {pn:.2} / {fna:.4}"
        );
        check_quality(name, "cpu", psnr, flip);
        // §4.1's claim: at the same per-pixel cost, interleaving beats marching N/M² steps —
        // with the paper's equal steps (eq. 1). Under the default equiangular steps, 4 steps
        // already integrate a local light's 1/d² exactly and the claim holds on FLIP, not on
        // PSNR (cage: brute-force 4 57.6 dB / 0.167 against interleaved 48.5 / 0.040, the 4×4
        // sum mixing neighbours' peaks near the lamp).
        let uniform = crepuscular::march::LocalSteps::Uniform;
        let il_u = cpu::render(
            &frame,
            &InterleavedSettings {
                ray_march: MarchSettings { ..Default::default() },
                policy: StepPolicy { local: uniform, ..Default::default() },
                ..Default::default()
            },
        )
        .unwrap()
        .0;
        let bf_u = brute_force::cpu::march(
            &frame,
            &BruteForceSettings {
                ray_march: MarchSettings { steps: 4, ..Default::default() },
                policy: StepPolicy { local: uniform, ..Default::default() },
                ..Default::default()
            },
        )
        .unwrap()
        .0;
        let (pu, fu) = metrics(&frame, &h.surface, &rf, &il_u, scene.render.exposure);
        let (p4u, f4u) = metrics(&frame, &h.surface, &rf, &bf_u, scene.render.exposure);
        eprintln!("cpu {name}, uniform steps: interleaved {pu:.2} dB / {fu:.4}, brute-force 4 {p4u:.2} / {f4u:.4}");
        assert!(pu > p4u && fu < f4u, "{name}: interleaved {pu:.2}/{fu:.4} vs brute-force 4 {p4u:.2}/{f4u:.4}");
        assert!(flip < f4, "{name}: interleaved FLIP {flip:.4} vs brute-force 4 {f4:.4} (equiangular steps)");
    }
}

#[test]
fn interleaved_vs_reference_on_every_builtin_scene_gpu() {
    let Some(gpu) = test_gpu("interleaved_vs_reference_on_every_builtin_scene_gpu") else { return };
    let mut il = interleaved_gpu(&gpu, &InterleavedSettings::default());
    // The one-light scenes (the several-light ones are tests/lights.rs's).
    for name in builtin::one_light_names() {
        let scene = small(name, 1024);
        let desc = frame_desc(&scene).unwrap();
        // The GPU host renderer's own depth and shadow map, as `crepuscular render` uses them;
        // the reference runs on the CPU over that very shadow map.
        let tex = GpuHost::for_scene(&gpu, &scene).unwrap().render(&gpu, &desc).unwrap();
        let views = tex.views();
        let gframe = views.frame(&desc);
        let g = run_gpu(&gpu, &mut il, &gframe);
        assert_eq!(g.stats.backend, "gpu");
        let depth = gpu.read_texture_f32(&tex.depth, 0).unwrap();
        let surface = gpu.read_image(&tex.surface).unwrap();
        let shadow_map = host::read_shadow_maps(&gpu, &tex, &desc).unwrap();
        let frame = CpuFrame { desc: &desc, depth: &depth, shadow_maps: &shadow_map, surface: Some(&surface) };
        let (rf, _) = reference::render(&frame, &REFERENCE, &|_, _| {}).unwrap();
        let (psnr, flip) = metrics(&frame, &surface, &rf, &g.out, scene.render.exposure);
        check_quality(name, "gpu", psnr, flip);
    }
}

// ---- (6) Phase table ---------------------------------------------------------------------

#[test]
fn phase_table_error_is_small_and_falls_quadratically() {
    // Measured 2026-11-22, max relative error at 64 / 256 / 1024 entries: HG g = 0.9
    // 2.9e-2 / 2.06e-3 / 1.29e-4; HG 0.5 7.5e-4 / 4.6e-5 / 2.9e-6; HG −0.7 (table mirrored)
    // 2.9e-3 / 1.8e-4 / 1.1e-5; Rayleigh 7.1e-4 / 4.3e-5 / 2.9e-6; Hoffman–Preetham 0.76
    // 4.8e-3 / 3.0e-4 / 1.9e-5; isotropic 1.3e-7 (f32 rounding). Asserted: < 1 % at 256 and
    // ≥ 8× smaller at 1024 (linear interpolation: error ∝ 1/size², 16× per 4×).
    let hg9 = Phase::HenyeyGreenstein { g: 0.9 };
    let e256 = PhaseLut::new(&hg9, 256).max_rel_error;
    eprintln!("HG g = 0.9, 256 entries: max relative error {e256:.3e}");
    assert!(e256 < 0.01, "HG 0.9 at 256 entries: {e256}");
    let phases = [
        Phase::Isotropic,
        Phase::HenyeyGreenstein { g: 0.5 },
        hg9,
        Phase::HenyeyGreenstein { g: -0.7 },
        Phase::Rayleigh,
        Phase::HoffmanPreetham { g: 0.76, rayleigh_fraction: Vec3::new(0.2, 0.4, 0.6) },
    ];
    for p in phases {
        let e: Vec<f64> = [64, 256, 1024].iter().map(|&n| PhaseLut::new(&p, n).max_rel_error).collect();
        eprintln!("{p:?}: 64 / 256 / 1024 entries: {:.2e} / {:.2e} / {:.2e}", e[0], e[1], e[2]);
        assert!(e[1] < 0.01, "{p:?}: {}", e[1]);
        // Linear interpolation: error ∝ 1/size², down to f32 rounding.
        assert!(e[2] < e[1] / 8.0 || e[2] < 1e-6, "{p:?}: {e:?}");
    }
    // The table reproduces the analytic phase function at its nodes, per channel.
    let hp = phases[5];
    let lut = PhaseLut::new(&hp, 33);
    for i in 0..33 {
        let u = i as f32 / 32.0;
        let c = 1.0 - 2.0 * u * u;
        let got = cpu::phase_lut(&lut, c);
        let exact = hp.eval(c);
        assert!(((got - exact) / exact).abs().max_element() < 1e-4, "node {i}: {got} vs {exact}");
    }
}

#[test]
fn the_phase_table_changes_each_pixel_by_at_most_its_error() {
    // Only the phase factor of each term changes, by at most the table's relative error ε, and
    // every term is ≥ 0, so every pixel changes by at most ε (plus rounding).
    for (name, _) in builtin::builtin_names() {
        let scene = small(name, 512);
        let desc = frame_desc(&scene).unwrap();
        let h = host_cpu::render(&scene.geometry, &scene.shading(), &desc);
        let frame = CpuFrame { desc: &desc, depth: &h.depth, shadow_maps: &h.shadow_maps, surface: None };
        let s = InterleavedSettings::default();
        let (a, _) = cpu::render(&frame, &s).unwrap();
        let (b, stats) = cpu::render(&frame, &InterleavedSettings { phase_lut: true, ..s }).unwrap();
        let eps = stats.extra["phase_lut_max_rel_error"] as f32;
        let e = max_rel(&b, &a, 0..3, 1e-6);
        eprintln!("{name}: table error {eps:.2e}, image change {e:.2e}");
        assert!(e <= eps + 1e-5, "{name}: {e} > {eps}");
    }
}

// ---- (7) Settings ------------------------------------------------------------------------

#[test]
fn validate_rejects_bad_settings() {
    let d = InterleavedSettings::default;
    assert!(d().validate().is_ok());
    let cases = [
        (InterleavedSettings { block: 0, ..d() }, "interleaved.block"),
        (InterleavedSettings { block: 17, ..d() }, "interleaved.block"),
        (
            InterleavedSettings { ray_march: MarchSettings { steps: 0, ..Default::default() }, ..d() },
            "interleaved.steps",
        ),
        (
            InterleavedSettings { ray_march: MarchSettings { steps: 4097, ..Default::default() }, ..d() },
            "interleaved.steps",
        ),
        (InterleavedSettings { depth_tolerance: -0.1, ..d() }, "interleaved.depth_tolerance"),
        (InterleavedSettings { depth_tolerance: f32::NAN, ..d() }, "interleaved.depth_tolerance"),
        (InterleavedSettings { depth_tolerance: f32::INFINITY, ..d() }, "interleaved.depth_tolerance"),
        (InterleavedSettings { phase_lut_size: 1, ..d() }, "interleaved.phase_lut_size"),
        (InterleavedSettings { phase_lut_size: 65537, ..d() }, "interleaved.phase_lut_size"),
        (
            InterleavedSettings {
                ray_march: MarchSettings { ..Default::default() },
                policy: StepPolicy { denominator: 0.0, ..Default::default() },
                ..d()
            },
            "interleaved.spot_denominator",
        ),
        (
            InterleavedSettings {
                ray_march: MarchSettings { ..Default::default() },
                policy: StepPolicy { denominator: 1.5, ..Default::default() },
                ..d()
            },
            "interleaved.spot_denominator",
        ),
    ];
    let (desc, depth, sm) = wall_frame(sun(), Medium::default(), 8, 4);
    let frame = CpuFrame { desc: &desc, depth: &depth, shadow_maps: std::slice::from_ref(&sm), surface: None };
    for (s, key) in cases {
        match s.validate() {
            Err(crepuscular::Error::Invalid { key: k, .. }) => assert_eq!(k, key),
            other => panic!("{s:?}: expected an error for {key}, got {other:?}"),
        }
        assert!(cpu::render(&frame, &s).is_err() && cpu::march(&frame, &s).is_err());
    }
    for s in [
        InterleavedSettings {
            ray_march: MarchSettings { steps: 1, ..Default::default() },
            block: 1,
            depth_tolerance: 0.0,
            phase_lut_size: 2,
            ..d()
        },
        InterleavedSettings {
            ray_march: MarchSettings { steps: 4096, ..Default::default() },
            policy: StepPolicy { denominator: 1.0, ..Default::default() },
            block: 16,
            phase_lut_size: 65536,
            ..d()
        },
    ] {
        assert!(s.validate().is_ok(), "{s:?}");
    }
    // Scene-file form: defaults for missing keys, kebab-case spot steps, unknown keys rejected.
    let s: InterleavedSettings = toml::from_str("").unwrap();
    assert_eq!(s, d());
    let s: InterleavedSettings =
        toml::from_str("block = 2\nsteps = 17\nspot_steps = \"exact-cone\"\nphase_lut = true").unwrap();
    assert_eq!(
        s,
        InterleavedSettings {
            ray_march: MarchSettings { steps: 17, ..Default::default() },
            policy: StepPolicy { spot: SpotSteps::ExactCone, ..Default::default() },
            block: 2,
            phase_lut: true,
            ..d()
        }
    );
    assert!(toml::from_str::<InterleavedSettings>("blocks = 2").is_err());
}

#[test]
fn raymarched_samples_count_every_pixels_terms() {
    for (w, h) in [(1, 1), (3, 2), (160, 90), (17, 33)] {
        for (block, steps) in [(1, 64), (2, 17), (3, 5), (4, 64), (4, 1), (16, 4096), (5, 100)] {
            let s = InterleavedSettings {
                ray_march: MarchSettings { steps: steps, ..Default::default() },
                block,
                ..Default::default()
            };
            let counted: u64 =
                (0..h).flat_map(|y| (0..w).map(move |x| (x, y))).map(|(x, y)| cpu::offset_terms(&s, x, y) as u64).sum();
            assert_eq!(s.raymarched_samples(w, h), counted, "{w}×{h} M={block} N={steps}");
        }
    }
    // Each complete M×M window holds all N terms.
    let s = InterleavedSettings {
        ray_march: MarchSettings { steps: 17, ..Default::default() },
        block: 3,
        ..Default::default()
    };
    let sum: u32 = (0..9).map(|k| s.terms_of_offset(k)).sum();
    assert_eq!(sum, 17);
}
