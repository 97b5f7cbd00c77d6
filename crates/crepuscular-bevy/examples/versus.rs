//! The side-by-side benchmark: Bevy's own `VolumetricFog` at step counts 16–256 against the
//! plugin's techniques at their presets, on the same scene, medium and adapter (docs/BEVY.md,
//! docs/RESULTS.md "Bevy's VolumetricFog against the plugin").
//!
//! ```text
//! cargo run --release -p crepuscular-bevy --example versus -- --size 1920x1080 --output docs/results/bevy-versus
//! ```
//!
//! Per configuration: a fresh app on the demo colonnade, settled (pipelines built), then
//! `--frames` timed frames. On a hardware adapter with timestamp queries the effect's cost is
//! its GPU time: two timestamps in Bevy's encoder around the systems between the main pass and
//! early post-processing (`demo::EffectTimer`: Bevy's fog pass, or the plugin's shadow copy,
//! technique and composite), median over the frames, minus the same bracket's median without
//! fog. On a software adapter (whose timestamps mean nothing) each frame is timed by wall clock
//! from `update` to the device being idle, and the cost is the median frame minus the median
//! frame without fog.
//! Quality: PSNR and FLIP of the final (tone-mapped, 8-bit) picture against the effect's own
//! converged picture: Bevy at 1024 steps; the plugin's brute-force march at 1024 steps.
//! `--temporal` adds the marching techniques with the temporal stage after them (a still camera).
//! `--config TECHNIQUE:PRESET:KEY=VALUE;…` adds a plugin row with settings of your own (e.g.
//! epipolar with fewer lines at a high resolution), and `--references-from DIR` reads both
//! converged pictures from an earlier run's output at the same size instead of rendering them
//! again (at 1920×1080 on a software adapter they take most of a run).
//! Writes `versus.md` (the table), `versus.json`, `side-by-side.png`, with `--temporal`
//! `temporal.png` (the plugin's converged picture, a technique alone, the same with the stage),
//! and each picture.

use std::path::{Path, PathBuf};
use std::time::Instant;

use bevy::prelude::*;
use clap::Parser;
use crepuscular::TechniqueSettings;
use crepuscular::techniques::presets::Preset;
use crepuscular_bevy::demo::{self, DemoOptions, Effect};
use indicatif::{ProgressBar, ProgressStyle};

#[derive(Parser)]
#[command(about = "Bevy's VolumetricFog against the crepuscular plugin, same scene and adapter")]
struct Args {
    /// Image size, WIDTHxHEIGHT.
    #[arg(long, default_value = "480x270")]
    size: String,
    /// Timed frames per configuration (the median is reported).
    #[arg(long, default_value_t = 5)]
    frames: u32,
    /// Bevy step counts to measure.
    #[arg(long, value_delimiter = ',', default_value = "16,32,64,128,256")]
    steps: Vec<u32>,
    /// Presets of the plugin's techniques to measure.
    #[arg(long, value_delimiter = ',', default_value = "fast,balanced")]
    presets: Vec<String>,
    /// The plugin's techniques to measure (names as `crepuscular techniques` lists them);
    /// default: every technique with a GPU implementation.
    #[arg(long, value_delimiter = ',')]
    techniques: Vec<String>,
    /// How the plugin's lights read Bevy's shadow maps (`CrepuscularLight::shadow_filter`):
    /// bilinear (2×2 percentage-closer, as Bevy's own lookups; the plugin's default) or nearest
    /// (one texel).
    #[arg(long, default_value = "bilinear", value_parser = crepuscular::ShadowFilter::parse)]
    shadow_filter: crepuscular::ShadowFilter,
    /// Also measure each marching technique (brute-force, interleaved, subsampled, epipolar)
    /// with the temporal stage after it (`CrepuscularTemporal` at its defaults, Bevy's motion
    /// vectors on): jittered samples blended over the timed frames and the captured one (the
    /// history is cut after the settle frames), the camera still (the stage's best case: a
    /// moving camera keeps less). `--frames 7` makes the captured frame the eighth.
    #[arg(long)]
    temporal: bool,
    /// An extra plugin row: `TECHNIQUE:PRESET:KEY=VALUE;KEY=VALUE…`, the preset's settings with
    /// each `KEY=VALUE` (a TOML value, keys as in a scene's `[render.TECHNIQUE]` table) set over
    /// them, e.g. `epipolar:fast:slices=512;samples=512`. Repeatable; measured like the preset
    /// rows (and with the stage after it under `--temporal`, for a marching technique).
    #[arg(long = "config", value_name = "TECHNIQUE:PRESET:KEY=VALUE;…")]
    configs: Vec<String>,
    /// Read both converged pictures (Bevy at 1024 steps, the plugin's brute-force at 1024
    /// steps) from this folder, an earlier run's `--output` at the same `--size` and
    /// `--shadow-filter`, instead of rendering them. The files are the PNGs that run wrote
    /// (8-bit, what quality is measured on); a missing file or another size is an error.
    #[arg(long, value_name = "DIR")]
    references_from: Option<PathBuf>,
    /// Output folder.
    #[arg(long, default_value = "bevy-versus")]
    output: PathBuf,
}

struct Run {
    label: String,
    family: &'static str,
    /// Median frame, wall clock (update to device idle), ms.
    frame_ms: f64,
    /// Median of the effect's GPU bracket, ms (hardware adapters with timestamps).
    gpu_ms: Option<f64>,
    image: Rgb8,
}

/// A final 8-bit picture, what quality is measured on.
struct Rgb8 {
    width: u32,
    height: u32,
    /// Row-major RGB bytes.
    data: Vec<u8>,
}

struct Row {
    label: String,
    family: &'static str,
    cost_ms: f64,
    /// The whole frame's median, wall clock (update to device idle), ms: the CPU's share too.
    frame_ms: f64,
    psnr_db: f64,
    flip: f64,
}

fn main() {
    if let Err(e) = run(Args::parse()) {
        eprintln!("error: {e}");
        std::process::exit(1);
    }
}

fn run(args: Args) -> Result<(), String> {
    let (width, height) = demo::parse_size(&args.size)?;
    if args.frames == 0 {
        return Err("--frames 0: at least one timed frame".into());
    }
    if let Some(s) = args.steps.iter().find(|&&s| s == 0) {
        return Err(format!("--steps {s}: step counts must be at least 1"));
    }
    let presets =
        args.presets.iter().map(|p| Preset::parse(p).map_err(|e| e.to_string())).collect::<Result<Vec<_>, _>>()?;
    for t in &args.techniques {
        if !crepuscular::techniques::TECHNIQUES.iter().any(|info| info.name == t) {
            let names: Vec<&str> = crepuscular::techniques::TECHNIQUES.iter().map(|i| i.name).collect();
            return Err(format!("--techniques {t}: unknown technique (one of {})", names.join(", ")));
        }
    }
    std::fs::create_dir_all(&args.output).map_err(|e| format!("{}: {e}", args.output.display()))?;
    // A fresh progress log for this run.
    let _ = std::fs::remove_file(args.output.join("progress.log"));

    type Config = (String, &'static str, Effect, Option<crepuscular_bevy::CrepuscularTemporal>);
    let mut configs: Vec<Config> = vec![("no fog".into(), "baseline", Effect::None, None)];
    for &s in &args.steps {
        configs.push((format!("Bevy VolumetricFog {s} steps"), "bevy", Effect::BevyFog { steps: s }, None));
    }
    configs.push((
        "Bevy VolumetricFog 1024 steps (converged)".into(),
        "bevy-converged",
        Effect::BevyFog { steps: 1024 },
        None,
    ));
    // The plugin's rows name a non-default shadow filter, so tables of both can be merged.
    let filter = match args.shadow_filter {
        crepuscular::ShadowFilter::Bilinear => String::new(),
        f => format!(", {} shadow filter", f.name()),
    };
    let mut converged = crepuscular::techniques::presets::Preset::ReferenceLike.brute_force();
    converged.ray_march.steps = 1024;
    configs.push((
        format!("crepuscular brute-force 1024 steps (converged{filter})"),
        "ours-converged",
        Effect::Crepuscular(demo::crepuscular(TechniqueSettings::BruteForce(converged))),
        None,
    ));
    // The stage's history is cut after the settle frames: the captured frame is its n-th.
    let stage_frames = args.frames + 1;
    let push_plugin = |configs: &mut Vec<Config>, t: TechniqueSettings, what: String| {
        if args.temporal && t.ray_march().is_some() {
            configs.push((
                format!(
                    "crepuscular {} ({what}{filter}) + temporal stage, still camera, frame {stage_frames} after a cut",
                    t.name()
                ),
                "ours",
                Effect::Crepuscular(demo::crepuscular(t.clone())),
                Some(crepuscular_bevy::CrepuscularTemporal::default()),
            ));
        }
        configs.push((
            format!("crepuscular {} ({what}{filter})", t.name()),
            "ours",
            Effect::Crepuscular(demo::crepuscular(t)),
            None,
        ));
    };
    for info in crepuscular::techniques::TECHNIQUES {
        if !args.techniques.is_empty() && !args.techniques.iter().any(|t| t == info.name) {
            continue;
        }
        for &p in &presets {
            let Some(t) = p.settings(info.name) else { continue };
            if !t.has_gpu() {
                continue;
            }
            push_plugin(&mut configs, t, p.name().to_string());
        }
    }
    for spec in &args.configs {
        let (t, what) = parse_config(spec)?;
        push_plugin(&mut configs, t, what);
    }
    // Converged pictures from an earlier run: their configurations are not rendered.
    let mut loaded = Vec::new();
    if let Some(dir) = &args.references_from {
        for family in ["bevy-converged", "ours-converged"] {
            let Some(k) = configs.iter().position(|c| c.1 == family) else { continue };
            let (label, ..) = configs.remove(k);
            let file = dir.join(format!("{}.png", slug(&label)));
            let image = load_png(&file, width, height)?;
            loaded.push(Run { label, family, frame_ms: f64::NAN, gpu_ms: None, image });
        }
    }

    let bar = ProgressBar::new(configs.len() as u64);
    bar.set_style(ProgressStyle::with_template("{bar:30} {pos}/{len} {elapsed} {msg}").map_err(|e| e.to_string())?);
    let mut runs = Vec::new();
    let mut adapter = String::new();
    let mut software = true;
    for (label, family, effect, temporal) in configs {
        bar.set_message(label.clone());
        // Bevy's logger is process-wide: the first app installs it.
        let opts = DemoOptions {
            width,
            height,
            effect,
            lamps: false,
            shadow_filter: args.shadow_filter,
            log: runs.is_empty(),
            temporal,
            ..Default::default()
        };
        let mut app = demo::headless_app(&opts);
        let timer = demo::EffectTimer::install(&mut app);
        app.finish();
        app.cleanup();
        demo::settle(&mut app, 3).map_err(|e| format!("{label}: {e}"))?;
        // The stage's history starts with the timed frames (the settle's count varies).
        let mut stages = app.world_mut().query::<&mut crepuscular_bevy::CrepuscularTemporal>();
        for mut t in stages.iter_mut(app.world_mut()) {
            t.cut();
        }
        let device = app.world().resource::<bevy::render::renderer::RenderDevice>().wgpu_device().clone();
        let queue: wgpu::Queue = {
            let q: &wgpu::Queue = &app.world().resource::<bevy::render::renderer::RenderQueue>().0;
            q.clone()
        };
        if adapter.is_empty() {
            let info = app.world().resource::<bevy::render::renderer::RenderAdapterInfo>();
            // The library's own rule for a software adapter (llvmpipe, SwiftShader, CPU type).
            software = crepuscular::GpuContext::from_device(&device, &queue).software;
            adapter = format!(
                "{} ({:?}, {:?}, driver {} {})",
                info.name, info.backend, info.device_type, info.driver, info.driver_info
            );
        }
        crepuscular::gpu::wait_idle(&device).map_err(|e| e.to_string())?;
        // Drop the settle frames' timestamps.
        timer.read(&device, &queue).map_err(|e| format!("{label}: {e}"))?;
        let (mut times, mut gpu) = (Vec::new(), Vec::new());
        for _ in 0..args.frames {
            let t0 = Instant::now();
            app.update();
            crepuscular::gpu::wait_idle(&device).map_err(|e| e.to_string())?;
            times.push(t0.elapsed().as_secs_f64() * 1e3);
            if let Some(ms) = timer.read(&device, &queue).map_err(|e| format!("{label}: {e}"))? {
                gpu.push(ms);
            }
        }
        let bracket = (!gpu.is_empty() && gpu.len() == times.len()).then(|| median(&mut gpu));
        // A software adapter's timestamps are logged (progress.log) but not used.
        let gpu_ms = bracket.filter(|_| !software);
        let captured = demo::capture(&mut app).map_err(|e| format!("{label}: {e}"))?;
        let file = args.output.join(format!("{}.png", slug(&label)));
        demo::save_png(&captured, &file)?;
        let image = rgb8(&captured)?;
        let run = Run { label, family, frame_ms: median(&mut times), gpu_ms, image };
        let stamps = match bracket {
            Some(ms) if software => format!("{ms:.3} ms (software adapter: not used)"),
            Some(ms) => format!("{ms:.3} ms"),
            None => "none".into(),
        };
        // Each configuration as it finishes (a long run cut short keeps what it measured).
        append_line(
            &args.output.join("progress.log"),
            &format!("{} | frame {:.3} ms | effect timestamps {stamps}", run.label, run.frame_ms),
        )?;
        runs.push(run);
        bar.inc(1);
    }
    bar.finish_and_clear();
    // Timestamps only where every rendered configuration has them (a hardware adapter).
    let timing = if runs.iter().all(|r| r.gpu_ms.is_some()) { Timing::Gpu } else { Timing::WallClock };
    // The loaded references' rows have no timing (NaN, written as "–"); they do not decide it.
    runs.extend(loaded);

    let baseline = runs.iter().find(|r| r.family == "baseline").ok_or("no baseline")?;
    let base = timing.ms(baseline);
    let bevy_ref = &runs.iter().find(|r| r.family == "bevy-converged").ok_or("no Bevy reference")?.image;
    let ours_ref = &runs.iter().find(|r| r.family == "ours-converged").ok_or("no plugin reference")?.image;
    let mut rows = Vec::new();
    for r in &runs {
        let reference = match r.family {
            "bevy" | "bevy-converged" => bevy_ref,
            "ours" | "ours-converged" => ours_ref,
            _ => continue,
        };
        let (psnr_db, flip) = quality(reference, &r.image)?;
        rows.push(Row {
            label: r.label.clone(),
            family: r.family,
            cost_ms: timing.ms(r) - base,
            frame_ms: r.frame_ms,
            psnr_db,
            flip,
        });
    }
    let md = markdown(&rows, &adapter, width, height, args.frames, base, timing);
    write_atomic(&args.output.join("versus.md"), md.as_bytes())?;
    write_atomic(&args.output.join("versus.json"), json(&rows, &adapter, width, height, base, timing).as_bytes())?;
    // One picture of both: Bevy at 64 steps (its default) beside the plugin's default technique.
    let left = runs
        .iter()
        .find(|r| r.label == "Bevy VolumetricFog 64 steps")
        .or_else(|| runs.iter().find(|r| r.family == "bevy"));
    let right = runs
        .iter()
        .find(|r| r.label == "crepuscular epipolar (balanced)")
        .or_else(|| runs.iter().find(|r| r.family == "ours"));
    if let (Some(l), Some(r)) = (left, right) {
        side_by_side(&[&l.image, &r.image], &args.output.join("side-by-side.png"))?;
    }
    // With --temporal: the plugin's converged picture, the first marching row alone and the
    // same row with the stage, left to right.
    let staged = runs.iter().find(|r| r.label.contains("temporal stage"));
    if let Some(staged) = staged {
        let plain_label = staged.label.split(" + temporal stage").next().unwrap_or_default();
        if let Some(plain) = runs.iter().find(|r| r.label == plain_label) {
            side_by_side(&[ours_ref, &plain.image, &staged.image], &args.output.join("temporal.png"))?;
        }
    }
    print!("{md}");
    eprintln!("wrote {}", args.output.join("versus.md").display());
    Ok(())
}

/// How the effect's cost was measured.
#[derive(Clone, Copy)]
enum Timing {
    /// GPU timestamps around the effect (`demo::EffectTimer`).
    Gpu,
    /// Whole frames by wall clock, update to device idle.
    WallClock,
}

impl Timing {
    fn ms(self, r: &Run) -> f64 {
        match self {
            Timing::Gpu => r.gpu_ms.unwrap_or(f64::NAN),
            Timing::WallClock => r.frame_ms,
        }
    }

    fn name(self) -> &'static str {
        match self {
            Timing::Gpu => "gpu-timestamps",
            Timing::WallClock => "wall-clock",
        }
    }

    fn describe(self, base: f64) -> String {
        match self {
            Timing::Gpu => format!(
                "Cost = the effect's GPU time (timestamps in Bevy's encoder after the main pass and before \
                 early post-processing) − the same bracket without fog ({base:.3} ms)"
            ),
            Timing::WallClock => format!(
                "Cost = frame time (wall clock, update to device idle) − the same scene without fog ({base:.1} ms)"
            ),
        }
    }
}

fn append_line(path: &Path, line: &str) -> Result<(), String> {
    use std::io::Write;
    let mut f = std::fs::OpenOptions::new()
        .create(true)
        .append(true)
        .open(path)
        .map_err(|e| format!("{}: {e}", path.display()))?;
    writeln!(f, "{line}").map_err(|e| format!("{}: {e}", path.display()))
}

fn median(v: &mut [f64]) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn slug(s: &str) -> String {
    let mut out = String::new();
    for c in s.chars() {
        if c.is_ascii_alphanumeric() {
            out.push(c.to_ascii_lowercase());
        } else if !out.ends_with('-') {
            out.push('-');
        }
    }
    out.trim_matches('-').to_string()
}

fn rgb8(img: &Image) -> Result<Rgb8, String> {
    let d = img.clone().try_into_dynamic().map_err(|e| e.to_string())?.to_rgb8();
    Ok(Rgb8 { width: d.width(), height: d.height(), data: d.into_raw() })
}

/// A picture written by an earlier run, which must be `width`×`height`.
fn load_png(file: &Path, width: u32, height: u32) -> Result<Rgb8, String> {
    let d = image::open(file).map_err(|e| format!("--references-from: {}: {e}", file.display()))?.to_rgb8();
    if (d.width(), d.height()) != (width, height) {
        return Err(format!(
            "--references-from: {}: {}x{}, but --size is {width}x{height}",
            file.display(),
            d.width(),
            d.height()
        ));
    }
    Ok(Rgb8 { width, height, data: d.into_raw() })
}

/// `TECHNIQUE:PRESET:KEY=VALUE;…` → the preset's settings with the overrides, validated, and
/// the row's description (the preset and the overrides).
fn parse_config(spec: &str) -> Result<(TechniqueSettings, String), String> {
    let mut parts = spec.splitn(3, ':');
    let (Some(name), Some(preset)) = (parts.next(), parts.next()) else {
        return Err(format!("--config {spec}: expected TECHNIQUE:PRESET:KEY=VALUE;…"));
    };
    let preset = Preset::parse(preset).map_err(|e| format!("--config {spec}: {e}"))?;
    let overrides: Vec<String> =
        parts.next().unwrap_or("").split(';').map(str::trim).filter(|o| !o.is_empty()).map(String::from).collect();
    let t = crepuscular_cli::view::parse_preset_technique(name, preset, &overrides)
        .map_err(|e| format!("--config {spec}: {e}"))?;
    if !t.has_gpu() {
        return Err(format!("--config {spec}: `{name}` runs on the CPU only"));
    }
    let what = std::iter::once(preset.name().to_string()).chain(overrides).collect::<Vec<_>>().join(", ");
    Ok((t, what))
}

/// PSNR (8-bit sRGB, peak 255) and FLIP mean of `test` against `reference`.
fn quality(reference: &Rgb8, test: &Rgb8) -> Result<(f64, f64), String> {
    let (w, h, r) = (reference.width, reference.height, &reference.data);
    let (w2, h2, t) = (test.width, test.height, &test.data);
    if (w, h) != (w2, h2) {
        return Err(format!("pictures of {w}x{h} and {w2}x{h2}"));
    }
    let mse = r.iter().zip(t).map(|(&a, &b)| (a as f64 - b as f64).powi(2)).sum::<f64>() / r.len() as f64;
    let psnr = if mse == 0.0 { f64::INFINITY } else { 10.0 * (255.0f64 * 255.0 / mse).log10() };
    let map = nv_flip::flip(
        nv_flip::FlipImageRgb8::with_data(w, h, r),
        nv_flip::FlipImageRgb8::with_data(w, h, t),
        nv_flip::DEFAULT_PIXELS_PER_DEGREE,
    );
    Ok((psnr, nv_flip::FlipPool::from_image(&map).mean() as f64))
}

/// The pictures side by side, left to right, 4 black pixels apart.
fn side_by_side(pictures: &[&Rgb8], path: &Path) -> Result<(), String> {
    let (w, h) = (pictures[0].width, pictures[0].height);
    if pictures.iter().any(|p| (p.width, p.height) != (w, h)) {
        return Err(format!("{}: pictures of different sizes", path.display()));
    }
    let gap = 4u32;
    let n = pictures.len() as u32;
    let mut out = image::RgbImage::new(n * w + (n - 1) * gap, h);
    for (k, p) in pictures.iter().map(|p| &p.data).enumerate() {
        for y in 0..h {
            for x in 0..w {
                let i = ((y * w + x) * 3) as usize;
                out.put_pixel(k as u32 * (w + gap) + x, y, image::Rgb([p[i], p[i + 1], p[i + 2]]));
            }
        }
    }
    let mut png = std::io::Cursor::new(Vec::new());
    out.write_to(&mut png, image::ImageFormat::Png).map_err(|e| format!("{}: {e}", path.display()))?;
    write_atomic(path, png.get_ref())
}

fn write_atomic(path: &Path, bytes: &[u8]) -> Result<(), String> {
    crepuscular_cli::output::write_atomic(path, bytes).map_err(|e| format!("{}: {e}", path.display()))
}

fn markdown(rows: &[Row], adapter: &str, w: u32, h: u32, frames: u32, base: f64, timing: Timing) -> String {
    let mut s = format!(
        "Adapter: {adapter}. {w}x{h}, the demo colonnade (sun, one cascade), median of {frames} frames. \
         {}. Quality of the final picture against \
         the effect's own converged picture (Bevy: 1024 steps; plugin: brute-force 1024 steps).\n\n\
         | effect | cost (ms) | whole frame, wall clock (ms) | PSNR (dB) | FLIP |\n| --- | ---: | ---: | ---: | ---: |\n",
        timing.describe(base)
    );
    // Milliseconds to three decimals on hardware (costs below a millisecond), one on software.
    let d = match timing {
        Timing::Gpu => 3,
        Timing::WallClock => 1,
    };
    // A picture read with --references-from has no timing.
    let ms =
        |v: f64, d: usize| if v.is_finite() { format!("{v:.d$}") } else { "– (read from an earlier run)".into() };
    for r in rows {
        s += &format!(
            "| {} | {} | {} | {:.1} | {:.4} |\n",
            r.label,
            ms(r.cost_ms, d),
            ms(r.frame_ms, 1),
            r.psnr_db,
            r.flip
        );
    }
    s += "\n**At equal quality** (for each plugin configuration, the cheapest Bevy step count whose PSNR is at least as high):\n\n\
          | plugin | its cost (ms) | PSNR | cheapest Bevy at ≥ that PSNR | Bevy's cost (ms) | plugin / Bevy |\n| --- | ---: | ---: | --- | ---: | ---: |\n";
    for r in rows.iter().filter(|r| r.family == "ours") {
        let bevy = rows
            .iter()
            .filter(|b| b.family == "bevy" && b.psnr_db >= r.psnr_db)
            .min_by(|a, b| a.cost_ms.total_cmp(&b.cost_ms));
        match bevy {
            Some(b) => {
                s += &format!(
                    "| {} | {:.d$} | {:.1} | {} ({:.1} dB) | {:.d$} | {:.2} |\n",
                    r.label,
                    r.cost_ms,
                    r.psnr_db,
                    b.label,
                    b.psnr_db,
                    b.cost_ms,
                    r.cost_ms / b.cost_ms
                )
            }
            None => {
                s += &format!(
                    "| {} | {:.d$} | {:.1} | none measured reaches it | – | – |\n",
                    r.label, r.cost_ms, r.psnr_db
                )
            }
        }
    }
    s
}

fn json(rows: &[Row], adapter: &str, w: u32, h: u32, base: f64, timing: Timing) -> String {
    let rows: Vec<_> = rows
        .iter()
        .map(|r| {
            serde_json::json!({"effect": r.label, "family": r.family, "cost_ms": r.cost_ms, "frame_ms": r.frame_ms,
                               "psnr_db": r.psnr_db, "flip": r.flip})
        })
        .collect();
    let doc = serde_json::json!({"adapter": adapter, "width": w, "height": h, "timing": timing.name(),
                                 "baseline_ms": base, "rows": rows});
    serde_json::to_string_pretty(&doc).unwrap_or_default() + "\n"
}
