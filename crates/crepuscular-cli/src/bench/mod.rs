//! `crepuscular bench`: the matrix scene × size × technique × setting, timed per pass over
//! repeated frames after warm-up frames, with ray-marched samples, GPU memory and quality vs
//! `reference`; written as `bench.json`, `bench.md` and SVG plots. Named presets reproduce the
//! papers' own experiments.
//!
//! Timing: every pass of every frame is measured by the library's `Scattering` (GPU timestamp
//! queries read back after the frame on hardware adapters, `StatsMode::Deferred`; a
//! synchronised wall clock on software adapters, `StatsMode::WallClock`, and on the CPU).
//! Warm-up frames (pipeline compilation, first-use allocation) are excluded; the report gives
//! the median and the min–max spread over the timed frames. Timings are only comparable within
//! one run on one device: the device is recorded in every output.
//!
//! Split along its seams: the plan and its run here; [`presets`] the papers' experiments;
//! [`report`] bench.md's tables; [`plot`] the plots and the files written.

use crate::animate::{
    AnimatedTechnique, Flicker, FlickerMeter, LIGHT_JUMP_DEGREES, MotionPath, PathRenderer, Stage, frame_time,
    recovery_frames, with_jitter,
};
use crate::metrics::Quality;
use crate::render::{self, AdapterStats, adapter_stats, frame_desc, load_scene, parse_technique};
use anyhow::{Context, Result, bail};
use crepuscular::TechniqueSettings;
use crepuscular::frame::surface_transmittance;
use crepuscular::gpu::GpuContext;
use crepuscular::stats::TechniqueStats;
use crepuscular::techniques::reference::{self, ReferenceSettings};
use crepuscular::temporal::TemporalSettings;
use crepuscular::tonemap::{ToneMap, composite};
use crepuscular::{CpuFrame, Image};
use crepuscular_scene::{GpuHost, host, host_cpu};
use serde::Serialize;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

pub mod plot;
pub mod presets;
pub mod report;

pub use plot::write;
use presets::*;
pub use presets::{KLEHM_TABLE1, KLEHM_TABLE2, PRESETS, TEMPORAL_PRESET, preset};
pub use report::markdown;

/// One technique configuration of the matrix.
#[derive(Clone, Debug, Serialize)]
pub struct Variant {
    /// Technique name.
    pub technique: String,
    /// `key=value` settings on top of the scene's `[render.<technique>]` table.
    pub overrides: Vec<String>,
    /// The curve this variant belongs to in plots (technique plus the fixed settings).
    pub series: String,
    /// The swept setting and its value (the x of a curve), if any.
    pub sweep: Option<(String, f64)>,
}

impl Variant {
    /// A variant named `series`, sweeping `key` (if any) at `value`.
    pub fn new(technique: &str, overrides: &[&str], series: &str, sweep: Option<(&str, f64)>) -> Self {
        Variant {
            technique: technique.into(),
            overrides: overrides.iter().map(|s| s.to_string()).collect(),
            series: series.into(),
            sweep: sweep.map(|(k, v)| (k.to_string(), v)),
        }
    }

    /// Series plus the swept value: one row of the tables.
    pub fn label(&self) -> String {
        if self.overrides.is_empty() {
            self.series.clone()
        } else {
            format!("{} {}", self.technique, self.overrides.join(" "))
        }
    }
}

/// What a bench run does.
#[derive(Clone, Debug, Serialize)]
pub struct BenchPlan {
    /// Preset name, or "custom".
    pub name: String,
    /// What it reproduces and how to read it.
    pub description: String,
    /// Scenes (built-in names or scene files).
    pub scenes: Vec<String>,
    /// Image sizes.
    pub sizes: Vec<(u32, u32)>,
    /// Technique configurations.
    pub variants: Vec<Variant>,
    /// Timed frames per configuration.
    pub repeat: u32,
    /// Untimed frames before them.
    pub warmup: u32,
    /// Steps of the quality reference (0: no quality measurement).
    pub reference_steps: u32,
    /// The shadow filter every scene's lights are read with, in place of the scene's own
    /// (`render.shadow_filter`, default bilinear). The papers' presets pin `nearest`: the
    /// binary visibility their techniques are written for and their published figures use
    /// (docs/RESULTS.md). None: each scene's own.
    pub shadow_filter: Option<crepuscular::ShadowFilter>,
}

impl BenchPlan {
    /// Loads one of the plan's scenes ([`load_scene`]) with the plan's
    /// [`shadow_filter`](Self::shadow_filter), if it pins one.
    pub fn load_scene(&self, name: &str) -> Result<crepuscular_scene::Scene> {
        let mut scene = load_scene(name)?;
        if let Some(f) = self.shadow_filter {
            scene.render.shadow.filter = f;
        }
        Ok(scene)
    }
}

/// The steps swept by default for each ray-marching technique.
pub const DEFAULT_STEP_SWEEP: [u32; 4] = [16, 32, 64, 128];

/// The default plan: every built-in scene, each given technique swept over its main setting.
pub fn default_plan(scenes: Vec<String>, techniques: &[String]) -> Result<BenchPlan> {
    let mut variants = Vec::new();
    for t in techniques {
        if t == "reference" {
            bail!("`reference` is the quality yardstick of every bench row; it is not benchmarked");
        }
        let settings = TechniqueSettings::named(t).map_err(|e| anyhow::anyhow!("{e}"))?;
        // Every technique that marches its rays (the shared `steps` setting) is swept over it;
        // the others run at their defaults.
        let marches = serde_json::to_value(&settings).ok().is_some_and(|v| v.get("steps").is_some());
        if marches {
            for n in DEFAULT_STEP_SWEEP {
                let o = format!("steps={n}");
                variants.push(Variant::new(t, &[&o], t, Some(("steps", n as f64))));
            }
        } else {
            variants.push(Variant::new(t, &[], t, None));
        }
    }
    Ok(BenchPlan {
        name: "custom".into(),
        description: "each technique over its main setting (steps) on the given scenes".into(),
        scenes,
        sizes: vec![(320, 180)],
        variants,
        repeat: 5,
        warmup: 2,
        reference_steps: 256,
        shadow_filter: None,
    })
}

/// Median, min and max of one pass over the timed frames.
#[derive(Clone, Debug, Serialize)]
pub struct PassSummary {
    /// Pass name.
    pub name: String,
    /// Median, milliseconds.
    pub median_ms: f64,
    /// Fastest frame, milliseconds.
    pub min_ms: f64,
    /// Slowest frame, milliseconds.
    pub max_ms: f64,
}

/// One row of the matrix.
#[derive(Clone, Debug, Serialize)]
pub struct BenchRecord {
    /// Scene name.
    pub scene: String,
    /// Width, height.
    pub size: [u32; 2],
    /// Technique.
    pub technique: String,
    /// Curve in the plots.
    pub series: String,
    /// Row label.
    pub label: String,
    /// Swept setting and value.
    pub sweep: Option<(String, f64)>,
    /// Full settings.
    pub settings: TechniqueSettings,
    /// Per pass over the timed frames.
    pub passes: Vec<PassSummary>,
    /// The whole technique per frame: median, min, max (ms).
    pub total_ms: [f64; 3],
    /// Ray-marched samples per frame.
    pub raymarched_samples: u64,
    /// GPU memory the technique holds.
    pub gpu_memory_bytes: u64,
    /// PSNR of the linear in-scattering vs reference (dB).
    pub psnr_db: Option<f64>,
    /// FLIP mean of the tone-mapped final image vs reference.
    pub flip_mean: Option<f64>,
    /// The technique's own extra numbers (last frame).
    pub extra: BTreeMap<String, f64>,
    /// Temporal stability vs reference along the scene's `animate` path (see
    /// [`BenchReport::flicker_frames`]); `None` where not measured.
    pub flicker: Option<Flicker>,
    /// The row with the temporal stage after a slow camera move (see [`measure_temporal`]);
    /// `None` where not measured.
    pub temporal: Option<TemporalColumn>,
}

/// One row's temporal column: its technique along a slow camera move (the scene's `animate`
/// path, frames 1/[`TEMPORAL_LOOP`] of the loop apart, lights still), as configured and with
/// `jitter` on (where it has one) followed by the temporal stage, each frame against its own
/// reference. PSNR of the linear in-scattering and FLIP of the tone-mapped final image are the
/// last frame's (the frames before it are its history); flicker is over all the frames.
#[derive(Clone, Debug, Serialize)]
pub struct TemporalColumn {
    /// Last frame, the row as configured (no stage): PSNR dB.
    #[serde(with = "crate::metrics::psnr_serde")]
    pub psnr_db_without: f64,
    /// Last frame, the row as configured: FLIP mean.
    pub flip_without: f64,
    /// Last frame, jitter + stage: PSNR dB.
    #[serde(with = "crate::metrics::psnr_serde")]
    pub psnr_db: f64,
    /// Last frame, jitter + stage: FLIP mean.
    pub flip: f64,
    /// Flicker of the row as configured over the frames.
    pub flicker_without: Flicker,
    /// Flicker with jitter + stage.
    pub flicker: Flicker,
    /// Whether `jitter=true` was added to the row's settings for the stage.
    pub jitter_added: bool,
    /// The stage's wall-clock time per frame (median, ms), around its submit and wait.
    pub stage_ms: f64,
    /// The ghosting measure: the frames after a light jump that follows the slow move
    /// ([`BenchReport::ghost_frames`]); `None` where not measured.
    pub light_jump: Option<LightJumpColumn>,
}

/// The frames after a light jump (every light turned by [`LIGHT_JUMP_DEGREES`] at the frame
/// after the slow move's measured one, the camera still moving as before), the row as
/// configured and with jitter + the stage, each frame against its own reference: what
/// `animate --still-lights --frames 96 --light-jump F --temporal --flicker` measures on the
/// same frames (its `recovery_frames`).
#[derive(Clone, Debug, Serialize)]
pub struct LightJumpColumn {
    /// The frame the lights jumped at (the slow move's frame count).
    pub jump_frame: u32,
    /// Per frame from the jump on, the row as configured: PSNR dB.
    #[serde(with = "crate::metrics::psnr_vec_serde")]
    pub psnr_db_without: Vec<f64>,
    /// Per frame from the jump on, jitter + stage: PSNR dB.
    #[serde(with = "crate::metrics::psnr_vec_serde")]
    pub psnr_db: Vec<f64>,
    /// Frames from the jump until the row as configured is within 1 dB of its new steady state
    /// (the mean of its last 4 frames; [`recovery_frames`]): 0 for a technique without
    /// history, unless its error moves along the path.
    pub recovery_frames_without: Option<u32>,
    /// The same for jitter + stage: the ghosting measure. None: never within the frames.
    pub recovery_frames: Option<u32>,
}

impl BenchRecord {
    /// Whether the row's technique has a `jitter` setting (the temporal column turns it on).
    pub fn settings_have_jitter(&self) -> bool {
        self.settings.ray_march().is_some()
    }
}

/// The frame without scattering: the host renderer's passes (shadow map, depth and surface).
#[derive(Clone, Debug, Serialize)]
pub struct HostRecord {
    /// Scene.
    pub scene: String,
    /// Width, height.
    pub size: [u32; 2],
    /// Per pass.
    pub passes: Vec<PassSummary>,
    /// Median, min, max of the whole host frame (ms).
    pub total_ms: [f64; 3],
}

/// Everything a bench run measured.
#[derive(Clone, Debug, Serialize)]
pub struct BenchReport {
    /// The plan.
    pub plan: BenchPlan,
    /// The device; a result without its device is not a result.
    pub adapter: AdapterStats,
    /// "gpu" or "cpu".
    pub backend: String,
    /// How passes were timed ("timestamp" or "wall-clock").
    pub timing: String,
    /// UTC date of the run (YYYY-MM-DD).
    pub date: String,
    /// The command line.
    pub command: String,
    /// The host frame per scene and size.
    pub host: Vec<HostRecord>,
    /// The matrix.
    pub records: Vec<BenchRecord>,
    /// Frames of the flicker measurement (0: not measured): frames 1/24 of the scene's
    /// `animate` loop apart, at [`BenchReport::flicker_size`], for the rows of the smallest size.
    pub flicker_frames: u32,
    /// Size the flicker and the temporal column were measured at ([`flicker_sizes`]).
    pub flicker_size: Option<[u32; 2]>,
    /// Frames of the temporal column (0: not measured); its size is the flicker's rule's.
    pub temporal_frames: u32,
    /// The temporal stage's settings of that column.
    pub temporal: Option<TemporalSettings>,
    /// Frames of the temporal column's light jump, after its slow move (0: not measured;
    /// [`LightJumpColumn`]).
    pub ghost_frames: u32,
}

fn median_min_max(v: &[f64]) -> [f64; 3] {
    if v.is_empty() {
        return [0.0; 3];
    }
    let mut s = v.to_vec();
    s.sort_by(f64::total_cmp);
    let n = s.len();
    let med = if n % 2 == 1 { s[n / 2] } else { 0.5 * (s[n / 2 - 1] + s[n / 2]) };
    [med, s[0], s[n - 1]]
}

/// Summaries of per-frame pass lists (same pass names each frame).
fn summarise(frames: &[Vec<crepuscular::stats::PassTime>]) -> (Vec<PassSummary>, [f64; 3]) {
    let mut names: Vec<String> = Vec::new();
    for f in frames {
        for p in f {
            if !names.contains(&p.name) {
                names.push(p.name.clone());
            }
        }
    }
    let passes = names
        .iter()
        .map(|n| {
            let v: Vec<f64> = frames.iter().map(|f| f.iter().filter(|p| &p.name == n).map(|p| p.ms).sum()).collect();
            let [median_ms, min_ms, max_ms] = median_min_max(&v);
            PassSummary { name: n.clone(), median_ms, min_ms, max_ms }
        })
        .collect();
    let totals: Vec<f64> = frames.iter().map(|f| f.iter().map(|p| p.ms).sum()).collect();
    (passes, median_min_max(&totals))
}

/// Today's UTC date from the system clock (days-from-civil inverse, Hinnant's algorithm).
pub fn utc_date() -> String {
    let secs = std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map(|d| d.as_secs()).unwrap_or(0);
    let z = (secs / 86400) as i64 + 719468;
    let era = z.div_euclid(146097);
    let doe = z - era * 146097;
    let yoe = (doe - doe / 1460 + doe / 36524 - doe / 146096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = doy - (153 * mp + 2) / 5 + 1;
    let m = if mp < 10 { mp + 3 } else { mp - 9 };
    let y = yoe + era * 400 + i64::from(m <= 2);
    format!("{y:04}-{m:02}-{d:02}")
}

/// Images of one row, kept when asked (for `compare`'s contact sheet).
pub struct Kept {
    /// Scene.
    pub scene: String,
    /// Width, height.
    pub size: [u32; 2],
    /// Row label ("reference" for the reference).
    pub label: String,
    /// Linear in-scattering.
    pub inscatter: Image,
    /// Final radiance.
    pub final_radiance: Image,
    /// Wall-clock time of the row's last frame (ms).
    pub ms: f64,
}

/// Runs a plan. `progress` receives one line per step. With `keep_images`, the reference's
/// and every row's last images are returned too.
pub fn run(
    plan: &BenchPlan,
    gpu: Option<&GpuContext>,
    command: &str,
    progress: &dyn Fn(&str),
    reference_progress: &(dyn Fn(u64, u64) + Sync),
    keep_images: bool,
) -> Result<(BenchReport, Vec<Kept>)> {
    let mut kept = Vec::new();
    if plan.repeat == 0 {
        bail!("--repeat must be at least 1");
    }
    let mut host_records = Vec::new();
    let mut records = Vec::new();
    let mut timing = String::from("wall-clock");
    for scene_name in &plan.scenes {
        for &(w, h) in &plan.sizes {
            let mut scene = plan.load_scene(scene_name)?;
            scene.render.width = w;
            scene.render.height = h;
            let desc = frame_desc(&scene)?;
            if let Some(g) = gpu {
                g.check_texture_size("image size", w, h)?;
            }
            progress(&format!("{} {w}×{h}: host frame ×{}", scene.name, plan.warmup + plan.repeat));
            // The host frame (no scattering), timed like a technique; its outputs feed every row.
            let mut host_frames = Vec::new();
            let gpu_host = match gpu {
                Some(g) => Some(GpuHost::for_scene(g, &scene)?),
                None => None,
            };
            let (depth, surface, shadow_map, gpu_tex) = match (gpu, &gpu_host) {
                (Some(g), Some(gh)) => {
                    let mut last = None;
                    for i in 0..plan.warmup + plan.repeat {
                        let t = gh.render(g, &desc)?;
                        if i >= plan.warmup {
                            host_frames.push(t.passes.clone());
                        }
                        last = Some(t);
                    }
                    let t = last.context("no host frame")?;
                    let depth = g.read_texture_f32(&t.depth, 0)?;
                    let surface = g.read_image(&t.surface)?;
                    let sm = host::read_shadow_maps(g, &t, &desc)?;
                    (depth, surface, sm, Some(t))
                }
                _ => {
                    let mut last = None;
                    for i in 0..plan.warmup + plan.repeat {
                        let hc = host_cpu::render(&scene.geometry, &scene.shading(), &desc);
                        if i >= plan.warmup {
                            host_frames.push(hc.passes.clone());
                        }
                        last = Some(hc);
                    }
                    let hc = last.context("no host frame")?;
                    (hc.depth, hc.surface, hc.shadow_maps, None)
                }
            };
            let (passes, total_ms) = summarise(&host_frames);
            host_records.push(HostRecord { scene: scene.name.clone(), size: [w, h], passes, total_ms });
            let cpu_frame = CpuFrame { desc: &desc, depth: &depth, shadow_maps: &shadow_map, surface: Some(&surface) };
            let transmittance = surface_transmittance(&desc, &depth);
            let tone = ToneMap::new(scene.render.exposure);
            let quality = if plan.reference_steps > 0 {
                progress(&format!("{} {w}×{h}: reference, {} steps per pixel (CPU)", scene.name, plan.reference_steps));
                let rs = ReferenceSettings { steps: plan.reference_steps, seed: 1 };
                let (r, rstats) = reference::render(&cpu_frame, &rs, reference_progress)?;
                let fin = composite(&surface, &r, &transmittance);
                if keep_images {
                    kept.push(Kept {
                        scene: scene.name.clone(),
                        size: [w, h],
                        label: "reference".into(),
                        inscatter: r.clone(),
                        final_radiance: fin.clone(),
                        ms: rstats.total_ms(),
                    });
                }
                Some(Quality { inscatter: r, final_radiance: fin, transmittance: transmittance.clone(), tone })
            } else {
                None
            };
            for v in &plan.variants {
                let choice = parse_technique(&v.technique, &scene, &v.overrides)?;
                progress(&format!("{} {w}×{h}: {} ×{}", scene.name, v.label(), plan.warmup + plan.repeat));
                let mut frames = Vec::new();
                let mut last: Option<(Image, TechniqueStats)> = None;
                match (gpu, &gpu_tex) {
                    (Some(g), Some(t)) => {
                        let Some(mut runner) = render::scattering(g, &choice)? else {
                            bail!("`{}` has no GPU implementation; bench it with --backend cpu", v.technique)
                        };
                        let out = g.create_output_texture(w, h);
                        let out_view = out.create_view(&Default::default());
                        let views = t.views();
                        let frame = views.frame(&desc);
                        let mut stats = None;
                        for i in 0..plan.warmup + plan.repeat {
                            let s = render::render_gpu(&mut runner, gpu_host.as_ref(), &frame, &out_view)?;
                            if i >= plan.warmup {
                                timing = s.timing.clone();
                                frames.push(s.passes.clone());
                            }
                            stats = Some(s);
                        }
                        last = Some((g.read_image(&out)?, stats.context("no frame")?));
                    }
                    _ => {
                        for i in 0..plan.warmup + plan.repeat {
                            let (img, s) = render::render_cpu(&choice, &cpu_frame, Some(&scene.geometry), &|_, _| {})?;
                            if i >= plan.warmup {
                                frames.push(s.passes.clone());
                            }
                            last = Some((img, s));
                        }
                    }
                }
                let (img, stats) = last.context("no frame")?;
                if !img.all_finite() {
                    bail!("{} on {}: non-finite output (a bug)", v.label(), scene.name);
                }
                let (psnr, flip) = match &quality {
                    Some(q) => {
                        let (p, f) = q.measure(&img, &surface)?;
                        (Some(p), Some(f))
                    }
                    None => (None, None),
                };
                let (passes, total_ms) = summarise(&frames);
                if keep_images {
                    kept.push(Kept {
                        scene: scene.name.clone(),
                        size: [w, h],
                        label: v.label(),
                        final_radiance: composite(&surface, &img, &transmittance),
                        inscatter: img.clone(),
                        ms: total_ms[0],
                    });
                }
                records.push(BenchRecord {
                    scene: scene.name.clone(),
                    size: [w, h],
                    technique: v.technique.clone(),
                    series: v.series.clone(),
                    label: v.label(),
                    sweep: v.sweep.clone(),
                    settings: choice,
                    passes,
                    total_ms,
                    raymarched_samples: stats.raymarched_samples,
                    gpu_memory_bytes: stats.gpu_memory_bytes,
                    psnr_db: psnr,
                    flip_mean: flip,
                    extra: stats.extra,
                    flicker: None,
                    temporal: None,
                });
            }
        }
    }
    let adapter = adapter_stats(gpu);
    if gpu.is_some_and(|g| !g.software) && timing == "wall-clock" {
        log::warn!("hardware adapter timed by wall clock");
    }
    let report = BenchReport {
        plan: plan.clone(),
        backend: if gpu.is_some() { "gpu".into() } else { "cpu".into() },
        adapter,
        timing,
        date: utc_date(),
        command: command.into(),
        host: host_records,
        records,
        flicker_frames: 0,
        flicker_size: None,
        temporal_frames: 0,
        temporal: None,
        ghost_frames: 0,
    };
    Ok((report, kept))
}

/// Frames of the flicker measurement when `--flicker-frames` is not given: 3 frame pairs.
pub const DEFAULT_FLICKER_FRAMES: u32 = 4;
/// Widest image the flicker is measured at; a larger smallest bench size is scaled down to it.
pub const FLICKER_MAX_WIDTH: u32 = 320;

/// The size flicker is measured at: the plan's smallest size (by pixels), scaled down to at most
/// [`FLICKER_MAX_WIDTH`] wide (aspect kept); also the size whose rows get the flicker column.
pub fn flicker_sizes(plan: &BenchPlan) -> Option<((u32, u32), (u32, u32))> {
    let &(w, h) = plan.sizes.iter().min_by_key(|(w, h)| *w as u64 * *h as u64)?;
    let m = if w > FLICKER_MAX_WIDTH {
        (FLICKER_MAX_WIDTH, ((h as u64 * FLICKER_MAX_WIDTH as u64 + w as u64 / 2) / w as u64).max(1) as u32)
    } else {
        (w, h)
    };
    Some(((w, h), m))
}

/// Measures flicker (see [`crate::animate::Flicker`]) of every row of the plan's smallest size:
/// per scene, `frames` host frames along the scene's `animate` path, 1/24 of its loop apart
/// (t = 0 is the benched frame), each rendered by `reference` (the plan's reference steps, seed
/// 1) and by every row's configuration, with `frame_index` advanced per frame. Costs `frames`
/// host frames and references per scene plus `frames` frames per row. `frames` = 0 does
/// nothing; 1 is an error, as is a plan without a reference.
pub fn measure_flicker(
    report: &mut BenchReport,
    gpu: Option<&GpuContext>,
    frames: u32,
    progress: &dyn Fn(&str),
    reference_progress: &(dyn Fn(u64, u64) + Sync),
) -> Result<()> {
    if frames == 0 {
        return Ok(());
    }
    check_flicker_frames(frames, report.plan.reference_steps)?;
    let Some((rows_size, size)) = flicker_sizes(&report.plan) else { return Ok(()) };
    for scene_arg in &report.plan.scenes {
        let mut scene = report.plan.load_scene(scene_arg)?;
        (scene.render.width, scene.render.height) = size;
        let mut rows = Vec::new();
        for (i, x) in report.records.iter().enumerate() {
            if x.scene == scene.name && x.size == [rows_size.0, rows_size.1] {
                let v =
                    report.plan.variants.iter().find(|v| v.label() == x.label).context("bench row without variant")?;
                rows.push((i, AnimatedTechnique::new(&v.technique, &scene, &v.overrides)?, FlickerMeter::new()));
            }
        }
        if rows.is_empty() {
            continue;
        }
        let r = [format!("steps={}", report.plan.reference_steps), "seed=1".to_string()];
        let mut reference = AnimatedTechnique::new("reference", &scene, &r)?;
        let path = MotionPath::for_scene(scene_arg, &scene);
        let name = scene.name.clone();
        let mut renderer = PathRenderer::new(scene, path, gpu)?;
        for f in 0..frames {
            progress(&format!(
                "{name} {}×{}: flicker frame {}/{frames} (reference + {} rows)",
                size.0,
                size.1,
                f + 1,
                rows.len()
            ));
            let mut frame = renderer.frame(frame_time(f, frames, false))?;
            let (ri, _) = reference.render(gpu, &mut frame, 0, reference_progress)?;
            for (_, t, meter) in &mut rows {
                let (img, _) = t.render(gpu, &mut frame, f, &|_, _| {})?;
                meter.push(&img, &ri)?;
            }
        }
        for (i, _, meter) in rows {
            report.records[i].flicker = Some(meter.finish()?);
        }
    }
    report.flicker_frames = frames;
    report.flicker_size = Some([size.0, size.1]);
    Ok(())
}

/// Frames of the temporal column when `--temporal-frames` is not given: the issue's "after 8
/// frames of a slow camera move" (8 frames of history, then the measured one).
pub const DEFAULT_TEMPORAL_FRAMES: u32 = 9;
/// Frames after the temporal column's light jump when `--ghost-frames` is not given: the
/// jump frame and 9 more, so that the steady state [`recovery_frames`] compares with (the
/// mean of the last 4) lies 6–9 frames after the jump, past the stage's young frames.
pub const DEFAULT_GHOST_FRAMES: u32 = 10;

/// The slow move of the temporal column: frame i is at 1/`TEMPORAL_LOOP` × i of the scene's
/// `animate` loop (as `animate --frames 96 --stop-after 9 --still-lights`).
pub const TEMPORAL_LOOP: u32 = 96;

/// Measures the temporal column ([`TemporalColumn`]) of every row of the plan's smallest size
/// (at [`flicker_sizes`]' size): per scene, `frames` host frames along the scene's `animate`
/// path with the lights still, 1/[`TEMPORAL_LOOP`] of the loop apart, each rendered by
/// `reference` (the plan's reference steps, seed 1), by every row as configured and by every
/// row with jitter and the temporal stage `settings`; then, when `ghost_frames` > 0, that many
/// more frames with every light turned by [`LIGHT_JUMP_DEGREES`] (the ghosting measure,
/// [`LightJumpColumn`]; the flicker and the last frame's figures are the slow move's alone).
/// Costs per scene `frames` + `ghost_frames` host frames and references, per row twice that
/// many frames (once where jitter adds nothing) and as many stage passes. `frames` = 0 does
/// nothing.
pub fn measure_temporal(
    report: &mut BenchReport,
    gpu: Option<&GpuContext>,
    frames: u32,
    ghost_frames: u32,
    settings: TemporalSettings,
    progress: &dyn Fn(&str),
    reference_progress: &(dyn Fn(u64, u64) + Sync),
) -> Result<()> {
    if frames == 0 {
        return Ok(());
    }
    check_temporal_frames(frames, report.plan.reference_steps)?;
    check_ghost_frames(ghost_frames)?;
    settings.validate().map_err(|e| anyhow::anyhow!("--temporal-set: {e}"))?;
    let Some((rows_size, size)) = flicker_sizes(&report.plan) else { return Ok(()) };
    struct Row {
        record: usize,
        plain: AnimatedTechnique,
        /// The row with `jitter=true`; None where that adds nothing (no such setting, or the
        /// row sets it): the stage is then fed the row's own frames, rendered once.
        jittered: Option<AnimatedTechnique>,
        stage: Stage,
        jitter_added: bool,
        meters: [FlickerMeter; 2],
        last: Option<[(f64, f64); 2]>,
        stage_ms: Vec<f64>,
        /// PSNR per frame from the light jump on: as configured, jitter + stage.
        jumped: [Vec<f64>; 2],
    }
    for scene_arg in &report.plan.scenes {
        let mut scene = report.plan.load_scene(scene_arg)?;
        (scene.render.width, scene.render.height) = size;
        let mut rows = Vec::new();
        for (i, x) in report.records.iter().enumerate() {
            if x.scene == scene.name && x.size == [rows_size.0, rows_size.1] {
                let v =
                    report.plan.variants.iter().find(|v| v.label() == x.label).context("bench row without variant")?;
                let (jo, jitter_added) = with_jitter(&v.technique, &scene, &v.overrides)?;
                rows.push(Row {
                    record: i,
                    plain: AnimatedTechnique::new(&v.technique, &scene, &v.overrides)?,
                    jittered: if jitter_added {
                        Some(AnimatedTechnique::new(&v.technique, &scene, &jo)?)
                    } else {
                        None
                    },
                    stage: Stage::new(settings, gpu, &v.technique)?,
                    jitter_added,
                    meters: [FlickerMeter::new(), FlickerMeter::new()],
                    last: None,
                    stage_ms: Vec::new(),
                    jumped: [Vec::new(), Vec::new()],
                });
            }
        }
        if rows.is_empty() {
            continue;
        }
        let r = [format!("steps={}", report.plan.reference_steps), "seed=1".to_string()];
        let mut reference = AnimatedTechnique::new("reference", &scene, &r)?;
        let path = MotionPath::for_scene(scene_arg, &scene).still_lights();
        let name = scene.name.clone();
        let tone = ToneMap::new(scene.render.exposure);
        let mut renderer = PathRenderer::new(scene, path, gpu)?;
        // The stage reads the frame's motion vectors, as it would an engine's (as `animate`).
        renderer.motion_vectors = true;
        let total = frames + ghost_frames;
        for f in 0..total {
            progress(&format!(
                "{name} {}×{}: temporal frame {}/{total}{} (reference + {} rows with and without the stage)",
                size.0,
                size.1,
                f + 1,
                if f >= frames { ", after the light jump" } else { "" },
                rows.len()
            ));
            if f == frames {
                renderer.light_turn_degrees = LIGHT_JUMP_DEGREES;
            }
            let mut frame = renderer.frame(frame_time(f, TEMPORAL_LOOP, true))?;
            let (ri, _) = reference.render(gpu, &mut frame, 0, reference_progress)?;
            let q = Quality {
                final_radiance: frame.final_radiance(&ri),
                inscatter: ri,
                transmittance: frame.transmittance.clone(),
                tone,
            };
            for row in &mut rows {
                // The row as configured: its frame_index advanced only if it jitters already.
                let (plain, _) = row.plain.render(gpu, &mut frame, f, &|_, _| {})?;
                let jittered = match &mut row.jittered {
                    Some(j) => Some((j.render(gpu, &mut frame, f, &|_, _| {})?.0, j.gpu_output())),
                    None => None,
                };
                let (raw, fed) = match &jittered {
                    Some((img, out)) => (img, *out),
                    None => (&plain, row.plain.gpu_output()),
                };
                let start = std::time::Instant::now();
                let (out, _) = row.stage.resolve(gpu, &frame, fed, raw)?;
                row.stage_ms.push(start.elapsed().as_secs_f64() * 1e3);
                if f < frames {
                    row.meters[0].push(&plain, &q.inscatter)?;
                    row.meters[1].push(&out, &q.inscatter)?;
                }
                if f + 1 == frames {
                    row.last = Some([q.measure(&plain, &frame.surface)?, q.measure(&out, &frame.surface)?]);
                }
                if f >= frames {
                    row.jumped[0].push(q.measure(&plain, &frame.surface)?.0);
                    row.jumped[1].push(q.measure(&out, &frame.surface)?.0);
                }
            }
        }
        for row in rows {
            let [m0, m1] = row.meters;
            let [(psnr_db_without, flip_without), (psnr_db, flip)] = row.last.context("no temporal frame")?;
            report.records[row.record].temporal = Some(TemporalColumn {
                psnr_db_without,
                flip_without,
                psnr_db,
                flip,
                flicker_without: m0.finish()?,
                flicker: m1.finish()?,
                jitter_added: row.jitter_added,
                stage_ms: median_min_max(&row.stage_ms)[0],
                light_jump: (ghost_frames > 0).then(|| {
                    let [without, with] = row.jumped;
                    LightJumpColumn {
                        jump_frame: frames,
                        recovery_frames_without: recovery_frames(&without, 0),
                        recovery_frames: recovery_frames(&with, 0),
                        psnr_db_without: without,
                        psnr_db: with,
                    }
                }),
            });
        }
    }
    report.temporal_frames = frames;
    report.ghost_frames = ghost_frames;
    report.temporal = Some(settings);
    report.flicker_size = Some([size.0, size.1]);
    Ok(())
}

/// Checks `--temporal-frames` against the plan before any work.
pub fn check_temporal_frames(frames: u32, reference_steps: u32) -> Result<()> {
    check_measured_frames("--temporal-frames", "temporal column", frames, reference_steps)
}

/// Checks `--ghost-frames` before any work: 0 (no light jump) or 8..=1000 (the steady state a
/// recovery is measured against is the mean of the last 4 frames, at least 8 after the jump).
pub fn check_ghost_frames(frames: u32) -> Result<()> {
    if frames != 0 && !(8..=1000).contains(&frames) {
        bail!("--ghost-frames {frames}: must be 0 (no light jump) or in 8..=1000");
    }
    Ok(())
}

/// Checks `--flicker-frames` against the plan before any work.
pub fn check_flicker_frames(frames: u32, reference_steps: u32) -> Result<()> {
    check_measured_frames("--flicker-frames", "flicker", frames, reference_steps)
}

/// A frame count of a measurement along the path against the reference (`what`, set by
/// `option`): 0 (off) or 2..=1000, and only with a reference.
fn check_measured_frames(option: &str, what: &str, frames: u32, reference_steps: u32) -> Result<()> {
    if frames == 1 || frames > 1000 {
        bail!("{option} {frames}: must be 0 (no {what}) or in 2..=1000");
    }
    if frames > 0 && reference_steps == 0 {
        bail!("{option} {frames}: {what} is measured against the reference; it needs --reference-steps > 0");
    }
    Ok(())
}

pub(super) fn load_name_matches(arg: &str, scene_name: &str) -> bool {
    arg == scene_name || Path::new(arg).file_stem().is_some_and(|s| s == scene_name)
}
