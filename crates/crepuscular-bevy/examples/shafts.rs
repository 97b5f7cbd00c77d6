//! The plugin in a Bevy app: the demo colonnade with light shafts, in a window (T switches to
//! the next technique, A turns temporal accumulation on and off, Escape quits), or headless
//! into a PNG with `--screenshot`.
//!
//! ```text
//! cargo run --release -p crepuscular-bevy --example shafts                       # a window
//! cargo run --release -p crepuscular-bevy --example shafts -- --screenshot shafts.png --frames 4
//! cargo run --release -p crepuscular-bevy --example shafts -- --technique prefiltered --preset fast --lamps --screenshot p.png
//! cargo run --release -p crepuscular-bevy --example shafts -- --bevy-fog 64 --screenshot bevy.png
//! cargo run --release -p crepuscular-bevy --example shafts -- --technique brute-force --preset fast --temporal --frames 12 --screenshot t.png
//! ```

use std::path::PathBuf;

use bevy::prelude::*;
use bevy::render::view::screenshot::{Screenshot, ScreenshotCaptured};
use clap::Parser;
use crepuscular::TechniqueSettings;
use crepuscular::techniques::presets::Preset;
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
    /// Temporal accumulation after the technique (`CrepuscularTemporal` at its defaults, with
    /// Bevy's motion vectors): the samples move every frame and the frames are blended.
    #[arg(long)]
    temporal: bool,
    /// Image (or window) size, WIDTHxHEIGHT.
    #[arg(long, default_value = "960x540")]
    size: String,
    /// Headless: frames to render (at least; on until Bevy's pipelines are built) before the screenshot.
    #[arg(long, default_value_t = 4)]
    frames: u32,
    /// Render headless and write the picture to this PNG (without it: a window).
    #[arg(long)]
    screenshot: Option<PathBuf>,
    /// In the window: after `--frames` frames, save the window's picture to this PNG and quit
    /// (to check the windowed path without a person, e.g. under Xvfb).
    #[arg(long)]
    window_screenshot: Option<PathBuf>,
}

fn main() {
    if let Err(e) = run(Args::parse()) {
        eprintln!("error: {e}");
        std::process::exit(1);
    }
}

fn run(args: Args) -> Result<(), String> {
    let (width, height) = demo::parse_size(&args.size)?;
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
        Effect::Crepuscular(demo::crepuscular(technique))
    };
    if args.temporal && !matches!(effect, Effect::Crepuscular(_)) {
        return Err("--temporal: the stage runs after the plugin's technique, not with --bevy-fog or --no-fog".into());
    }
    let temporal = args.temporal.then(crepuscular_bevy::CrepuscularTemporal::default);
    let opts = DemoOptions { width, height, effect, lamps: args.lamps, temporal, ..Default::default() };
    let Some(screenshot) = args.screenshot else {
        let mut app = demo::windowed_app(&opts);
        if let Some(path) = args.window_screenshot {
            let frames = args.frames;
            app.add_systems(Update, move |mut n: Local<u32>, mut commands: Commands| {
                *n += 1;
                if *n == frames {
                    let path = path.clone();
                    commands.spawn(Screenshot::primary_window()).observe(
                        move |captured: On<ScreenshotCaptured>, mut exit: MessageWriter<AppExit>| match demo::save_png(
                            &captured.image,
                            &path,
                        ) {
                            Ok(()) => {
                                eprintln!("wrote {}", path.display());
                                exit.write(AppExit::Success);
                            }
                            Err(e) => {
                                eprintln!("error: {e}");
                                exit.write(AppExit::error());
                            }
                        },
                    );
                }
            });
        }
        return match app.run() {
            AppExit::Success => Ok(()),
            AppExit::Error(code) => Err(format!("the app exited with code {code}")),
        };
    };
    let mut app = demo::headless_app(&opts);
    app.finish();
    app.cleanup();
    eprintln!("rendering {} frames at {width}x{height} …", args.frames);
    let image = demo::render_frames(&mut app, args.frames)?;
    demo::save_png(&image, &screenshot)?;
    eprintln!("wrote {}", screenshot.display());
    Ok(())
}
