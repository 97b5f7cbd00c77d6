//! The plugin in a Bevy app: the demo colonnade with light shafts, rendered headless into a PNG.
//!
//! ```text
//! cargo run --release -p crepuscular-bevy --example shafts -- --screenshot shafts.png
//! cargo run --release -p crepuscular-bevy --example shafts -- --technique prefiltered --preset fast --lamps --screenshot p.png
//! cargo run --release -p crepuscular-bevy --example shafts -- --bevy-fog 64 --screenshot bevy.png
//! ```
//! In a window (`--features window`), T switches to the next technique.

use std::path::PathBuf;

use clap::Parser;
use crepuscular::TechniqueSettings;
use crepuscular::techniques::presets::Preset;
use crepuscular_bevy::Crepuscular;
use crepuscular_bevy::demo::{self, DemoOptions, Effect};

#[derive(Parser)]
#[command(about = "The crepuscular Bevy plugin on the demo colonnade")]
struct Args {
    /// Technique (any GPU technique of the library: epipolar, prefiltered, minmax, brute-force, …).
    #[arg(long, default_value = "epipolar")]
    technique: String,
    /// Preset of the technique: fast, balanced, reference-like.
    #[arg(long, default_value = "balanced")]
    preset: String,
    /// Render Bevy's own VolumetricFog at this many steps instead of the plugin.
    #[arg(long)]
    bevy_fog: Option<u32>,
    /// Render without any fog.
    #[arg(long)]
    no_fog: bool,
    /// Add a spot and a point lamp to the sun (both scatter).
    #[arg(long)]
    lamps: bool,
    /// Image size, WIDTHxHEIGHT.
    #[arg(long, default_value = "640x360")]
    size: String,
    /// Frames to render before the screenshot.
    #[arg(long, default_value_t = 4)]
    frames: u32,
    /// Where to write the PNG (headless).
    #[arg(long, default_value = "shafts.png")]
    screenshot: PathBuf,
}

fn main() {
    if let Err(e) = run(Args::parse()) {
        eprintln!("error: {e}");
        std::process::exit(1);
    }
}

fn run(args: Args) -> Result<(), String> {
    let (width, height) = args
        .size
        .split_once('x')
        .and_then(|(w, h)| Some((w.parse::<u32>().ok()?, h.parse::<u32>().ok()?)))
        .filter(|&(w, h)| w > 0 && h > 0)
        .ok_or_else(|| format!("--size {}: expected WIDTHxHEIGHT, e.g. 640x360", args.size))?;
    let effect = if args.no_fog {
        Effect::None
    } else if let Some(steps) = args.bevy_fog {
        if steps == 0 {
            return Err("--bevy-fog 0: the step count must be at least 1".into());
        }
        Effect::BevyFog { steps }
    } else {
        let preset = Preset::parse(&args.preset).map_err(|e| e.to_string())?;
        let technique: TechniqueSettings = preset.settings(&args.technique).ok_or_else(|| {
            format!("--technique {}: {}", args.technique, TechniqueSettings::named(&args.technique).unwrap_err())
        })?;
        if !technique.has_gpu() {
            return Err(format!("--technique {}: CPU only; the plugin runs GPU techniques", args.technique));
        }
        Effect::Crepuscular(Crepuscular { technique, ..Default::default() })
    };
    let opts = DemoOptions { width, height, effect, lamps: args.lamps, ..Default::default() };
    let mut app = demo::headless_app(&opts);
    app.finish();
    app.cleanup();
    eprintln!("rendering {} frames at {width}x{height} …", args.frames);
    let image = demo::render_frames(&mut app, args.frames)?;
    demo::save_png(&image, &args.screenshot)?;
    eprintln!("wrote {}", args.screenshot.display());
    Ok(())
}
