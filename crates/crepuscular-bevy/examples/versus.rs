//! The side-by-side benchmark: Bevy's own `VolumetricFog` at step counts 16–256 against the
//! plugin's techniques at their presets, on the same scene, medium and adapter (docs/BEVY.md,
//! docs/RESULTS.md "Bevy's VolumetricFog against the plugin").
//!
//! ```text
//! cargo run --release -p crepuscular-bevy --example versus -- --size 1920x1080 --output docs/results/bevy-versus
//! ```
//!
//! Per configuration: a fresh app on the demo colonnade, settled (pipelines built), then
//! `--frames` frames each timed by wall clock from `update` to the device being idle (a
//! software adapter's timestamps mean nothing; on hardware this still measures whole frames).
//! The effect's cost is its frame's median minus the median of the same scene without fog.
//! Quality: PSNR and FLIP of the final (tone-mapped, 8-bit) picture against the effect's own
//! converged picture: Bevy at 1024 steps; the plugin's brute-force march at 1024 steps.
//! Writes `versus.md` (the table), `versus.json`, `side-by-side.png` and each picture.

use std::path::{Path, PathBuf};
use std::time::Instant;

use bevy::prelude::*;
use clap::Parser;
use crepuscular::TechniqueSettings;
use crepuscular::techniques::presets::Preset;
use crepuscular_bevy::Crepuscular;
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
    /// Output folder.
    #[arg(long, default_value = "bevy-versus")]
    output: PathBuf,
}

struct Run {
    label: String,
    family: &'static str,
    ms: f64,
    image: Image,
}

struct Row {
    label: String,
    family: &'static str,
    cost_ms: f64,
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
    std::fs::create_dir_all(&args.output).map_err(|e| format!("{}: {e}", args.output.display()))?;

    let mut configs: Vec<(String, &'static str, Effect)> = vec![("no fog".into(), "baseline", Effect::None)];
    for &s in &args.steps {
        configs.push((format!("Bevy VolumetricFog {s} steps"), "bevy", Effect::BevyFog { steps: s }));
    }
    configs.push((
        "Bevy VolumetricFog 1024 steps (converged)".into(),
        "bevy-converged",
        Effect::BevyFog { steps: 1024 },
    ));
    let mut converged = crepuscular::techniques::presets::Preset::ReferenceLike.brute_force();
    converged.ray_march.steps = 1024;
    configs.push((
        "crepuscular brute-force 1024 steps (converged)".into(),
        "ours-converged",
        Effect::Crepuscular(Crepuscular { technique: TechniqueSettings::BruteForce(converged), ..Default::default() }),
    ));
    for info in crepuscular::techniques::TECHNIQUES {
        for &p in &presets {
            let Some(t) = p.settings(info.name) else { continue };
            if !t.has_gpu() {
                continue;
            }
            configs.push((
                format!("crepuscular {} ({})", info.name, p.name()),
                "ours",
                Effect::Crepuscular(Crepuscular { technique: t, ..Default::default() }),
            ));
        }
    }

    let bar = ProgressBar::new(configs.len() as u64);
    bar.set_style(ProgressStyle::with_template("{bar:30} {pos}/{len} {elapsed} {msg}").map_err(|e| e.to_string())?);
    let mut runs = Vec::new();
    let mut adapter = String::new();
    for (label, family, effect) in configs {
        bar.set_message(label.clone());
        // Bevy's logger is process-wide: the first app installs it.
        let opts = DemoOptions { width, height, effect, lamps: false, log: runs.is_empty(), ..Default::default() };
        let mut app = demo::headless_app(&opts);
        app.finish();
        app.cleanup();
        demo::settle(&mut app, 3).map_err(|e| format!("{label}: {e}"))?;
        let device = app.world().resource::<bevy::render::renderer::RenderDevice>().wgpu_device().clone();
        if adapter.is_empty() {
            let info = app.world().resource::<bevy::render::renderer::RenderAdapterInfo>();
            adapter = format!(
                "{} ({:?}, {:?}, driver {} {})",
                info.name, info.backend, info.device_type, info.driver, info.driver_info
            );
        }
        crepuscular::gpu::wait_idle(&device).map_err(|e| e.to_string())?;
        let mut times = Vec::new();
        for _ in 0..args.frames {
            let t0 = Instant::now();
            app.update();
            crepuscular::gpu::wait_idle(&device).map_err(|e| e.to_string())?;
            times.push(t0.elapsed().as_secs_f64() * 1e3);
        }
        times.sort_by(f64::total_cmp);
        let image = demo::capture(&mut app).map_err(|e| format!("{label}: {e}"))?;
        let file = args.output.join(format!("{}.png", slug(&label)));
        demo::save_png(&image, &file)?;
        runs.push(Run { label, family, ms: times[times.len() / 2], image });
        bar.inc(1);
    }
    bar.finish_and_clear();

    let base = runs.iter().find(|r| r.family == "baseline").ok_or("no baseline")?.ms;
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
        rows.push(Row { label: r.label.clone(), family: r.family, cost_ms: r.ms - base, psnr_db, flip });
    }
    let md = markdown(&rows, &adapter, width, height, args.frames, base);
    write_atomic(&args.output.join("versus.md"), md.as_bytes())?;
    write_atomic(&args.output.join("versus.json"), json(&rows, &adapter, width, height, base).as_bytes())?;
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
        side_by_side(&l.image, &r.image, &args.output.join("side-by-side.png"))?;
    }
    print!("{md}");
    eprintln!("wrote {}", args.output.join("versus.md").display());
    Ok(())
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

fn rgb8(img: &Image) -> Result<(u32, u32, Vec<u8>), String> {
    let d = img.clone().try_into_dynamic().map_err(|e| e.to_string())?.to_rgb8();
    Ok((d.width(), d.height(), d.into_raw()))
}

/// PSNR (8-bit sRGB, peak 255) and FLIP mean of `test` against `reference`.
fn quality(reference: &Image, test: &Image) -> Result<(f64, f64), String> {
    let (w, h, r) = rgb8(reference)?;
    let (w2, h2, t) = rgb8(test)?;
    if (w, h) != (w2, h2) {
        return Err(format!("pictures of {w}x{h} and {w2}x{h2}"));
    }
    let mse = r.iter().zip(&t).map(|(&a, &b)| (a as f64 - b as f64).powi(2)).sum::<f64>() / r.len() as f64;
    let psnr = if mse == 0.0 { f64::INFINITY } else { 10.0 * (255.0f64 * 255.0 / mse).log10() };
    let map = nv_flip::flip(
        nv_flip::FlipImageRgb8::with_data(w, h, &r),
        nv_flip::FlipImageRgb8::with_data(w, h, &t),
        nv_flip::DEFAULT_PIXELS_PER_DEGREE,
    );
    Ok((psnr, nv_flip::FlipPool::from_image(&map).mean() as f64))
}

fn side_by_side(left: &Image, right: &Image, path: &Path) -> Result<(), String> {
    let (w, h, l) = rgb8(left)?;
    let (_, _, r) = rgb8(right)?;
    let gap = 4u32;
    let mut out = image::RgbImage::new(2 * w + gap, h);
    for y in 0..h {
        for x in 0..w {
            let i = ((y * w + x) * 3) as usize;
            out.put_pixel(x, y, image::Rgb([l[i], l[i + 1], l[i + 2]]));
            out.put_pixel(w + gap + x, y, image::Rgb([r[i], r[i + 1], r[i + 2]]));
        }
    }
    let mut png = std::io::Cursor::new(Vec::new());
    out.write_to(&mut png, image::ImageFormat::Png).map_err(|e| format!("{}: {e}", path.display()))?;
    write_atomic(path, png.get_ref())
}

fn write_atomic(path: &Path, bytes: &[u8]) -> Result<(), String> {
    crepuscular_cli::output::write_atomic(path, bytes).map_err(|e| format!("{}: {e}", path.display()))
}

fn markdown(rows: &[Row], adapter: &str, w: u32, h: u32, frames: u32, base: f64) -> String {
    let mut s = format!(
        "Adapter: {adapter}. {w}x{h}, the demo colonnade (sun, one cascade), median of {frames} frames. \
         Cost = frame time − the same scene without fog ({base:.1} ms). Quality of the final picture against \
         the effect's own converged picture (Bevy: 1024 steps; plugin: brute-force 1024 steps).\n\n\
         | effect | cost (ms) | PSNR (dB) | FLIP |\n| --- | ---: | ---: | ---: |\n"
    );
    for r in rows {
        s += &format!("| {} | {:.1} | {:.1} | {:.4} |\n", r.label, r.cost_ms, r.psnr_db, r.flip);
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
                    "| {} | {:.1} | {:.1} | {} ({:.1} dB) | {:.1} | {:.2} |\n",
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
                    "| {} | {:.1} | {:.1} | none measured reaches it | – | – |\n",
                    r.label, r.cost_ms, r.psnr_db
                )
            }
        }
    }
    s
}

fn json(rows: &[Row], adapter: &str, w: u32, h: u32, base: f64) -> String {
    let rows: Vec<_> = rows
        .iter()
        .map(|r| {
            serde_json::json!({"effect": r.label, "family": r.family, "cost_ms": r.cost_ms,
                               "psnr_db": r.psnr_db, "flip": r.flip})
        })
        .collect();
    let doc = serde_json::json!({"adapter": adapter, "width": w, "height": h, "baseline_ms": base, "rows": rows});
    serde_json::to_string_pretty(&doc).unwrap_or_default() + "\n"
}
