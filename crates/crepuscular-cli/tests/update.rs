//! Settings changed in place (`Scattering::update`, what the viewer does when a setting is
//! edited) render exactly what a runner built fresh with the new settings renders: a technique
//! that kept a stale table, texture or pipeline across the change would differ here. And
//! `StatsMode::Off` (nothing measured) and `StatsMode::Deferred` (timings and counters read back
//! frames later) render the same image as `StatsMode::WallClock` (each pass waited for).

use crepuscular::gpu::{GpuContext, test_gpu};
use crepuscular::{Scattering, StatsMode, TechniqueSettings};
use crepuscular_cli::render::{frame_desc, parse_technique, render_gpu, scattering};
use crepuscular_scene::{GpuHost, Scene, builtin};

fn small(name: &str) -> Scene {
    let mut s = builtin::builtin(name).expect("built-in scene");
    s.render.width = 96;
    s.render.height = 54;
    s.render.shadow.size = 256;
    s
}

/// One frame of `scene` through `runner`, read back as raw f32 bits.
fn render(gpu: &GpuContext, scene: &Scene, host: &GpuHost, runner: &mut Scattering) -> Vec<u32> {
    render_stats(gpu, scene, host, runner).0
}

/// One frame and the technique's stats.
fn render_stats(
    gpu: &GpuContext,
    scene: &Scene,
    host: &GpuHost,
    runner: &mut Scattering,
) -> (Vec<u32>, crepuscular::stats::TechniqueStats) {
    let desc = frame_desc(scene).unwrap();
    let tex = host.render(gpu, &desc).unwrap();
    let out = gpu.create_output_texture(desc.width, desc.height);
    let views = tex.views();
    let stats = render_gpu(runner, Some(host), &views.frame(&desc), &out.create_view(&Default::default())).unwrap();
    (gpu.read_texture_f32(&out, 0).unwrap().into_iter().map(f32::to_bits).collect(), stats)
}

fn parse(technique: &str, scene: &Scene, set: &[&str]) -> TechniqueSettings {
    let set: Vec<String> = set.iter().map(|s| s.to_string()).collect();
    parse_technique(technique, scene, &set).unwrap_or_else(|e| panic!("{technique} {set:?}: {e:#}"))
}

#[test]
fn settings_changed_in_place_render_what_a_fresh_runner_renders() {
    let Some(gpu) = test_gpu("settings_changed_in_place_render_what_a_fresh_runner_renders") else { return };
    // Each technique walks through a chain of settings; every step changes something a
    // technique sizes or builds from its settings (tables, textures, pipelines) as well as
    // plain uniforms.
    let chains: &[(&str, &[&[&str]])] = &[
        ("brute-force", &[&["steps=32"], &["steps=17", "jitter=true", "frame_index=3"], &["steps=32"]]),
        (
            "interleaved",
            &[
                &["steps=64"],
                &["steps=64", "block=2", "phase_lut=true", "phase_lut_size=64"],
                &["steps=64", "block=4", "phase_lut=true", "phase_lut_size=128", "depth_aware=false"],
                &["steps=64"],
            ],
        ),
        ("subsampled", &[&["factor=4"], &["factor=2"], &["grid=[40, 30]", "edge_remarch=false"], &["factor=4"]]),
        (
            "epipolar",
            &[
                &["slices=64", "samples=64"],
                &["slices=128", "samples=32", "taps=3"],
                &["slices=64", "samples=96", "initial_samples=8"],
            ],
        ),
        (
            "prefiltered",
            &[
                &["map_size=[128, 128]"],
                &["map_size=[96, 64]", "bases=16", "bands=2"],
                &["map_size=[128, 128]", "precision=\"float16\"", "regions=2"],
                &["map_size=[128, 128]"],
            ],
        ),
        (
            "minmax",
            &[
                &["map_size=[128, 128]"],
                &["map_size=[64, 32]"],
                &["map_size=[128, 128]", "max_nodes=2"],
                &["map_size=[128, 128]"],
            ],
        ),
    ];
    for scene_name in ["colonnade", "stained-glass"] {
        let scene = small(scene_name);
        let host = GpuHost::for_scene(&gpu, &scene).unwrap();
        for (technique, chain) in chains {
            let first = parse(technique, &scene, chain[0]);
            let mut runner = scattering(&gpu, &first).unwrap().expect("a GPU technique");
            let mut previous = render(&gpu, &scene, &host, &mut runner);
            for set in &chain[1..] {
                let next = parse(technique, &scene, set);
                assert!(runner.update(&next).unwrap(), "{technique}: update refused its own settings");
                let in_place = render(&gpu, &scene, &host, &mut runner);
                let mut fresh_runner = scattering(&gpu, &next).unwrap().expect("a GPU technique");
                let fresh = render(&gpu, &scene, &host, &mut fresh_runner);
                let differ = in_place.iter().zip(&fresh).filter(|(a, b)| a != b).count();
                eprintln!("{scene_name} {technique} → {set:?}: {differ} of {} values differ", fresh.len());
                assert_eq!(differ, 0, "{scene_name} {technique}: in place after {set:?} differs from a fresh runner");
                // The change did change the image (so the comparison above can fail).
                assert_ne!(in_place, previous, "{scene_name} {technique}: {set:?} changed nothing");
                previous = in_place;
            }
            // Another technique's settings are refused and change nothing.
            let other = parse(if *technique == "brute-force" { "epipolar" } else { "brute-force" }, &scene, &[]);
            assert!(!runner.update(&other).unwrap(), "{technique} accepted another technique's settings");
        }
    }
}

#[test]
fn stats_off_renders_the_same_image_without_timing_or_readbacks() {
    let Some(gpu) = test_gpu("stats_off_renders_the_same_image_without_timing_or_readbacks") else { return };
    for scene_name in ["colonnade", "cage"] {
        let scene = small(scene_name);
        let host = GpuHost::for_scene(&gpu, &scene).unwrap();
        for (technique, set) in [
            ("brute-force", &[][..]),
            ("interleaved", &[]),
            ("subsampled", &[]),
            ("epipolar", &["slices=64", "samples=64"]),
            ("prefiltered", &["map_size=[128, 128]"]),
            ("minmax", &["map_size=[128, 128]"]),
        ] {
            let choice = parse(technique, &scene, set);
            let mut runner = scattering(&gpu, &choice).unwrap().expect("a GPU technique");
            runner.set_stats_mode(StatsMode::WallClock).unwrap();
            let (measured, ms) = render_stats(&gpu, &scene, &host, &mut runner);
            runner.set_stats_mode(StatsMode::Off).unwrap();
            let (off, os) = render_stats(&gpu, &scene, &host, &mut runner);
            // Deferred: the counters arrive after the frame (here: after the wait in `render`)
            // and are the ones measured at once.
            runner.set_stats_mode(StatsMode::Deferred).unwrap();
            let (deferred, ds) = render_stats(&gpu, &scene, &host, &mut runner);
            // The three images compared below are no picture if the measured one is black.
            assert!(
                measured.chunks(4).any(|p| p[..3].iter().any(|&b| f32::from_bits(b) > 0.0)),
                "{scene_name} {technique}: the measured frame scatters nothing"
            );
            assert!(deferred == measured, "{scene_name} {technique}: StatsMode::Deferred changed the image");
            assert_eq!(ds.raymarched_samples, ms.raymarched_samples, "{scene_name} {technique}: deferred counts");
            assert_eq!(ds.extra, ms.extra, "{scene_name} {technique}: deferred counts");
            eprintln!(
                "{scene_name} {technique}: measured {} samples {:?}; off {} samples {:?}",
                ms.raymarched_samples, ms.timing, os.raymarched_samples, os.timing
            );
            assert!(off == measured, "{scene_name} {technique}: StatsMode::Off changed the image");
            assert_eq!(os.timing, "off");
            assert_ne!(ms.timing, "off");
            let names =
                |s: &crepuscular::stats::TechniqueStats| s.passes.iter().map(|p| p.name.clone()).collect::<Vec<_>>();
            assert_eq!(names(&os), names(&ms), "{technique}: the same passes");
            assert!(os.passes.iter().all(|p| p.ms == 0.0), "{technique}: {:?}", os.passes);
            match technique {
                // Known on the CPU: the same count.
                "brute-force" | "interleaved" | "prefiltered" => {
                    assert_eq!(os.raymarched_samples, ms.raymarched_samples)
                }
                // The grid only: without the re-marched pixels, which only the GPU counts.
                // The epipole disc's samples are known on the CPU; the walks are counted on
                // the GPU only.
                "minmax" => {
                    assert_eq!(os.raymarched_samples, ms.raymarched_samples);
                    assert!(!os.extra.contains_key("nodes_per_ray") && ms.extra.contains_key("nodes_per_ray"));
                }
                "subsampled" => {
                    assert!(os.raymarched_samples <= ms.raymarched_samples && os.raymarched_samples > 0);
                    assert!(!os.extra.contains_key("remarched_pixels") && ms.extra.contains_key("remarched_pixels"));
                }
                _ => {
                    assert_eq!(os.raymarched_samples, 0);
                    assert!(!os.extra.contains_key("marched_samples") && ms.extra.contains_key("marched_samples"));
                }
            }
        }
    }
}
