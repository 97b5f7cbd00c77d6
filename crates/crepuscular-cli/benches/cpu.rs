//! Criterion benchmarks of the CPU paths: `reference`, the CPU mirrors of `brute-force`,
//! `interleaved` and `subsampled`, the CPU host renderer, and the metrics (PSNR and FLIP,
//! flicker). Inputs are tiny (the built-in `colonnade` at 64×36 with a 256² shadow map) so
//! that a full run takes about a minute:
//!
//! ```sh
//! cargo bench -p crepuscular-cli --bench cpu              # all
//! cargo bench -p crepuscular-cli --bench cpu -- mirror    # the ones whose name contains "mirror"
//! cargo bench -p crepuscular-cli --bench cpu --no-run     # compile only
//! ```
//!
//! These time the CPU code on this machine, not the GPU techniques (`crepuscular bench` does).

use crepuscular::march::MarchSettings;
use crepuscular::techniques::brute_force::{self, BruteForceSettings};
use crepuscular::techniques::interleaved::{self, InterleavedSettings};
use crepuscular::techniques::reference::{self, ReferenceSettings};
use crepuscular::techniques::subsampled::{self, SubsampledSettings};
use crepuscular::tonemap::ToneMap;
use crepuscular::{CpuFrame, Image};
use crepuscular_cli::animate::FlickerMeter;
use crepuscular_cli::metrics;
use crepuscular_cli::render::{frame_desc, load_scene};
use crepuscular_scene::host_cpu;
use criterion::{Criterion, criterion_group, criterion_main};
use std::hint::black_box;
use std::time::Duration;

/// Width and height of every benchmarked image.
const SIZE: (u32, u32) = (64, 36);

fn setup() -> (crepuscular::frame::FrameDesc, host_cpu::CpuHost, crepuscular_scene::Scene) {
    let mut scene = load_scene("colonnade").expect("built-in scene");
    (scene.render.width, scene.render.height) = SIZE;
    scene.render.shadow.size = 256;
    let desc = frame_desc(&scene).expect("the built-in scene is valid");
    let host = host_cpu::render(&scene.geometry, &scene.shading(), &desc);
    (desc, host, scene)
}

fn techniques(c: &mut Criterion) {
    let (desc, host, _) = setup();
    let frame =
        CpuFrame { desc: &desc, depth: &host.depth, shadow_maps: &host.shadow_maps, surface: Some(&host.surface) };
    let mut g = c.benchmark_group("cpu 64x36");
    g.bench_function("reference steps=64", |b| {
        let s = ReferenceSettings { steps: 64, seed: 1 };
        b.iter(|| black_box(reference::render(black_box(&frame), &s, &|_, _| {}).unwrap()))
    });
    g.bench_function("brute-force mirror steps=32", |b| {
        let s =
            BruteForceSettings { ray_march: MarchSettings { steps: 32, ..Default::default() }, ..Default::default() };
        b.iter(|| black_box(brute_force::cpu::march(black_box(&frame), &s).unwrap()))
    });
    g.bench_function("interleaved mirror steps=32 block=4", |b| {
        let s =
            InterleavedSettings { ray_march: MarchSettings { steps: 32, ..Default::default() }, ..Default::default() };
        b.iter(|| black_box(interleaved::cpu::render(black_box(&frame), &s).unwrap()))
    });
    g.bench_function("subsampled mirror steps=32 factor=4", |b| {
        let s =
            SubsampledSettings { ray_march: MarchSettings { steps: 32, ..Default::default() }, ..Default::default() };
        b.iter(|| black_box(subsampled::cpu::render(black_box(&frame), &s).unwrap()))
    });
    g.finish();
}

fn host(c: &mut Criterion) {
    let (desc, _, scene) = setup();
    c.bench_function("cpu 64x36/host frame (shadow map 256², depth, surface)", |b| {
        b.iter(|| black_box(host_cpu::render(black_box(&scene.geometry), &scene.shading(), &desc)))
    });
}

fn metrics_benches(c: &mut Criterion) {
    let (desc, host, _) = setup();
    let frame =
        CpuFrame { desc: &desc, depth: &host.depth, shadow_maps: &host.shadow_maps, surface: Some(&host.surface) };
    let (reference, _) = reference::render(&frame, &ReferenceSettings { steps: 64, seed: 1 }, &|_, _| {}).unwrap();
    let (test, _) = brute_force::cpu::march(
        &frame,
        &BruteForceSettings { ray_march: MarchSettings { steps: 8, ..Default::default() }, ..Default::default() },
    )
    .unwrap();
    let tone = ToneMap::default();
    let mut g = c.benchmark_group("metrics 64x36");
    g.bench_function("compare (RMSE, PSNR, FLIP)", |b| {
        b.iter(|| black_box(metrics::compare(black_box(&reference), black_box(&test), &tone).unwrap()))
    });
    g.bench_function("FLIP heat map", |b| {
        b.iter(|| black_box(metrics::flip_heatmap(black_box(&reference), black_box(&test), &tone).unwrap()))
    });
    g.bench_function("flicker, 4 frames", |b| {
        let frames: Vec<(Image, Image)> = (0..4).map(|_| (test.clone(), reference.clone())).collect();
        b.iter(|| {
            let mut m = FlickerMeter::new();
            for (t, r) in &frames {
                m.push(t, r).unwrap();
            }
            black_box(m.finish().unwrap())
        })
    });
    g.finish();
}

criterion_group! {
    name = benches;
    // Small inputs, short runs: the suite is for spotting regressions, not for publication.
    config = Criterion::default().sample_size(10).warm_up_time(Duration::from_millis(300)).measurement_time(Duration::from_secs(1));
    targets = techniques, host, metrics_benches
}
criterion_main!(benches);
