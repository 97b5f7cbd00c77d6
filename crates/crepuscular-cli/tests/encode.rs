//! The engine's way in: `Scattering::encode` records into the caller's encoder and submits
//! nothing — proven by reading the output between `encode` and the caller's submit (still the
//! sentinel the test wrote) and after it (the frame) — records several frames into one encoder,
//! delivers its deferred counters after `end_frame`, and refuses inputs that do not match the
//! frame with an error naming them.

use crepuscular::gpu::{GpuContext, test_gpu};
use crepuscular::{Error, GpuFrame, Scattering, StatsMode, TechniqueSettings};
use crepuscular_cli::render::{frame_desc, parse_technique};
use crepuscular_scene::{GpuHost, Scene, builtin};

fn small(name: &str) -> Scene {
    let mut s = builtin::builtin(name).expect("built-in scene");
    s.render.width = 80;
    s.render.height = 45;
    s.render.shadow.size = 256;
    s
}

/// The GPU techniques at settings sized for an 80×45 frame.
fn techniques(scene: &Scene) -> Vec<TechniqueSettings> {
    let list = [
        ("brute-force", &["steps=24"][..]),
        ("interleaved", &["steps=32"]),
        ("subsampled", &["steps=24"]),
        ("epipolar", &["slices=64", "samples=48"]),
        ("prefiltered", &["map_size=[128, 128]"]),
        ("minmax", &["map_size=[128, 128]"]),
    ];
    // Every registered technique with a GPU side is here: a new one fails this test until it is given settings.
    for info in crepuscular::techniques::TECHNIQUES.iter().filter(|i| i.gpu) {
        assert!(list.iter().any(|(t, _)| *t == info.name), "no test settings for `{}`", info.name);
    }
    list.iter()
        .map(|(t, set)| {
            let set: Vec<String> = set.iter().map(|s| s.to_string()).collect();
            parse_technique(t, scene, &set).unwrap()
        })
        .collect()
}

fn read(gpu: &GpuContext, t: &wgpu::Texture) -> Vec<u32> {
    gpu.read_texture_f32(t, 0).unwrap().into_iter().map(f32::to_bits).collect()
}

/// An output texture filled with `value` in every channel.
fn filled_output(gpu: &GpuContext, w: u32, h: u32, value: f32) -> wgpu::Texture {
    // An engine's own target: storage for the effect, copy destination for the sentinel.
    let t = gpu.device.create_texture(&wgpu::TextureDescriptor {
        label: Some("engine target"),
        size: wgpu::Extent3d { width: w, height: h, depth_or_array_layers: 1 },
        mip_level_count: 1,
        sample_count: 1,
        dimension: wgpu::TextureDimension::D2,
        format: wgpu::TextureFormat::Rgba32Float,
        usage: wgpu::TextureUsages::STORAGE_BINDING | wgpu::TextureUsages::COPY_SRC | wgpu::TextureUsages::COPY_DST,
        view_formats: &[],
    });
    gpu.queue.write_texture(
        t.as_image_copy(),
        bytemuck::cast_slice(&vec![value; (w * h * 4) as usize]),
        wgpu::TexelCopyBufferLayout { offset: 0, bytes_per_row: Some(w * 16), rows_per_image: Some(h) },
        wgpu::Extent3d { width: w, height: h, depth_or_array_layers: 1 },
    );
    t
}

#[test]
fn encode_records_into_the_callers_encoder_and_never_submits() {
    let Some(gpu) = test_gpu("encode_records_into_the_callers_encoder_and_never_submits") else { return };
    let sentinel = 7.25f32;
    for scene_name in ["colonnade", "cage", "stained-glass"] {
        let scene = small(scene_name);
        let desc = frame_desc(&scene).unwrap();
        let (w, h) = (desc.width, desc.height);
        let host = GpuHost::for_scene(&gpu, &scene).unwrap();
        let tex = host.render(&gpu, &desc).unwrap();
        let views = tex.views();
        let frame = views.frame(&desc);
        for settings in techniques(&scene) {
            let name = settings.name();
            // The engine's constructor: its own device and queue, nothing else.
            let mut sc = Scattering::new(&gpu.device, &gpu.queue, settings).unwrap();
            assert_eq!(sc.stats_mode(), StatsMode::Deferred);
            let expected_tex = gpu.create_output_texture(w, h);
            sc.render(&frame, &expected_tex.create_view(&Default::default())).unwrap();
            let expected = read(&gpu, &expected_tex);
            assert!(expected.iter().any(|&b| f32::from_bits(b) > 0.0), "{scene_name} {name}: a black frame");

            let out = filled_output(&gpu, w, h, sentinel);
            let mut encoder = gpu.device.create_command_encoder(&Default::default());
            sc.encode(&mut encoder, &frame, &out.create_view(&Default::default())).unwrap();
            // Everything encode recorded is still in the caller's encoder: the GPU has run
            // all submitted work (this readback waits for it) and the output is untouched.
            let before = read(&gpu, &out);
            assert!(
                before.iter().all(|&b| b == sentinel.to_bits()),
                "{scene_name} {name}: encode wrote the output before the caller submitted"
            );
            gpu.queue.submit([encoder.finish()]);
            sc.end_frame();
            assert_eq!(read(&gpu, &out), expected, "{scene_name} {name}: the submitted frame differs");

            // Two different frames (the second with a denser medium) into one encoder, one
            // submit: each is its own frame (the uniforms are uploaded in order inside the
            // encoder, not by the queue before it).
            let mut denser = desc.clone();
            denser.medium.scattering *= 2.0;
            let frame2 = GpuFrame { desc: &denser, ..frame };
            let expected2_tex = gpu.create_output_texture(w, h);
            sc.render(&frame2, &expected2_tex.create_view(&Default::default())).unwrap();
            let expected2 = read(&gpu, &expected2_tex);
            assert_ne!(expected2, expected, "{scene_name} {name}: the denser medium changed nothing");
            let (a, b) = (filled_output(&gpu, w, h, sentinel), filled_output(&gpu, w, h, sentinel));
            let mut encoder = gpu.device.create_command_encoder(&Default::default());
            sc.encode(&mut encoder, &frame, &a.create_view(&Default::default())).unwrap();
            sc.encode(&mut encoder, &frame2, &b.create_view(&Default::default())).unwrap();
            gpu.queue.submit([encoder.finish()]);
            sc.end_frame();
            assert_eq!(read(&gpu, &a), expected, "{scene_name} {name}: the first of two frames in one encoder");
            assert_eq!(read(&gpu, &b), expected2, "{scene_name} {name}: the second of two frames in one encoder");
            // Both frames' stats arrive (the readback above waited for the GPU).
            let stats = sc.stats().expect("the frames' stats").clone();
            assert_eq!(stats.technique, name);
            assert!(!stats.passes.is_empty(), "{name}: no passes in the stats");
            eprintln!("{scene_name} {name}: ok ({} passes, timing {})", stats.passes.len(), stats.timing);
        }
    }
}

#[test]
fn deferred_counters_arrive_after_the_frame_and_match_the_wall_clock_ones() {
    let Some(gpu) = test_gpu("deferred_counters_arrive_after_the_frame_and_match_the_wall_clock_ones") else {
        return;
    };
    let scene = small("colonnade");
    let desc = frame_desc(&scene).unwrap();
    let host = GpuHost::for_scene(&gpu, &scene).unwrap();
    let tex = host.render(&gpu, &desc).unwrap();
    let views = tex.views();
    let frame = views.frame(&desc);
    let out = gpu.create_output_texture(desc.width, desc.height);
    let out_view = out.create_view(&Default::default());
    for settings in techniques(&scene) {
        let name = settings.name();
        let mut measured =
            Scattering::from_gpu(&gpu, settings.clone()).unwrap().with_stats(StatsMode::WallClock).unwrap();
        let want = measured.render(&frame, &out_view).unwrap();
        let mut sc = Scattering::from_gpu(&gpu, settings).unwrap();
        let mut encoder = gpu.device.create_command_encoder(&Default::default());
        sc.encode(&mut encoder, &frame, &out_view).unwrap();
        assert!(sc.stats().is_none(), "{name}: stats before the frame was submitted");
        gpu.queue.submit([encoder.finish()]);
        sc.end_frame();
        gpu.wait().unwrap();
        let got = sc.stats().expect("the frame's stats after the GPU finished").clone();
        assert_eq!(got.raymarched_samples, want.raymarched_samples, "{name}");
        assert_eq!(got.extra, want.extra, "{name}");
        let names =
            |s: &crepuscular::stats::TechniqueStats| s.passes.iter().map(|p| p.name.clone()).collect::<Vec<_>>();
        assert_eq!(names(&got), names(&want), "{name}");
        assert_eq!(want.timing, "wall-clock");
        let expected_timing = if gpu.timestamps { "timestamp-queries" } else { "unmeasured" };
        assert_eq!(got.timing, expected_timing, "{name}");
    }
}

#[test]
fn inputs_that_do_not_match_the_frame_are_errors_naming_them() {
    let Some(gpu) = test_gpu("inputs_that_do_not_match_the_frame_are_errors_naming_them") else { return };
    let scene = small("colonnade");
    let desc = frame_desc(&scene).unwrap();
    let host = GpuHost::for_scene(&gpu, &scene).unwrap();
    let tex = host.render(&gpu, &desc).unwrap();
    let views = tex.views();
    let frame = views.frame(&desc);
    let mut sc = Scattering::from_gpu(&gpu, TechniqueSettings::named("brute-force").unwrap()).unwrap();
    let check = |sc: &mut Scattering, frame: &GpuFrame, out: &wgpu::Texture, key: &str, why: &str| {
        let mut encoder = gpu.device.create_command_encoder(&Default::default());
        match sc.encode(&mut encoder, frame, &out.create_view(&Default::default())) {
            Err(e @ Error::Invalid { .. }) => {
                let m = e.to_string();
                assert!(m.contains(key) && m.contains(why), "{key}: {m}");
                eprintln!("{m}");
            }
            other => panic!("{key}: expected an error, got {other:?}"),
        }
    };
    let small_out = gpu.create_output_texture(desc.width / 2, desc.height);
    check(&mut sc, &frame, &small_out, "output", "frame's size");
    let rgba8 = crepuscular::gpu::storage_texture(
        &gpu.device,
        "wrong",
        wgpu::TextureFormat::Rgba8Unorm,
        desc.width,
        desc.height,
    );
    check(&mut sc, &frame, &rgba8, "output", "Rgba32Float");
    let out = gpu.create_output_texture(desc.width, desc.height);
    // A depth buffer of another size.
    let other = small("colonnade");
    let mut other_desc = frame_desc(&other).unwrap();
    other_desc.width = 40;
    other_desc.height = 30;
    let other_tex = host.render(&gpu, &other_desc).unwrap();
    let other_views = other_tex.views();
    let other_frame = other_views.frame(&other_desc);
    check(&mut sc, &GpuFrame { depth: other_frame.depth, ..frame }, &out, "depth", "frame's size");
    // A point light's frame with a one-layer shadow map.
    let mut point = desc.clone();
    point.lights[0].light = builtin::builtin("cage").unwrap().lights[0].light.clone();
    point.lights[0].shadow.layers = 6;
    check(&mut sc, &GpuFrame { desc: &point, ..frame }, &out, "shadow_maps", "lights[0] (point) needs layers 0..6");
    // NaN or a negative coefficient, a light or shadow projection that cannot be evaluated:
    // refused before any pass runs, naming the field (never a NaN in the output).
    let mut bad = |edit: &dyn Fn(&mut crepuscular::FrameDesc), key: &str, why: &str| {
        let mut d = desc.clone();
        edit(&mut d);
        check(&mut sc, &GpuFrame { desc: &d, ..frame }, &out, key, why);
    };
    bad(&|d| d.medium.scattering.y = f32::NAN, "medium.scattering", "finite");
    bad(&|d| d.medium.absorption.x = -0.1, "medium.absorption", "≥ 0");
    bad(&|d| d.medium.phase = crepuscular::Phase::HenyeyGreenstein { g: 1.0 }, "medium.phase.g", "(−1, 1)");
    bad(
        &|d| {
            if let crepuscular::Light::Directional { direction, .. } = &mut d.lights[0].light {
                *direction = glam::Vec3::ZERO;
            }
        },
        "lights[0].direction",
        "non-zero",
    );
    bad(
        &|d| {
            if let crepuscular::Light::Directional { intensity, .. } = &mut d.lights[0].light {
                *intensity = f32::INFINITY;
            }
        },
        "lights[0].intensity",
        "finite",
    );
    bad(&|d| d.lights[0].shadow.view_proj[0] = glam::Mat4::ZERO, "lights[0].shadow.view_proj[0]", "invertible");
    bad(&|d| d.lights[0].shadow.far = d.lights[0].shadow.near, "lights[0].shadow.far", "far > near");
    bad(&|d| d.lights[0].shadow.texel_world = f32::NAN, "lights[0].shadow.texel_world", "finite");
    // The real thing still renders.
    let mut encoder = gpu.device.create_command_encoder(&Default::default());
    sc.encode(&mut encoder, &frame, &out.create_view(&Default::default())).unwrap();
}

#[test]
fn bind_groups_are_built_on_resize_and_new_inputs_not_per_frame() {
    let Some(gpu) = test_gpu("bind_groups_are_built_on_resize_and_new_inputs_not_per_frame") else { return };
    let scene = small("colonnade");
    let desc = frame_desc(&scene).unwrap();
    let host = GpuHost::for_scene(&gpu, &scene).unwrap();
    let tex = host.render(&gpu, &desc).unwrap();
    let views = tex.views();
    let frame = views.frame(&desc);
    let out = gpu.create_output_texture(desc.width, desc.height);
    let out_view = out.create_view(&Default::default());
    for settings in techniques(&scene) {
        let name = settings.name();
        let mut sc = Scattering::from_gpu(&gpu, settings).unwrap();
        for _ in 0..3 {
            sc.render(&frame, &out_view).unwrap();
        }
        assert_eq!(sc.technique().bind_group_builds(), 1, "{name}: three frames of the same inputs");
        // Another output texture (an engine's second swap target): rebuilt once, then kept.
        let other = gpu.create_output_texture(desc.width, desc.height);
        let other_view = other.create_view(&Default::default());
        sc.render(&frame, &other_view).unwrap();
        sc.render(&frame, &other_view).unwrap();
        assert_eq!(sc.technique().bind_group_builds(), 2, "{name}: a new output");
        // A resize.
        let mut half = small("colonnade");
        half.render.width = 40;
        half.render.height = 22;
        let half_desc = frame_desc(&half).unwrap();
        let half_tex = host.render(&gpu, &half_desc).unwrap();
        let half_views = half_tex.views();
        let half_out = gpu.create_output_texture(40, 22);
        let half_out_view = half_out.create_view(&Default::default());
        for _ in 0..2 {
            sc.render(&half_views.frame(&half_desc), &half_out_view).unwrap();
        }
        assert_eq!(sc.technique().bind_group_builds(), 3, "{name}: a resize");
    }
}

/// PSNR floors (dB) of the `Rgba16Float` frame against the `Rgba32Float` one, per scene, for
/// the techniques whose radiance intermediates follow the output format
/// (`pass::intermediate_format`: interleaved's partial sums, subsampled's grid, epipolar's
/// marched and interpolated samples). Measured 2026-12-07 at the bilinear default (llvmpipe,
/// 80×45): colonnade 75.9 / 74.5 / 71.6 dB, cage 84.7 / 96.5 / 102.8 dB (interleaved /
/// subsampled / epipolar; the techniques without such intermediates: 78.0–78.1 and
/// 104.4–105.0 dB, the output's own rounding). Each floor is 2 dB below its measurement.
const HALF_INTERMEDIATES_PSNR: &[(&str, &str, f64)] = &[
    ("colonnade", "interleaved", 73.9),
    ("colonnade", "subsampled", 72.5),
    ("colonnade", "epipolar", 69.6),
    ("cage", "interleaved", 82.7),
    ("cage", "subsampled", 94.5),
    ("cage", "epipolar", 100.8),
];

#[test]
fn rgba16float_output_costs_at_most_the_half_float_rounding_of_its_intermediates() {
    let Some(gpu) = test_gpu("rgba16float_output_costs_at_most_the_half_float_rounding_of_its_intermediates") else {
        return;
    };
    for scene_name in ["colonnade", "cage"] {
        let scene = small(scene_name);
        let desc = frame_desc(&scene).unwrap();
        let (w, h) = (desc.width, desc.height);
        let host = GpuHost::for_scene(&gpu, &scene).unwrap();
        let tex = host.render(&gpu, &desc).unwrap();
        let views = tex.views();
        let frame = views.frame(&desc);
        for settings in techniques(&scene) {
            let name = settings.name();
            let mut full = Scattering::from_gpu(&gpu, settings.clone()).unwrap();
            let full_out = gpu.create_output_texture(w, h);
            full.render(&frame, &full_out.create_view(&Default::default())).unwrap();
            let full_memory = full.technique().gpu_memory_bytes();
            let want = gpu.read_texture_f32(&full_out, 0).unwrap();

            let mut half = Scattering::from_gpu(&gpu, settings).unwrap();
            half = half.with_output_format(wgpu::TextureFormat::Rgba16Float).unwrap();
            assert_eq!(half.output_format(), wgpu::TextureFormat::Rgba16Float);
            // The Rgba32Float target is now refused, naming the format.
            let mut enc = gpu.device.create_command_encoder(&Default::default());
            let e = half.encode(&mut enc, &frame, &full_out.create_view(&Default::default())).unwrap_err();
            assert!(e.to_string().contains("Rgba16Float"), "{e}");
            let half_out =
                crepuscular::gpu::storage_texture(&gpu.device, "half", wgpu::TextureFormat::Rgba16Float, w, h);
            half.render(&frame, &half_out.create_view(&Default::default())).unwrap();
            let half_memory = half.technique().gpu_memory_bytes();
            let got = gpu.read_texture_f32(&half_out, 0).unwrap();
            assert_eq!(got.len(), want.len());
            let floor = HALF_INTERMEDIATES_PSNR.iter().find(|(s, t, _)| *s == scene_name && *t == name).map(|r| r.2);
            let (mut se, mut peak) = (0.0f64, 0.0f64);
            for (i, (g, f)) in got.iter().zip(&want).enumerate() {
                if i % 4 == 3 {
                    continue; // alpha
                }
                assert!(g.is_finite(), "{scene_name} {name}: {g}");
                if floor.is_none() {
                    // No radiance intermediate: every value is the f32 frame's value converted
                    // to a half float, within one half ulp (relative 2⁻¹⁰; the conversion may
                    // truncate rather than round — llvmpipe's does — and subnormals are 2⁻²⁴
                    // apart): the technique computed exactly the same.
                    assert!(
                        (g - f).abs() <= f.abs() * 2f32.powi(-10) + 2f32.powi(-24),
                        "{scene_name} {name}: {g} vs {f}"
                    );
                }
                se += ((g - f) as f64).powi(2);
                peak = peak.max(*f as f64);
            }
            let mse = se / (w * h * 3) as f64;
            let psnr = 10.0 * (peak * peak / mse.max(1e-30)).log10();
            eprintln!(
                "{scene_name} {name}: Rgba16Float vs Rgba32Float output: PSNR {psnr:.1} dB (peak {peak:.3}); memory {half_memory} vs {full_memory} bytes"
            );
            assert!(peak > 1e-3, "{scene_name} {name}: a black frame");
            if let Some(floor) = floor {
                assert!(psnr >= floor, "{scene_name} {name}: PSNR {psnr:.1} dB below {floor}");
                assert!(half_memory < full_memory, "{scene_name} {name}: its intermediates did not shrink");
            } else {
                assert_eq!(half_memory, full_memory, "{scene_name} {name}");
            }
        }
    }
}

#[test]
fn a_frame_loop_that_never_asks_for_stats_keeps_at_most_three_frames_in_flight() {
    let Some(gpu) = test_gpu("a_frame_loop_that_never_asks_for_stats_keeps_at_most_three_frames_in_flight") else {
        return;
    };
    let scene = small("colonnade");
    let desc = frame_desc(&scene).unwrap();
    let host = GpuHost::for_scene(&gpu, &scene).unwrap();
    let tex = host.render(&gpu, &desc).unwrap();
    let views = tex.views();
    let frame = views.frame(&desc);
    let out = gpu.create_output_texture(desc.width, desc.height);
    let out_view = out.create_view(&Default::default());
    // Subsampled reads back a GPU counter every measured frame.
    let mut sc = Scattering::from_gpu(&gpu, parse_technique("subsampled", &scene, &[]).unwrap()).unwrap();
    for _ in 0..10 {
        let mut encoder = gpu.device.create_command_encoder(&Default::default());
        sc.encode(&mut encoder, &frame, &out_view).unwrap();
        gpu.queue.submit([encoder.finish()]);
        sc.end_frame();
        assert!(sc.frames_in_flight() <= 3, "{} frames in flight", sc.frames_in_flight());
    }
    gpu.wait().unwrap();
    let stats = sc.stats().expect("the measured frames' stats").clone();
    assert!(stats.extra.contains_key("remarched_pixels"), "{:?}", stats.extra);
    assert_eq!(sc.frames_in_flight(), 0);
}
