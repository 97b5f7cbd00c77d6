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
use crepuscular::{Image, Light, ShadowMap, TechniqueSettings};
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
/// ray through the standard shadow map — each of 20 000 steps weighs its light by the
/// reference's lookup (`ShadowMap::visibility` at its midpoint, with the light's filter:
/// bilinear by default) —, i.e. minmax is exact at the standard map's
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
                let v = sm.visibility(Vec3::ZERO, d.camera.position + dir * t, fl.shadow_bias, fl.shadow_filter);
                if v > 0.0 {
                    sum += v * f * (-st * (i as f32 * delta)).exp() * segment_transmittance(st, delta);
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

/// Texels with x + y < n hold an occluder at stored depth `d` on every layer of the map; the
/// rest are empty: a straight shadow edge across both texel axes.
fn diagonal_occluder(sm: &mut ShadowMap, d: f32) {
    let n = sm.projection.size as usize;
    for (i, v) in sm.depth.iter_mut().enumerate() {
        let (x, y) = (i % n, (i / n) % n);
        *v = if x + y < n { d } else { 1.0 };
    }
}

/// Pixel (x, y)'s ray marched densely through the frame's standard shadow map: 20 000 steps,
/// each the reference's lookup (`ShadowMap::visibility` under the light's filter) and light
/// at its midpoint. Returns the in-scattering, the same unshadowed, and the share of steps
/// with visibility below 1.
fn dense_march(d: &FrameDesc, depth: &[f32], sm: &ShadowMap, x: u32, y: u32) -> (Vec3, Vec3, f32) {
    let fl = &d.lights[0];
    let light_pos = crepuscular::integrand::light_position(&fl.light);
    let st = d.medium.extinction();
    let dir = d.pixel_ray(x, y);
    let s_end = d.view_distance(depth[(y * d.width + x) as usize], dir);
    let n = 20_000;
    let delta = s_end / n as f32;
    let (mut sum, mut open, mut dark) = (Vec3::ZERO, Vec3::ZERO, 0);
    for i in 0..n {
        let t = (i as f32 + 0.5) * delta;
        let p = d.camera.position + dir * t;
        let (l_in, wl) = crepuscular::integrand::light_incident(fl, &d.medium, p);
        let f = d.medium.scattering * d.medium.phase.eval(wl.dot(-dir)) * l_in;
        let step = f * (-st * (i as f32 * delta)).exp() * segment_transmittance(st, delta);
        let v = sm.visibility(light_pos, p, fl.shadow_bias, fl.shadow_filter);
        sum += step * v;
        open += step;
        dark += (v < 1.0) as u32;
    }
    (sum, open, dark as f32 / n as f32)
}

/// Mixed texels are resolved exactly under either shadow filter (docs/MODEL.md §8): a sun
/// (orthographic map), a spot (perspective) and a point light (cube map) over a diagonal
/// occluder in a coarse 64² map, where the bilinear filter's ramp spans many steps of a ray.
/// Every tenth pixel against its own dense march through the standard map (uniform segments
/// of the local lights, 1024 of them, so their quadrature adds nothing measurable), as a share
/// of the ray's unshadowed in-scattering. Measured 2026-12-07 (CPU), sun / spot / point:
/// nearest 2.0e-4 / 2.5e-4 / 2.3e-4, bilinear 1.3e-4 / 1.7e-4 / 4.6e-4 (the march's own
/// rounding and step; the point light's cube map, perspective, adds the quadratic fit of its
/// weights); each bound is 2.5× the worse of the two. The walk that read the nearest texel
/// whatever the filter (minmax before that day) is off the bilinear march by 8.7e-2 / 9.9e-3
/// / 6.6e-3, and must stay more than 4 bounds off.
#[test]
fn mixed_texels_are_exact_under_either_shadow_filter() {
    use crepuscular::ShadowFilter;
    let sun = common::sun();
    let spot = Light::Spot {
        position: Vec3::new(4.0, 10.0, -12.0),
        direction: Vec3::new(-0.3, -1.0, -0.2).normalize(),
        outer_angle_degrees: 50.0,
        inner_angle_degrees: 30.0,
        color: Vec3::new(1.0, 0.8, 0.6),
        intensity: 80.0,
        texture: None,
    };
    let lamp = Light::Point { position: Vec3::new(0.0, 8.0, -14.0), color: Vec3::new(1.0, 0.8, 0.6), intensity: 50.0 };
    let m = wall_media()[1].clone();
    let (w, h) = (48, 27);
    let (mut report, mut cases) = (vec![], vec![]);
    for (name, light, bound) in [("sun", sun, 5e-4), ("spot", spot, 6.5e-4), ("point", lamp, 1.2e-3)] {
        for filter in [ShadowFilter::Nearest, ShadowFilter::Bilinear] {
            let (mut d, depth, mut sm) = wall_frame(light.clone(), m.clone(), w, h);
            d.lights[0].shadow_filter = filter;
            diagonal_occluder(&mut sm, 0.5);
            let frame = cpu_frame(&d, &depth, &sm);
            let s = MinmaxSettings {
                epipole_radius: 0,
                light_steps: 1024,
                policy: StepPolicy { local: LocalSteps::Uniform, ..Default::default() },
                ..settings([256, 128], 8)
            };
            let (p, _) = cpu::passes(&frame, &s, None).unwrap();
            assert!(p.totals.mixed > 0, "{name}, {filter:?}: the edge must leave texels mixed");
            // The same walk reading the nearest texel whatever the filter (what minmax did
            // before 2026-12-07): the bilinear march must tell it apart.
            let mut d_near = d.clone();
            d_near.lights[0].shadow_filter = ShadowFilter::Nearest;
            let (near, _) = cpu::passes(&cpu_frame(&d_near, &depth, &sm), &s, None).unwrap();
            let (mut worst, mut worst_near, mut partly) = (0.0f32, 0.0f32, 0);
            for y in (0..h).step_by(3) {
                for x in (0..w).step_by(3) {
                    let (sum, open, dark) = dense_march(&d, &depth, &sm, x, y);
                    partly += (dark > 0.05 && dark < 0.95) as u32;
                    let i = (y * w + x) as usize;
                    let off = |img: &Image| {
                        (0..3).map(|k| (img.pixels[i][k] - sum[k]).abs() / open.max_element()).fold(0.0, f32::max)
                    };
                    worst = worst.max(off(&p.image));
                    worst_near = worst_near.max(off(&near.image));
                }
            }
            report.push(format!(
                "{name} {filter:?}: worst {worst:.2e} of the unshadowed ({worst_near:.2e} reading the nearest texel), {partly} rays partly shadowed"
            ));
            assert!(partly > 10, "{name}, {filter:?}: the frame must have partly shadowed rays: {partly}");
            assert!(
                worst < bound,
                "{name}, {filter:?}: off the dense march by {worst} of the unshadowed (bound {bound})"
            );
            if filter == ShadowFilter::Bilinear {
                assert!(
                    worst_near > 4.0 * bound,
                    "{name}: the nearest walk is only {worst_near} off the bilinear march"
                );
            }
            cases.push((format!("{name} {filter:?}"), d, depth, sm, s, p.image));
        }
    }
    eprintln!("{}", report.join("\n"));
    // The GPU's walk mirrors the CPU's on the same frames: the ramps of the bilinear filter
    // under both kinds of map, and the cube map's faces.
    let Some(gpu) = test_gpu("mixed_texels_are_exact_under_either_shadow_filter") else { return };
    for (case, d, depth, sm, s, cpu_img) in &cases {
        let g = common::gpu_technique(&gpu, &cpu_frame(d, depth, sm), TechniqueSettings::Minmax(s.clone()));
        let peak = cpu_img.pixels.iter().map(|q| q[1]).fold(0.0f32, f32::max);
        let worst = g.pixels.iter().zip(&cpu_img.pixels).map(|(a, b)| (a[1] - b[1]).abs() / peak).fold(0.0, f32::max);
        eprintln!("{case}: GPU off the CPU by {worst:.2e} of the peak at most");
        assert!(worst < 1e-3, "{case}: GPU off the CPU by {worst} of the peak");
    }
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
    for filter in [crepuscular::ShadowFilter::Nearest, crepuscular::ShadowFilter::Bilinear] {
        gpu_mirrors_cpu(&gpu, filter);
    }
}

/// [`the_gpu_passes_mirror_the_cpu`] under one shadow filter.
fn gpu_mirrors_cpu(gpu: &crepuscular::gpu::GpuContext, filter: crepuscular::ShadowFilter) {
    eprintln!("{filter:?}:");
    let gpu = gpu.clone();
    let m = wall_media()[1].clone();
    let (mut d, depth, sm, _) = half_plane_frame(m, 96, 54, 512);
    d.lights[0].shadow_filter = filter;
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
