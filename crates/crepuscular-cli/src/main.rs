//! `crepuscular`: render, compare and measure single scattering from the command line.

use anyhow::{Context, Result, bail};
use clap::{Parser, Subcommand};
use crepuscular::tonemap::ToneMap;
use crepuscular_cli::render::{self, Backend, RenderOptions};
use crepuscular_cli::{metrics, output};
use crepuscular_scene::builtin;
use indicatif::{ProgressBar, ProgressStyle};
use std::path::PathBuf;
use std::process::ExitCode;

#[derive(Parser)]
#[command(
    name = "crepuscular",
    version,
    about = "Crepuscular rays and light shafts: single scattering in participating media, GPU (wgpu) and CPU"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Render a scene (built-in name or scene file) with a technique to a PNG (+ EXR, stats).
    Render(RenderArgs),
    /// List the built-in scenes.
    Scenes,
    /// List the techniques.
    Techniques,
    /// Compare two images (EXR or PNG): RMSE, PSNR on linear values, FLIP mean on tone-mapped.
    Diff(DiffArgs),
    /// Benchmark: scene × size × technique × setting, per-pass times (median, spread), samples,
    /// memory and quality vs reference → bench.json, bench.md, SVG plots. `--preset` runs a
    /// paper's own experiment.
    Bench(BenchArgs),
    /// Render `reference` and each technique on the same inputs: a contact sheet (final,
    /// in-scattering, FLIP error map, captions) and report.md / report.json.
    Compare(CompareArgs),
    /// Print the GPU adapter that `--backend auto|gpu` would use (fails if there is none).
    Adapter,
    /// Move the camera and the light along the scene's looping path, render every frame with a
    /// technique and write an animated GIF; `--flicker` measures temporal stability vs reference.
    Animate(AnimateArgs),
    /// Open an interactive window: the scene rendered every frame with a GPU technique, an
    /// orbit/fly camera, a movable light, the scene, medium and every technique setting editable
    /// live, per-pass timings, debug and error views, screenshots (F12 / P, with the view's
    /// state as JSON beside them); N / T cycle the built-in scenes / the techniques.
    View(ViewArgs),
}

#[derive(clap::Args)]
struct ViewArgs {
    /// Built-in scene name or path to a .toml scene file.
    #[arg(default_value = builtin::DEFAULT_SCENE)]
    scene: String,
    /// Technique (a GPU technique; see `crepuscular techniques`); switchable in the window.
    #[arg(long, short, default_value = "brute-force")]
    technique: String,
    /// Settings preset: fast, balanced or reference-like (over the scene's table, under --set).
    #[arg(long, value_parser = parse_preset)]
    preset: Option<crepuscular::techniques::presets::Preset>,
    /// A technique setting, `key=value` (TOML value), e.g. `--set steps=128`; repeatable.
    #[arg(long = "set", value_name = "KEY=VALUE")]
    set: Vec<String>,
    /// Window size WIDTHxHEIGHT, physical pixels, at most 8192 per side.
    #[arg(long, value_parser = parse_size, default_value = "960x540")]
    size: (u32, u32),
    /// Render scale: the scene is rendered at window size × scale, in 0.05..=2 (default 1 on
    /// a hardware adapter, 0.5 on a software one). Cost ∝ scale².
    #[arg(long)]
    scale: Option<f32>,
    /// Shadow-map texels per side (overrides the scene's shadow_map_size).
    #[arg(long)]
    shadow_map_size: Option<u32>,
    /// Render N frames, write the scene image (tone-mapped, render size, no UI) to --output
    /// and exit with code 0.
    #[arg(long, value_name = "N")]
    screenshot_after: Option<u32>,
    /// Screenshot path: --screenshot-after writes it (and `<stem>.json`); F12 / P write `<stem>-<n>.png` and
    /// `<stem>-<n>.json` (scene, camera, light, medium, settings, stats) beside it.
    #[arg(long, short, default_value = "crepuscular-view.png")]
    output: PathBuf,
    /// Start with the temporal stage on (docs/MODEL.md §7; a checkbox in the tools panel,
    /// with its history-weight view): the technique's samples move every frame and the view
    /// renders continuously.
    #[arg(long)]
    temporal: bool,
}

fn parse_preset(s: &str) -> Result<crepuscular::techniques::presets::Preset, String> {
    crepuscular::techniques::presets::Preset::parse(s).map_err(|e| e.to_string())
}

#[derive(clap::Args)]
struct AnimateArgs {
    /// Built-in scene name or path to a .toml scene file (files get a generic path).
    #[arg(default_value = builtin::DEFAULT_SCENE)]
    scene: String,
    /// Technique (see `crepuscular techniques`).
    #[arg(long, short, default_value = "brute-force")]
    technique: String,
    /// Frames: one loop of the path, frame i at t = i/frames; 1..=3600. Cost: linear.
    #[arg(long, default_value_t = crepuscular_cli::animate::DEFAULT_FRAMES)]
    frames: u32,
    /// Frame size WIDTHxHEIGHT, at most 4096 per side. Cost: linear in pixels.
    #[arg(long, value_parser = parse_size, default_value = "320x180")]
    size: (u32, u32),
    /// Where to compute: auto (GPU if any, else CPU), gpu, cpu.
    #[arg(long, value_enum, default_value_t = Backend::Auto)]
    backend: Backend,
    /// A technique setting, `key=value` (TOML value), e.g. `--set steps=128`; repeatable.
    /// `frame_index` (where the technique has it) is advanced by one per frame from its value.
    #[arg(long = "set", value_name = "KEY=VALUE")]
    set: Vec<String>,
    /// Shadow-map texels per side (overrides the scene's shadow_map_size).
    #[arg(long)]
    shadow_map_size: Option<u32>,
    /// GIF frame rate, frames per second, 1..=100 (GIF delays are in 1/100 s). No render cost.
    #[arg(long, default_value_t = crepuscular_cli::animate::DEFAULT_FPS)]
    fps: u32,
    /// Also render `reference` on every frame and print the flicker: the mean frame-to-frame
    /// change of the luminance error vs reference. Cost: one CPU reference per frame.
    #[arg(long)]
    flicker: bool,
    /// Steps per pixel of the `--flicker` reference (even, ≥ 2). Cost: linear, on the CPU
    /// (≈ 120 ms per frame at 160x90 and 256 steps on 2 cores).
    #[arg(long, default_value_t = crepuscular_cli::animate::DEFAULT_REFERENCE_STEPS)]
    reference_steps: u32,
    /// Run the temporal stage (reprojection, history rejection and clipping, exponential
    /// blend; docs/MODEL.md §7) after the technique on every frame, with the technique's
    /// `jitter` on where it has one (unless --set jitter=… says otherwise). With --flicker,
    /// prints each frame's PSNR and FLIP with and without it. Cost: one full-screen pass per
    /// frame.
    #[arg(long)]
    temporal: bool,
    /// Hold the lights still: only the camera moves along the path.
    #[arg(long)]
    still_lights: bool,
    /// Render only the first N frames of the --frames path: a slow move (a large --frames)
    /// over a few frames. The GIF then does not loop back.
    #[arg(long, value_name = "N")]
    stop_after: Option<u32>,
    /// From frame K on, every light is turned by 20° about the vertical axis through the
    /// camera's target (a light jump). With --temporal --flicker, prints how many frames the
    /// temporal stage takes to recover (its ghosting).
    #[arg(long, value_name = "K")]
    light_jump: Option<u32>,
    /// Add a box on the camera's line of sight, where the lights shine brightest, and move it
    /// sideways by 1.5 of its sides at frame K (an occluder crossing a shaft). With --temporal
    /// --flicker, prints how many frames the temporal stage takes to recover, over the frame
    /// and over the pixels the jump changed (its ghosting). Not with --light-jump.
    #[arg(long, value_name = "K")]
    occluder_jump: Option<u32>,
    /// A temporal-stage setting, `key=value` (with --temporal), e.g. `--temporal-set
    /// history_weight=0.8`; repeatable. Keys: history_weight, clip, clip_sigma,
    /// depth_tolerance, light_jump_degrees, history_filter ("bilinear" or "catmull-rom"),
    /// adaptive_weight, young_frames, light_disc_radius, scattering_distance (docs/MODEL.md §7).
    #[arg(long = "temporal-set", value_name = "KEY=VALUE")]
    temporal_set: Vec<String>,
    /// Write the run's report (settings, per-frame times, flicker, the temporal stage's
    /// per-frame quality) as JSON to this file.
    #[arg(long)]
    report: Option<PathBuf>,
    /// Write every frame's images into DIR (created if missing): NNNN-technique.exr (linear
    /// in-scattering) and .png (final image); with --temporal NNNN-temporal.exr/.png and
    /// NNNN-weight.png (history weight per pixel); with --flicker NNNN-reference.exr/.png and
    /// NNNN-error-technique.png / NNNN-error-temporal.png (error maps against the reference,
    /// the ramp's top at 5 % of its peak).
    #[arg(long, value_name = "DIR")]
    dump_frames: Option<PathBuf>,
    /// The animated GIF (loops forever).
    #[arg(long, short, default_value = "crepuscular.gif")]
    output: PathBuf,
}

#[derive(clap::Args)]
struct CompareArgs {
    /// Built-in scene name or path to a .toml scene file.
    #[arg(default_value = builtin::DEFAULT_SCENE)]
    scene: String,
    /// Techniques, comma-separated, at the scene's (or default) settings (default: every GPU technique).
    #[arg(long, value_delimiter = ',')]
    techniques: Vec<String>,
    /// Image size WIDTHxHEIGHT (default: the scene's).
    #[arg(long, value_parser = parse_size)]
    size: Option<(u32, u32)>,
    /// Steps per pixel of the reference (even).
    #[arg(long, default_value_t = 512)]
    reference_steps: u32,
    /// Timed frames per technique (median reported), after one warm-up frame.
    #[arg(long, default_value_t = 3)]
    repeat: u32,
    /// Where to compute the techniques: auto (GPU if any, else CPU), gpu, cpu.
    #[arg(long, value_enum, default_value_t = Backend::Auto)]
    backend: Backend,
    /// Output directory (sheet.png, report.md, report.json).
    #[arg(long, short, default_value = "compare")]
    output: PathBuf,
}

#[derive(clap::Args)]
struct BenchArgs {
    /// A named experiment (see `--list-presets`); other flags override its choices.
    #[arg(long)]
    preset: Option<String>,
    /// List the presets and exit.
    #[arg(long)]
    list_presets: bool,
    /// Scenes, comma-separated (default: every built-in scene).
    #[arg(long, value_delimiter = ',')]
    scenes: Vec<String>,
    /// Techniques, comma-separated, each swept over its main setting (default: every GPU technique).
    #[arg(long, value_delimiter = ',')]
    techniques: Vec<String>,
    /// Sizes WIDTHxHEIGHT, comma-separated (default 320x180).
    #[arg(long, value_delimiter = ',', value_parser = parse_size)]
    sizes: Vec<(u32, u32)>,
    /// Timed frames per configuration (default 5).
    #[arg(long)]
    repeat: Option<u32>,
    /// Untimed warm-up frames before them (default 2).
    #[arg(long)]
    warmup: Option<u32>,
    /// Steps per pixel of the quality reference; 0 skips quality (default 256).
    #[arg(long)]
    reference_steps: Option<u32>,
    /// Frames of the flicker measurement (temporal stability vs reference along the scene's
    /// `animate` path, frames 1/24 of its loop apart, at the smallest size capped to 320 wide,
    /// rows of that size only); 0 disables it (default 4; 0 when --reference-steps is 0). Cost:
    /// per scene that many references and host frames, per row that many frames.
    #[arg(long)]
    flicker_frames: Option<u32>,
    /// Add the temporal column (on in the `temporal` preset): every row of the smallest size (at the flicker's size) along a
    /// slow camera move (--temporal-frames frames of the scene's `animate` path, 1/96 of its
    /// loop apart, lights still), as configured and with `jitter=true` followed by the temporal
    /// stage (docs/MODEL.md §7), each frame against its own reference; PSNR and FLIP of the last
    /// frame, flicker over all. Cost: per scene that many references and host frames, per row
    /// twice that many frames (once where jitter adds nothing).
    #[arg(long)]
    temporal: bool,
    /// A temporal-stage setting for that column, `key=value` (with --temporal), e.g.
    /// `--temporal-set clip_sigma=1.0`; repeatable.
    #[arg(long = "temporal-set", value_name = "KEY=VALUE")]
    temporal_set: Vec<String>,
    /// Frames of the temporal column, 2..=1000 (default 9: eight frames of history, then the
    /// measured one).
    #[arg(long)]
    temporal_frames: Option<u32>,
    /// The temporal column's ghosting measure: after the slow move, this many frames with every
    /// light turned by 20° (a light jump; the camera keeps moving), the row as configured and
    /// with the stage against each frame's reference, and how many frames each takes to come
    /// back within 1 dB of its new steady state (the mean of the last 4). 0 or 8..=1000
    /// (default 10; with --temporal). Cost: as many more frames as --temporal-frames costs.
    #[arg(long)]
    ghost_frames: Option<u32>,
    /// Where to compute: auto (GPU if any, else CPU), gpu, cpu.
    #[arg(long, value_enum, default_value_t = Backend::Auto)]
    backend: Backend,
    /// Output directory.
    #[arg(long, short, default_value = "bench")]
    output: PathBuf,
}

#[derive(clap::Args)]
struct RenderArgs {
    /// Built-in scene name (see `crepuscular scenes`) or path to a .toml scene file.
    #[arg(default_value = builtin::DEFAULT_SCENE)]
    scene: String,
    /// Technique (see `crepuscular techniques`).
    #[arg(long, short, default_value = "brute-force")]
    technique: String,
    /// Where to compute: auto (GPU if any, else CPU), gpu, cpu.
    #[arg(long, value_enum, default_value_t = Backend::Auto)]
    backend: Backend,
    /// Image size WIDTHxHEIGHT (overrides the scene's [render] width/height).
    #[arg(long, value_parser = parse_size)]
    size: Option<(u32, u32)>,
    /// Shadow-map texels per side (overrides the scene's shadow_map_size).
    #[arg(long)]
    shadow_map_size: Option<u32>,
    /// A technique setting, `key=value` (TOML value), e.g. `--set steps=128`; repeatable.
    #[arg(long = "set", value_name = "KEY=VALUE")]
    set: Vec<String>,
    /// Settings preset: fast, balanced or reference-like (over the scene's table, under --set).
    #[arg(long, value_parser = parse_preset)]
    preset: Option<crepuscular::techniques::presets::Preset>,
    /// Tone-mapped final image (PNG).
    #[arg(long, short, default_value = "crepuscular.png")]
    output: PathBuf,
    /// Linear in-scattering as 32-bit float OpenEXR; the final linear radiance goes beside it
    /// as `<stem>.final.exr`.
    #[arg(long)]
    exr: Option<PathBuf>,
    /// Statistics (adapter, settings, per-pass times, samples, memory) as JSON.
    #[arg(long)]
    stats: Option<PathBuf>,
    /// Exposure multiplier before the tone curve (overrides the scene's).
    #[arg(long)]
    exposure: Option<f32>,
    /// Also write a debug view of the technique as `<output stem>.<view>.png`, tone-mapped like
    /// the image (the library's `crepuscular::debug::DebugView`): `epipolar` — `classification`
    /// (the sample classification of Engelhardt & Dachsbacher 2010 Fig. 9 bottom), `radiance`
    /// (the lines × samples radiance texture scaled up); `interleaved` — `pattern` (each
    /// pixel's block offset over the image); `prefiltered` — `rectified-map`, `basis`,
    /// `visibility`; `minmax` — `nodes` (the tree nodes each pixel's walk visits). Costs one
    /// more run of the technique.
    #[arg(long, value_name = "VIEW", value_parser = parse_debug_view)]
    debug: Option<render::DebugView>,
}

#[derive(clap::Args)]
struct DiffArgs {
    /// Reference image (EXR or PNG).
    reference: PathBuf,
    /// Test image (EXR or PNG).
    test: PathBuf,
    /// Write a FLIP error heat map (PNG, magma) here.
    #[arg(long)]
    heatmap: Option<PathBuf>,
    /// Exposure used to tone-map both images for FLIP.
    #[arg(long, default_value_t = 1.0)]
    exposure: f32,
    /// Also write the metrics as JSON here.
    #[arg(long)]
    json: Option<PathBuf>,
}

fn parse_size(s: &str) -> Result<(u32, u32), String> {
    let (w, h) = s.split_once(['x', 'X']).ok_or_else(|| format!("size `{s}`: expected WIDTHxHEIGHT"))?;
    let w: u32 = w.trim().parse().map_err(|_| format!("size `{s}`: bad width"))?;
    let h: u32 = h.trim().parse().map_err(|_| format!("size `{s}`: bad height"))?;
    if w == 0 || h == 0 || w > 16384 || h > 16384 {
        return Err(format!("size `{s}`: width and height must be in 1..=16384"));
    }
    Ok((w, h))
}

fn exr_final_path(exr: &std::path::Path) -> PathBuf {
    let stem = exr.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
    exr.with_file_name(format!("{stem}.final.exr"))
}

fn cmd_render(a: RenderArgs) -> Result<()> {
    let mut scene = render::load_scene(&a.scene)?;
    if let Some((w, h)) = a.size {
        scene.render.width = w;
        scene.render.height = h;
    }
    if let Some(s) = a.shadow_map_size {
        if s == 0 || s > 16384 {
            bail!("--shadow-map-size {s}: must be in 1..=16384");
        }
        scene.render.shadow.size = s;
    }
    if let Some(e) = a.exposure {
        if !e.is_finite() || e < 0.0 {
            bail!("--exposure {e}: must be a finite number ≥ 0");
        }
        scene.render.exposure = e;
    }
    let technique = crepuscular_cli::view::parse_technique(&a.technique, &scene, a.preset, &a.set)?;
    if let Some(view) = a.debug {
        // Refused before anything is rendered.
        view.check(&technique).with_context(|| format!("--debug {}", view.name()))?;
    }
    let notice = |m: &str| eprintln!("{m}");
    let gpu = render::open_gpu(a.backend, &notice)?;
    let on = match &gpu {
        Some(g) => g.describe(),
        None => "CPU".into(),
    };
    eprintln!(
        "rendering `{}` with {} at {}x{} on {on}",
        scene.name,
        technique.name(),
        scene.render.width,
        scene.render.height
    );
    let bar = ProgressBar::hidden();
    let progress = |done: u64, total: u64| {
        if bar.is_hidden() && total > 0 {
            bar.set_draw_target(indicatif::ProgressDrawTarget::stderr());
            bar.set_length(total);
            bar.set_style(
                ProgressStyle::with_template("{msg} [{bar:40}] {pos}/{len} rows, eta {eta}")
                    .unwrap_or_else(|_| ProgressStyle::default_bar()),
            );
            bar.set_message("integrating");
        }
        bar.set_position(done);
    };
    let debug_technique = a.debug.map(|_| technique.clone());
    let mut out = render::render(&scene, gpu.as_ref(), &RenderOptions { technique, progress: &progress })?;
    bar.finish_and_clear();
    let tone = ToneMap::new(scene.render.exposure);
    let rgb = tone.to_rgb8(&out.final_radiance);
    output::write_png_rgb8(&a.output, scene.render.width, scene.render.height, &rgb)?;
    eprintln!("wrote {}", a.output.display());
    if let Some(exr) = &a.exr {
        // Opaque, as an image viewer expects: the technique's alpha is the temporal stage's
        // (brute-force's scattering distance), not coverage.
        out.inscatter.pixels.iter_mut().for_each(|p| p[3] = 1.0);
        output::write_exr(exr, &out.inscatter)?;
        let fin = exr_final_path(exr);
        output::write_exr(&fin, &out.final_radiance)?;
        eprintln!("wrote {} (in-scattering) and {} (final radiance)", exr.display(), fin.display());
    }
    let t = &out.stats.technique;
    eprintln!(
        "{}: {:.1} ms ({}), {} ray-marched samples",
        t.technique,
        t.total_ms(),
        t.passes.iter().map(|p| format!("{} {:.1} ms", p.name, p.ms)).collect::<Vec<_>>().join(", "),
        t.raymarched_samples
    );
    if let Some(p) = &a.stats {
        output::write_json(p, &out.stats)?;
        eprintln!("wrote {}", p.display());
    }
    if let (Some(view), Some(technique)) = (a.debug, &debug_technique) {
        let img = render::debug_view(&scene, gpu.as_ref(), technique, view, &out.final_radiance)?;
        let p = a.output.with_extension(format!("{}.png", view.name()));
        output::write_png_rgb8(&p, img.width, img.height, &tone.to_rgb8(&img))?;
        eprintln!("wrote {} ({} view, {}×{})", p.display(), view.name(), img.width, img.height);
    }
    Ok(())
}

fn cmd_diff(a: DiffArgs) -> Result<()> {
    let r = output::read_exr(&a.reference)?;
    let t = output::read_exr(&a.test)?;
    let tone = ToneMap::new(a.exposure);
    let m = metrics::compare(&r, &t, &tone)
        .with_context(|| format!("{} vs {}", a.reference.display(), a.test.display()))?;
    println!("RMSE       {:.6e}", m.rmse);
    println!("PSNR       {:.2} dB (linear, peak = max of the reference)", m.psnr_db);
    println!("FLIP mean  {:.5} (tone-mapped, exposure {})", m.flip_mean, a.exposure);
    println!("max |Δ|    {:.6e}", m.max_abs);
    if let Some(h) = &a.heatmap {
        let (w, hgt, rgb) = metrics::flip_heatmap(&r, &t, &tone)?;
        output::write_png_rgb8(h, w, hgt, &rgb)?;
        eprintln!("wrote {}", h.display());
    }
    if let Some(j) = &a.json {
        output::write_json(j, &m)?;
    }
    Ok(())
}

/// Progress of a long command: a bar on a terminal, and — where stderr is not a terminal (a
/// log file, CI) and indicatif draws nothing — one line per step with the elapsed time, so a
/// redirected run still shows where it is.
struct Steps {
    bar: ProgressBar,
    lines: bool,
    start: std::time::Instant,
}

impl Steps {
    fn new(total: u64) -> Self {
        use std::io::IsTerminal;
        let bar = ProgressBar::new(total);
        bar.set_style(
            ProgressStyle::with_template("[{elapsed_precise}] [{bar:30}] {pos}/{len} {msg}")
                .unwrap_or_else(|_| ProgressStyle::default_bar()),
        );
        Self { bar, lines: !std::io::stderr().is_terminal(), start: std::time::Instant::now() }
    }

    /// Moves to step `done` (or one on, with `None`) and names it.
    fn step(&self, done: Option<u64>, m: &str) {
        match done {
            Some(d) => self.bar.set_position(d),
            None => self.bar.inc(1),
        }
        self.bar.set_message(m.to_string());
        if self.lines {
            let len = self.bar.length().unwrap_or(0);
            eprintln!("[{:7.1} s] {}/{len} {m}", self.start.elapsed().as_secs_f64(), self.bar.position());
        }
    }

    /// Detail within a step (reference rows): on the bar only.
    fn detail(&self, m: String) {
        self.bar.set_message(m);
    }

    fn finish(&self) {
        self.bar.finish_and_clear();
    }
}

fn cmd_compare(a: CompareArgs) -> Result<()> {
    use crepuscular_cli::compare;
    compare::check_output_dir(&a.output)?;
    let techniques: Vec<String> = if a.techniques.is_empty() {
        crepuscular::techniques::TECHNIQUES.iter().filter(|t| t.gpu).map(|t| t.name.to_string()).collect()
    } else {
        a.techniques.clone()
    };
    let notice = |m: &str| eprintln!("{m}");
    let gpu = render::open_gpu(a.backend, &notice)?;
    let on = gpu.as_ref().map(|g| g.describe()).unwrap_or_else(|| "CPU".into());
    eprintln!("compare `{}`: reference + {} on {on}", a.scene, techniques.join(", "));
    let bar = Steps::new(techniques.len() as u64 + 2);
    let step = |m: &str| bar.step(None, m);
    let rows = |done: u64, total: u64| bar.detail(format!("reference: row {done}/{total}"));
    let args = compare::CompareArgs {
        scene: a.scene.clone(),
        techniques,
        size: a.size,
        reference_steps: a.reference_steps,
        repeat: a.repeat,
        output: a.output.clone(),
    };
    let command = std::env::args().collect::<Vec<_>>().join(" ");
    let written = compare::run(&args, gpu.as_ref(), &command, &step, &rows)?;
    bar.finish();
    for p in written {
        eprintln!("wrote {}", p.display());
    }
    Ok(())
}

fn cmd_bench(a: BenchArgs) -> Result<()> {
    use crepuscular_cli::bench;
    if a.list_presets {
        for (name, what) in bench::PRESETS {
            println!("{name:<20} {what}");
        }
        return Ok(());
    }
    let mut plan = match &a.preset {
        Some(p) => bench::preset(p)?,
        None => {
            let scenes = builtin::builtin_names().iter().map(|(n, _)| n.to_string()).collect();
            let techniques: Vec<String> = if a.techniques.is_empty() {
                crepuscular::techniques::TECHNIQUES.iter().filter(|t| t.gpu).map(|t| t.name.to_string()).collect()
            } else {
                a.techniques.clone()
            };
            bench::default_plan(scenes, &techniques)?
        }
    };
    if a.preset.is_some() && !a.techniques.is_empty() {
        plan.variants.retain(|v| a.techniques.contains(&v.technique));
    }
    if !a.scenes.is_empty() {
        plan.scenes = a.scenes.clone();
    }
    if !a.sizes.is_empty() {
        plan.sizes = a.sizes.clone();
    }
    plan.repeat = a.repeat.unwrap_or(plan.repeat);
    plan.warmup = a.warmup.unwrap_or(plan.warmup);
    plan.reference_steps = a.reference_steps.unwrap_or(plan.reference_steps);
    if plan.reference_steps != 0 && (plan.reference_steps % 2 != 0 || plan.reference_steps < 2) {
        bail!("--reference-steps {}: must be 0 (no quality) or even and ≥ 2", plan.reference_steps);
    }
    let flicker_frames = match a.flicker_frames {
        Some(n) => n,
        None if plan.reference_steps == 0 => 0,
        None => bench::DEFAULT_FLICKER_FRAMES,
    };
    bench::check_flicker_frames(flicker_frames, plan.reference_steps)?;
    let temporal_on = a.temporal || plan.name == bench::TEMPORAL_PRESET;
    let temporal = match (temporal_on, a.temporal_set.is_empty(), a.temporal_frames) {
        (true, _, _) => Some(render::parse_temporal(&a.temporal_set)?),
        (false, false, _) => bail!("--temporal-set needs --temporal"),
        (false, _, Some(_)) => bail!("--temporal-frames needs --temporal"),
        (false, true, None) => None,
    };
    if temporal.is_none() && a.ghost_frames.is_some() {
        bail!("--ghost-frames needs --temporal");
    }
    let ghost_frames = match temporal {
        Some(_) => a.ghost_frames.unwrap_or(bench::DEFAULT_GHOST_FRAMES),
        None => 0,
    };
    bench::check_ghost_frames(ghost_frames)?;
    let temporal_frames = match temporal {
        Some(_) => a.temporal_frames.unwrap_or(bench::DEFAULT_TEMPORAL_FRAMES),
        None => 0,
    };
    bench::check_temporal_frames(temporal_frames, plan.reference_steps)?;
    let notice = |m: &str| eprintln!("{m}");
    let gpu = render::open_gpu(a.backend, &notice)?;
    let on = gpu.as_ref().map(|g| g.describe()).unwrap_or_else(|| "CPU".into());
    let total = (plan.scenes.len() * plan.sizes.len() * (plan.variants.len() + 2)) as u64
        + (plan.scenes.len() as u64 * (flicker_frames + temporal_frames + ghost_frames) as u64);
    eprintln!(
        "bench `{}` on {on}: {} configurations",
        plan.name,
        plan.scenes.len() * plan.sizes.len() * plan.variants.len()
    );
    let bar = Steps::new(total);
    let step = |m: &str| bar.step(None, m);
    let rows = |done: u64, total: u64| bar.detail(format!("reference rows {done}/{total}"));
    let command = std::env::args().collect::<Vec<_>>().join(" ");
    let (mut report, _) = bench::run(&plan, gpu.as_ref(), &command, &step, &rows, false)?;
    bench::measure_flicker(&mut report, gpu.as_ref(), flicker_frames, &step, &rows)?;
    if let Some(t) = temporal {
        bench::measure_temporal(&mut report, gpu.as_ref(), temporal_frames, ghost_frames, t, &step, &rows)?;
    }
    bar.finish();
    for p in bench::write(&report, &a.output)? {
        eprintln!("wrote {}", p.display());
    }
    print!("{}", bench::markdown(&report));
    Ok(())
}

fn cmd_animate(a: AnimateArgs) -> Result<()> {
    use crepuscular_cli::animate::{self, AnimateOptions};
    let opts = AnimateOptions {
        scene: a.scene.clone(),
        technique: a.technique.clone(),
        overrides: a.set.clone(),
        frames: a.frames,
        size: a.size,
        shadow_map_size: a.shadow_map_size,
        fps: a.fps,
        flicker: a.flicker,
        reference_steps: a.reference_steps,
        temporal: match (a.temporal, a.temporal_set.is_empty()) {
            (true, _) => Some(render::parse_temporal(&a.temporal_set)?),
            (false, true) => None,
            (false, false) => bail!("--temporal-set needs --temporal"),
        },
        still_lights: a.still_lights,
        stop_after: a.stop_after,
        light_jump: a.light_jump,
        occluder_jump: a.occluder_jump,
        dump_frames: a.dump_frames.clone(),
        output: a.output.clone(),
    };
    animate::check(&opts)?;
    let notice = |m: &str| eprintln!("{m}");
    let gpu = render::open_gpu(a.backend, &notice)?;
    let on = gpu.as_ref().map(|g| g.describe()).unwrap_or_else(|| "CPU".into());
    eprintln!(
        "animating `{}` with {}{}: {} frames at {}x{} on {on}",
        a.scene,
        a.technique,
        match (a.temporal, a.flicker) {
            (true, true) => " + temporal stage, and reference",
            (true, false) => " + temporal stage",
            (false, true) => " and reference",
            (false, false) => "",
        },
        a.stop_after.map_or(a.frames, |s| s.min(a.frames)),
        a.size.0,
        a.size.1
    );
    let bar = Steps::new(a.frames as u64);
    let step = |done: u32, _total: u32, m: &str| bar.step(Some(done as u64), m);
    let rows = |done: u64, total: u64| bar.detail(format!("reference rows {done}/{total}"));
    let report = animate::run(&opts, gpu.as_ref(), &step, &rows)?;
    bar.finish();
    let mut ms = report.technique_ms.clone();
    ms.sort_by(f64::total_cmp);
    eprintln!(
        "wrote {} ({} frames, {} fps, {:.1} KiB); {}: median {:.1} ms per frame{}",
        a.output.display(),
        report.frames,
        a.fps,
        report.bytes as f64 / 1024.0,
        a.technique,
        ms.get(ms.len() / 2).copied().unwrap_or(0.0),
        if report.frame_index_advanced { ", frame_index advanced per frame" } else { "" }
    );
    if let Some(f) = report.flicker {
        println!(
            "flicker    {:.6e} (mean |Δe| per pixel and frame pair, e = luminance of technique − reference in-scattering)",
            f.mean_abs_change
        );
        println!(
            "           {:.4} % of the reference's mean luminance {:.6e}, over {} frame pairs",
            100.0 * f.relative,
            f.mean_reference,
            f.frames - 1
        );
        println!("           (the reference itself changes by {:.6e} per pixel and frame pair)", f.reference_change);
    }
    if let Some(t) = &report.temporal {
        let mut ms = t.stage_ms.clone();
        ms.sort_by(f64::total_cmp);
        println!(
            "temporal   on the {}{}: median {:.1} ms per frame",
            t.backend,
            if t.jitter_added { ", jitter=true added to the technique" } else { "" },
            ms.get(ms.len() / 2).copied().unwrap_or(0.0)
        );
        if let Some(f) = t.flicker_without {
            println!("           flicker without the stage {:.4} %", 100.0 * f.relative);
        }
        let jump = match (t.light_jump, &t.occluder_jump) {
            (Some(k), _) => Some((k, "light jump")),
            (_, Some((k, _))) => Some((*k, "occluder jump")),
            _ => None,
        };
        if let (Some((k, what)), true) = (jump, a.flicker) {
            match t.recovery_frames {
                Some(r) => {
                    println!("           {what} at frame {k}: within 1 dB of the new steady state after {r} frames")
                }
                None => println!(
                    "           {what} at frame {k}: not within 1 dB of the new steady state (the mean of the last 4 \
                     frames; at least 8 frames must follow the jump)"
                ),
            }
            if let Some(r) = &t.region {
                let after = match r.recovery_frames {
                    Some(n) => format!("within 1 dB of its steady state after {n} frames"),
                    None => "not within 1 dB of its steady state".into(),
                };
                println!(
                    "           over the {} pixels it changed ({:.1} % of the frame): {after}",
                    r.pixels,
                    100.0 * r.fraction
                );
            }
        }
        if !t.frames.is_empty() {
            let regions = t.region.is_some();
            println!(
                "frame  PSNR dB without → with   FLIP without → with   mean history weight{}",
                if regions { "   jump region PSNR without → with" } else { "" }
            );
            for (i, q) in t.frames.iter().enumerate() {
                let region = match (q.region_psnr_db_without, q.region_psnr_db) {
                    (Some(a), Some(b)) => format!("        {a:>7.2} → {b:>7.2}"),
                    _ => String::new(),
                };
                println!(
                    "{:>5}  {:>7.2} → {:>7.2}      {:.4} → {:.4}        {:.3}{region}",
                    i, q.psnr_db_without, q.psnr_db, q.flip_without, q.flip, q.mean_history_weight
                );
            }
        }
    }
    if let Some(path) = &a.report {
        let json = serde_json::to_string_pretty(&report)?;
        crepuscular_cli::output::write_atomic(path, json.as_bytes())
            .with_context(|| format!("cannot write {}", path.display()))?;
    }
    Ok(())
}

fn run() -> Result<()> {
    let cli = Cli::parse();
    match cli.command {
        Command::Render(a) => cmd_render(a),
        Command::Scenes => {
            for (name, desc) in builtin::builtin_names() {
                let mark = if *name == builtin::DEFAULT_SCENE { " (default)" } else { "" };
                println!("{name:<14} {desc}{mark}");
            }
            Ok(())
        }
        Command::Techniques => {
            for t in crepuscular::techniques::TECHNIQUES {
                let where_ = match (t.gpu, t.cpu) {
                    (true, true) => "gpu+cpu",
                    (true, false) => "gpu",
                    _ => "cpu",
                };
                println!("{:<14} [{where_}] {} — {}", t.name, t.summary, t.paper);
            }
            Ok(())
        }
        Command::Diff(a) => cmd_diff(a),
        Command::Bench(a) => cmd_bench(a),
        Command::Compare(a) => cmd_compare(a),
        Command::Animate(a) => cmd_animate(a),
        Command::View(a) => crepuscular_cli::view::run(crepuscular_cli::view::ViewOptions {
            scene: a.scene,
            technique: a.technique,
            preset: a.preset,
            overrides: a.set,
            size: a.size,
            scale: a.scale,
            shadow_map_size: a.shadow_map_size,
            screenshot_after: a.screenshot_after,
            output: a.output,
            temporal: a.temporal,
        }),
        Command::Adapter => {
            let gpu = crepuscular::GpuContext::new()?;
            println!("{}", gpu.describe());
            Ok(())
        }
    }
}

fn main() -> ExitCode {
    env_logger::Builder::from_env(env_logger::Env::default().default_filter_or("warn")).init();
    match run() {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {}", format!("{e:#}").replace('\n', " "));
            ExitCode::FAILURE
        }
    }
}

/// `--debug VIEW`: one of the library's debug views, by name.
fn parse_debug_view(s: &str) -> Result<render::DebugView, String> {
    s.parse().map_err(|e: crepuscular::Error| e.to_string())
}
