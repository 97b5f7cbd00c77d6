//! `crepuscular`: render, compare and measure single scattering from the command line.

use anyhow::{Context, Result, bail};
use clap::{Parser, Subcommand};
use crepuscular::tonemap::ToneMap;
use crepuscular_cli::render::{self, Backend, RenderOptions, TechniqueChoice};
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
    /// Print the GPU adapter that `--backend auto|gpu` would use (fails if there is none).
    Adapter,
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
    let technique = TechniqueChoice::parse(&a.technique, &scene, &a.set)?;
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
    let out = render::render(&scene, gpu.as_ref(), &RenderOptions { technique, progress: &progress })?;
    bar.finish_and_clear();
    let tone = ToneMap::new(scene.render.exposure);
    let rgb = tone.to_rgb8(&out.final_radiance);
    output::write_png_rgb8(&a.output, scene.render.width, scene.render.height, &rgb)?;
    eprintln!("wrote {}", a.output.display());
    if let Some(exr) = &a.exr {
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
