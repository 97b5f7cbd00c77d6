//! Closed forms (docs/MODEL.md §4, rung 2): on occluder-free frames every technique must match the
//! known answer — the directional closed form σs·p·E·(1 − e^(−σt·s))/σt per pixel, and an
//! independent high-order quadrature for a point light.

mod common;

use crepuscular::frame::FrameDesc;
use crepuscular::gpu::test_gpu;
use crepuscular::march::{MarchSettings, StepPolicy};
use crepuscular::techniques::brute_force::{self, BruteForceSettings};
use crepuscular::techniques::reference::{self, ReferenceSettings};
use crepuscular::testing::{WALL_DISTANCE, wall_closed_form, wall_frame, wall_frame_lights};
use crepuscular::{CpuFrame, Image, Light, Medium, ShadowMap};
use glam::{DVec3, Vec3};

const W: u32 = 64;
const H: u32 = 36;

/// The wall frame (a wall 30 m down −Z, empty shadow map: V = 1) at W × H.
fn frame(light: Light, medium: Medium) -> (FrameDesc, Vec<f32>, ShadowMap) {
    wall_frame(light, medium, W, H)
}

fn ray(desc: &FrameDesc, x: u32, y: u32) -> (DVec3, f64) {
    let inv = desc.camera.view_proj().as_dmat4().inverse();
    let ndc_x = (x as f64 + 0.5) / W as f64 * 2.0 - 1.0;
    let ndc_y = 1.0 - (y as f64 + 0.5) / H as f64 * 2.0;
    let dir = inv.project_point3(DVec3::new(ndc_x, ndc_y, 1.0)).normalize();
    let s = WALL_DISTANCE as f64 / dir.dot(DVec3::NEG_Z);
    (dir, s)
}

fn directional_closed_form(desc: &FrameDesc) -> Image {
    common::image_of(W, H, |x, y| wall_closed_form(desc, x, y))
}

/// Composite Gauss–Legendre (5 points × 4096 panels) of the point-light integral, f64.
fn point_quadrature(desc: &FrameDesc) -> Image {
    point_quadrature_of(desc, 0)
}

/// [`point_quadrature`] of light `k` of the frame.
fn point_quadrature_of(desc: &FrameDesc, k: usize) -> Image {
    let Light::Point { position, color, intensity } = &desc.lights[k].light else { unreachable!() };
    let st = desc.medium.extinction().as_dvec3();
    let ss = desc.medium.scattering.as_dvec3();
    let lp = position.as_dvec3();
    let gl = [
        (0.0, 0.568888888888889),
        (-0.538469310105683, 0.478628670499366),
        (0.538469310105683, 0.478628670499366),
        (-0.906179845938664, 0.236926885056189),
        (0.906179845938664, 0.236926885056189),
    ];
    let mut img = Image::new(W, H);
    for y in 0..H {
        for x in 0..W {
            let (dir, s) = ray(desc, x, y);
            let panels = 4096;
            let h = s / panels as f64;
            let mut sum = DVec3::ZERO;
            for k in 0..panels {
                for (xi, wi) in gl {
                    let t = (k as f64 + 0.5 + 0.5 * xi) * h;
                    let v = dir * t - lp;
                    let d = v.length();
                    let wl = v / d;
                    let p = DVec3::from(desc.medium.phase.eval_f64(-wl.dot(dir)));
                    let f =
                        (-st * t).exp() * ss * p * color.as_dvec3() * (*intensity as f64) * (-st * d).exp() / (d * d);
                    sum += f * wi * 0.5 * h;
                }
            }
            img.pixels[(y * W + x) as usize] = [sum.x as f32, sum.y as f32, sum.z as f32, 1.0];
        }
    }
    img
}

use crepuscular::testing::wall_media as media;

use common::{cpu_frame, sun};

/// The largest relative error of `reference` at `settings` on the one-light frame against `exact`.
fn reference_off(d: &FrameDesc, depth: &[f32], sm: &ShadowMap, settings: ReferenceSettings, exact: &Image) -> f32 {
    let (img, _) = reference::render(&cpu_frame(d, depth, sm), &settings, &|_, _| {}).unwrap();
    common::max_rel(&img, exact, 1e-9)
}

#[test]
fn directional_reference_matches_the_closed_form_tightly() {
    for m in media() {
        let (d, depth, sm) = frame(sun(), m.clone());
        let e =
            reference_off(&d, &depth, &sm, ReferenceSettings { steps: 1024, seed: 3 }, &directional_closed_form(&d));
        assert!(e < 1e-3, "{m:?}: reference off the closed form by {e}");
    }
}

#[test]
fn directional_brute_force_matches_the_closed_form() {
    // With exact per-step transmittance, an unshadowed sun is integrated exactly at any step
    // count; what remains is f32 rounding.
    for m in media() {
        let (d, depth, sm) = frame(sun(), m.clone());
        let exact = directional_closed_form(&d);
        for steps in [1, 8, 64] {
            let s = BruteForceSettings {
                ray_march: MarchSettings { steps: steps, ..Default::default() },
                ..Default::default()
            };
            let (img, _) = brute_force::cpu::march(&cpu_frame(&d, &depth, &sm), &s).unwrap();
            let e = common::max_rel(&img, &exact, 1e-9);
            assert!(e < 1e-4, "{m:?}, {steps} steps: brute-force off the closed form by {e}");
        }
    }
}

#[test]
fn directional_brute_force_on_the_gpu_matches_the_closed_form() {
    let Some(gpu) = test_gpu("directional_brute_force_on_the_gpu_matches_the_closed_form") else { return };
    for m in media() {
        let (d, depth, sm) = frame(sun(), m.clone());
        let exact = directional_closed_form(&d);
        let img = common::gpu_brute_force(&gpu, &cpu_frame(&d, &depth, &sm), &BruteForceSettings::default());
        let e = common::max_rel(&img, &exact, 1e-9);
        assert!(e < 1e-3, "{m:?}: GPU brute-force off the closed form by {e}");
    }
}

fn lamp() -> Light {
    Light::Point { position: Vec3::new(0.0, 12.0, -14.0), color: Vec3::new(1.0, 0.8, 0.6), intensity: 50.0 }
}

/// A lamp 3.5 cm from the view rays that pass nearest it, on screen: its 1/d² peak is a few
/// centimetres wide on 30 m rays.
fn lamp_by_the_rays() -> Light {
    Light::Point { position: Vec3::new(0.031, 0.017, -14.0), color: Vec3::new(1.0, 0.8, 0.6), intensity: 50.0 }
}

#[test]
fn point_light_reference_matches_an_independent_quadrature() {
    // The reference's strata are equal in the angle seen from a local light (docs/MODEL.md §9),
    // so the lamp by the rays converges as fast as the one far from them. Measured worst over
    // the media at 2048 strata: 1.8e-4 (far lamp), 2.6e-4 (lamp by the rays); strata equal in
    // transmittance measured 3.1e-5 and 2.6e-3, so the bound tells the two layouts apart.
    for lamp in [lamp(), lamp_by_the_rays()] {
        for m in media() {
            let (d, depth, sm) = frame(lamp.clone(), m.clone());
            let e = reference_off(&d, &depth, &sm, ReferenceSettings { steps: 2048, seed: 5 }, &point_quadrature(&d));
            assert!(e < 1e-3, "{lamp:?}, {m:?}: reference off the quadrature by {e}");
        }
    }
}

#[test]
fn point_light_brute_force_is_within_its_step_error() {
    // Midpoint sampling of the 1/d² peak, with the light off screen (rays pass ≥ ~3 m from it):
    // the step error at the default 64 steps is bounded in the README, and falls with more steps
    // down to f32 rounding.
    // Both step layouts (docs/MODEL.md §9): equal steps, and the default equal angles, which
    // put their steps where the rays pass the light and are coarser far from it, so on this
    // smooth frame their worst pixel converges more slowly.
    use crepuscular::march::LocalSteps;
    let layouts = [
        (LocalSteps::Uniform, [(16, 0.05), (64, 0.005), (256, 5e-4)]),
        // Measured worst over the media: 0.072, 4.7e-3, 2.8e-4 (uniform: 4.0e-3, 2.4e-4, 3.2e-5).
        (LocalSteps::Equiangular, [(16, 0.09), (64, 0.007), (256, 4e-4)]),
    ];
    for m in media() {
        let (d, depth, sm) = frame(lamp(), m.clone());
        let exact = point_quadrature(&d);
        for (local, bounds) in layouts {
            let mut last = f32::MAX;
            for (steps, bound) in bounds {
                let s = BruteForceSettings {
                    ray_march: MarchSettings { steps: steps, ..Default::default() },
                    policy: StepPolicy { local: local, ..Default::default() },
                    ..Default::default()
                };
                let (img, _) = brute_force::cpu::march(&cpu_frame(&d, &depth, &sm), &s).unwrap();
                let e = common::max_rel(&img, &exact, 1e-9);
                eprintln!("{local:?}, {steps}: {e}");
                assert!(e < bound, "{m:?}, {local:?}, {steps} steps: off by {e} (bound {bound})");
                assert!(e < last, "error must fall with more steps");
                last = e;
            }
        }
    }
}

// ---- several lights (docs/MODEL.md §6): the in-scattering is the sum over the lights ----

fn second_sun() -> Light {
    Light::Directional {
        direction: Vec3::new(-0.45, -0.3, 1.0).normalize(),
        color: Vec3::new(0.6, 0.7, 1.0),
        intensity: 2.5,
    }
}

fn cpu_frame_of<'a>(d: &'a FrameDesc, depth: &'a [f32], maps: &'a [ShadowMap]) -> CpuFrame<'a> {
    CpuFrame { desc: d, depth, shadow_maps: maps, surface: None }
}

#[test]
fn two_suns_match_the_sum_of_their_closed_forms() {
    for m in media() {
        let (d, depth, maps) = wall_frame_lights(vec![sun(), second_sun()], m.clone(), W, H);
        // wall_closed_form sums the frame's suns; check it is the sum of the two one-sun forms.
        let exact = directional_closed_form(&d);
        let (one, two) = (directional_closed_form(&d.with_light(0)), directional_closed_form(&d.with_light(1)));
        for ((e, a), b) in exact.pixels.iter().zip(&one.pixels).zip(&two.pixels) {
            for c in 0..3 {
                assert!((e[c] - (a[c] + b[c])).abs() <= 1e-6 * e[c].abs().max(1e-9));
            }
        }
        let frame = cpu_frame_of(&d, &depth, &maps);
        let (img, _) = reference::render(&frame, &ReferenceSettings { steps: 1024, seed: 3 }, &|_, _| {}).unwrap();
        let e = common::max_rel(&img, &exact, 1e-9);
        assert!(e < 1e-3, "{m:?}: reference off the two suns' closed form by {e}");
        for steps in [1, 8, 64] {
            let s = BruteForceSettings {
                ray_march: MarchSettings { steps: steps, ..Default::default() },
                ..Default::default()
            };
            let (img, _) = brute_force::cpu::march(&frame, &s).unwrap();
            let e = common::max_rel(&img, &exact, 1e-9);
            assert!(e < 1e-4, "{m:?}, {steps} steps: brute-force off the two suns' closed form by {e}");
        }
    }
}

#[test]
fn two_suns_on_the_gpu_match_the_sum_of_their_closed_forms() {
    let Some(gpu) = test_gpu("two_suns_on_the_gpu_match_the_sum_of_their_closed_forms") else { return };
    for m in media() {
        let (d, depth, maps) = wall_frame_lights(vec![sun(), second_sun()], m.clone(), W, H);
        let exact = directional_closed_form(&d);
        let img = common::gpu_brute_force(&gpu, &cpu_frame_of(&d, &depth, &maps), &BruteForceSettings::default());
        let e = common::max_rel(&img, &exact, 1e-9);
        assert!(e < 1e-3, "{m:?}: GPU brute-force off the two suns' closed form by {e}");
    }
}

#[test]
fn a_sun_and_a_point_light_match_closed_form_plus_quadrature() {
    for m in media() {
        let (d, depth, maps) = wall_frame_lights(vec![sun(), lamp()], m.clone(), W, H);
        let sun_only = directional_closed_form(&d.with_light(0));
        let point = point_quadrature_of(&d, 1);
        let mut exact = sun_only.clone();
        for (e, p) in exact.pixels.iter_mut().zip(&point.pixels) {
            for c in 0..3 {
                e[c] += p[c];
            }
        }
        let frame = cpu_frame_of(&d, &depth, &maps);
        let (img, _) = reference::render(&frame, &ReferenceSettings { steps: 2048, seed: 5 }, &|_, _| {}).unwrap();
        let e = common::max_rel(&img, &exact, 1e-9);
        assert!(e < 5e-3, "{m:?}: reference off closed form + quadrature by {e}");
        // The point light's step error at 256 steps (point_light_brute_force_is_within_its_step_error)
        // bounds the sum's: the sun's share is exact at any step count.
        let s =
            BruteForceSettings { ray_march: MarchSettings { steps: 256, ..Default::default() }, ..Default::default() };
        let (img, _) = brute_force::cpu::march(&frame, &s).unwrap();
        let e = common::max_rel(&img, &exact, 1e-9);
        assert!(e < 5e-4, "{m:?}: brute-force at 256 steps off closed form + quadrature by {e}");
    }
}

// ---- the scattering distance brute-force writes for the temporal stage (docs/MODEL.md §7) ----

/// The point light's scattering distance per pixel by the same quadrature as
/// [`point_quadrature`]: Σ Y(f)·t / Σ Y(f), Y the Rec. 709 luminance of the integrand f.
fn point_scattering_distance(desc: &FrameDesc) -> Vec<f64> {
    let Light::Point { position, color, intensity } = &desc.lights[0].light else { unreachable!() };
    let st = desc.medium.extinction().as_dvec3();
    let ss = desc.medium.scattering.as_dvec3();
    let lp = position.as_dvec3();
    let lum = DVec3::new(0.2126, 0.7152, 0.0722);
    let mut out = Vec::new();
    for y in 0..H {
        for x in 0..W {
            let (dir, s) = ray(desc, x, y);
            let panels = 8192;
            let h = s / panels as f64;
            let (mut yt, mut yy) = (0.0, 0.0);
            for k in 0..panels {
                for (xi, wi) in [(-0.577350269189626, 0.5), (0.577350269189626, 0.5)] {
                    let t = (k as f64 + 0.5 + 0.5 * xi) * h;
                    let v = dir * t - lp;
                    let d = v.length();
                    let p = DVec3::from(desc.medium.phase.eval_f64(-(v / d).dot(dir)));
                    let f =
                        (-st * t).exp() * ss * p * color.as_dvec3() * (*intensity as f64) * (-st * d).exp() / (d * d);
                    let l = f.dot(lum) * wi * h;
                    yt += l * t;
                    yy += l;
                }
            }
            out.push(yt / yy);
        }
    }
    out
}

#[test]
fn brute_force_writes_the_scattering_distance_of_its_local_lights_and_none_for_a_sun() {
    // A point light alone: every pixel's alpha is minus the luminance-weighted mean distance of
    // its in-scattering along the ray, found from the march's own 64 equiangular samples; a
    // sun alone gives none (alpha 0: the stage uses the surface). The GPU writes what the CPU
    // writes.
    let gpu = test_gpu("brute_force_writes_the_scattering_distance_of_its_local_lights_and_none_for_a_sun");
    let mut worst = 0.0f64;
    for m in media().into_iter().filter(|m| m.scattering.min_element() > 0.0) {
        let (d, depth, sm) = frame(lamp(), m.clone());
        let exact = point_scattering_distance(&d);
        let s = BruteForceSettings::default();
        let (img, _) = brute_force::cpu::march(&cpu_frame(&d, &depth, &sm), &s).unwrap();
        for (p, e) in img.pixels.iter().zip(&exact) {
            assert!(p[3] < 0.0, "{m:?}: a pixel lit by the lamp has no scattering distance ({})", p[3]);
            worst = worst.max((-p[3] as f64 - e).abs() / e);
        }
        if let Some(gpu) = &gpu {
            let g = common::gpu_brute_force(gpu, &cpu_frame(&d, &depth, &sm), &s);
            let apart =
                g.pixels.iter().zip(&img.pixels).map(|(a, b)| (a[3] - b[3]).abs() / b[3].abs()).fold(0.0, f32::max);
            eprintln!("{m:?}: GPU scattering distance within {apart:.1e} of the CPU's");
            assert!(apart < 1e-4, "{m:?}: the GPU's scattering distance is {apart} from the CPU's");
        }
        let (sd, sdepth, ssm) = frame(sun(), m.clone());
        let (img, _) = brute_force::cpu::march(&cpu_frame(&sd, &sdepth, &ssm), &s).unwrap();
        assert!(img.pixels.iter().all(|p| p[3] == 0.0), "{m:?}: a sun gave a scattering distance");
    }
    eprintln!("scattering distance of a point light, 64 equiangular steps: worst relative error {worst:.2e}");
    // Measured: 4.7e-3 of the distance (the 64 steps' own quadrature error; the distances are
    // 10–30 m, so a few centimetres).
    assert!(worst < 7e-3, "brute-force's scattering distance is off by {worst} of the exact one");
}
