//! Criterion benchmarks of the CPU cost of recording a frame: what an engine's render thread
//! pays each frame for [`crepuscular::Scattering::encode`] (every GPU technique at its
//! defaults, the built-in `colonnade` at 320×180, its sun's 1024² map) and for the temporal
//! stage's [`crepuscular::Temporal::encode`], each with the encoder's `finish`. The GPU's work
//! is not timed: every frame is submitted and waited for outside the measurement, so the
//! figures hold on any adapter, llvmpipe included.
//!
//! ```sh
//! cargo bench -p crepuscular-cli --bench encode              # all (~1 min)
//! cargo bench -p crepuscular-cli --bench encode -- epipolar  # the ones whose name contains "epipolar"
//! ```
//!
//! Without a GPU adapter it prints why and measures nothing.

use crepuscular::{Scattering, StatsMode, TechniqueSettings, Temporal, TemporalSettings};
use crepuscular_cli::render::{frame_desc, load_scene};
use crepuscular_scene::GpuHost;
use criterion::{Criterion, criterion_group, criterion_main};
use std::time::{Duration, Instant};

/// The GPU techniques, each at its defaults.
const TECHNIQUES: [&str; 6] = ["brute-force", "interleaved", "subsampled", "epipolar", "prefiltered", "minmax"];

fn encode(c: &mut Criterion) {
    let gpu = match crepuscular::GpuContext::new() {
        Ok(gpu) => gpu,
        Err(e) => {
            println!("encode benchmarks skipped: no GPU adapter ({e})");
            return;
        }
    };
    let mut scene = load_scene("colonnade").expect("built-in scene");
    (scene.render.width, scene.render.height) = (320, 180);
    let desc = frame_desc(&scene).expect("the built-in scene is valid");
    let host = GpuHost::for_scene(&gpu, &scene).expect("host renderer");
    let tex = host.render(&gpu, &desc).expect("host frame");
    let views = tex.views();
    let frame = views.frame(&desc);
    let out = gpu.create_output_texture(desc.width, desc.height);
    let out_view = out.create_view(&Default::default());
    let resolved = gpu.create_output_texture(desc.width, desc.height);
    let resolved_view = resolved.create_view(&Default::default());

    let mut g = c.benchmark_group(format!("encode 320x180 colonnade ({})", gpu.info.name));
    g.sample_size(20).warm_up_time(Duration::from_millis(500)).measurement_time(Duration::from_secs(3));
    for name in TECHNIQUES {
        let settings = TechniqueSettings::named(name).expect("a built-in technique");
        let mut scattering = Scattering::from_gpu(&gpu, settings)
            .and_then(|s| s.with_stats(StatsMode::Off))
            .expect("the technique builds");
        g.bench_function(name, |b| {
            b.iter_custom(|iters| {
                let mut spent = Duration::ZERO;
                for _ in 0..iters {
                    let start = Instant::now();
                    let mut enc = gpu.device.create_command_encoder(&Default::default());
                    scattering.encode(&mut enc, &frame, &out_view).expect("encode");
                    let commands = enc.finish();
                    spent += start.elapsed();
                    gpu.queue.submit([commands]);
                    scattering.end_frame();
                    gpu.wait().expect("the frame runs");
                }
                spent
            })
        });
    }
    let mut temporal = Temporal::new(&gpu.device, TemporalSettings::default()).expect("the stage builds");
    g.bench_function("temporal stage", |b| {
        b.iter_custom(|iters| {
            let mut spent = Duration::ZERO;
            for _ in 0..iters {
                let start = Instant::now();
                let mut enc = gpu.device.create_command_encoder(&Default::default());
                temporal.encode(&mut enc, &desc, frame.depth, &out_view, &resolved_view, None).expect("encode");
                let commands = enc.finish();
                spent += start.elapsed();
                gpu.queue.submit([commands]);
                gpu.wait().expect("the frame runs");
            }
            spent
        })
    });
    g.finish();
}

criterion_group!(benches, encode);
criterion_main!(benches);
