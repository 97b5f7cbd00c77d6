//! `crepuscular bench`: the matrix scene × size × technique × setting, timed per pass over
//! repeated frames after warm-up frames, with ray-marched samples, GPU memory and quality vs
//! `reference`; written as `bench.json`, `bench.md` and SVG plots. Named presets reproduce the
//! papers' own experiments.
//!
//! Timing: every pass of every frame is measured by the technique's `PassTimer` (GPU timestamp
//! queries on hardware adapters; a synchronised wall clock on software adapters and the CPU).
//! Warm-up frames (pipeline compilation, first-use allocation) are excluded; the report gives
//! the median and the min–max spread over the timed frames. Timings are only comparable within
//! one run on one device: the device is recorded in every output.

use crate::metrics::compare;
use crate::render::{AdapterStats, TechniqueChoice, adapter_stats, frame_desc, load_scene};
use anyhow::{Context, Result, bail};
use crepuscular::frame::surface_transmittance;
use crepuscular::gpu::GpuContext;
use crepuscular::stats::TechniqueStats;
use crepuscular::techniques::reference::{self, ReferenceSettings};
use crepuscular::tonemap::{ToneMap, composite};
use crepuscular::{CpuFrame, GpuFrame, Image};
use crepuscular_scene::{GpuHost, host, host_cpu};
use serde::Serialize;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

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
}

/// The steps swept by default for each ray-marching technique.
pub const DEFAULT_STEP_SWEEP: [u32; 4] = [16, 32, 64, 128];

/// The default plan: every built-in scene, each given technique swept over its main setting.
pub fn default_plan(scenes: Vec<String>, techniques: &[String]) -> Result<BenchPlan> {
    let mut variants = Vec::new();
    for t in techniques {
        match t.as_str() {
            "brute-force" | "interleaved" | "subsampled" => {
                for n in DEFAULT_STEP_SWEEP {
                    let o = format!("steps={n}");
                    variants.push(Variant::new(t, &[&o], t, Some(("steps", n as f64))));
                }
            }
            "reference" => bail!("`reference` is the quality yardstick of every bench row; it is not benchmarked"),
            other => {
                if crepuscular::techniques::find(other).is_none() {
                    bail!("unknown technique `{other}`");
                }
                variants.push(Variant::new(other, &[], other, None));
            }
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
    })
}

/// The named presets: (name, one line).
pub const PRESETS: &[(&str, &str)] = &[
    (
        "toth-interleaving",
        "Tóth & Umenhoffer 2009 §5: no scattering vs scattering without interleaving vs 4×4 interleaving, equal N, 1920×1080, point light",
    ),
    (
        "wyman-steps",
        "Wyman & Ramsey 2008 App. B: the four spot-step policies at equal N (16, 32, 64 steps), spot light",
    ),
];

/// A named preset.
pub fn preset(name: &str) -> Result<BenchPlan> {
    let plan = match name {
        "toth-interleaving" => BenchPlan {
            name: name.into(),
            description: "Tóth & Umenhoffer 2009, §5: the frame without scattering (host passes only), with \
                          per-pixel ray marching of N = 64 steps (brute-force), and with 4×4 interleaved \
                          sampling of the same N (each pixel marches 4 steps, the block sums them). The \
                          paper's point-light scene is `cage`. brute-force at 4 steps is added: the same \
                          per-pixel cost as interleaving without the sum."
                .into(),
            scenes: vec!["cage".into()],
            sizes: vec![(1920, 1080)],
            variants: vec![
                Variant::new("brute-force", &["steps=64"], "no interleaving (brute-force, N = 64)", None),
                Variant::new("interleaved", &["block=4", "steps=64"], "4×4 interleaving (N = 64)", None),
                Variant::new("brute-force", &["steps=4"], "brute-force, N = 4", None),
            ],
            repeat: 3,
            warmup: 1,
            reference_steps: 256,
        },
        "wyman-steps" => {
            let mut variants = Vec::new();
            for policy in crepuscular::march::SpotSteps::ALL {
                for n in [16u32, 32, 64] {
                    let (o1, o2) = (format!("steps={n}"), format!("spot_steps=\"{}\"", policy.name()));
                    variants.push(Variant::new(
                        "brute-force",
                        &[&o1, &o2],
                        &format!("spot_steps = {}", policy.name()),
                        Some(("steps", n as f64)),
                    ));
                }
            }
            BenchPlan {
                name: name.into(),
                description: "Wyman & Ramsey 2008, Appendix B: brute-force with each spot-step policy at equal \
                              N on the spot-light scene `stained-glass`. `fixed` marches eye → surface; \
                              `exact-cone` the ray's chord inside the cone; the two App. B policies march \
                              Δ = d·sinφ / den from the cone entry, with a constant or a smoothstep-clamped \
                              denominator."
                    .into(),
                scenes: vec!["stained-glass".into()],
                sizes: vec![(960, 540)],
                variants,
                repeat: 3,
                warmup: 1,
                reference_steps: 512,
            }
        }
        other => {
            let names: Vec<_> = PRESETS.iter().map(|p| p.0).collect();
            bail!("unknown preset `{other}` (known: {})", names.join(", "))
        }
    };
    Ok(plan)
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
    pub settings: TechniqueChoice,
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

/// The reference in-scattering and final image of a frame, for quality.
struct Quality {
    inscatter: Image,
    final_radiance: Image,
    transmittance: Vec<[f32; 3]>,
    tone: ToneMap,
}

impl Quality {
    fn measure(&self, inscatter: &Image, surface: &Image) -> Result<(f64, f64)> {
        let lin = compare(&self.inscatter, inscatter, &self.tone)?;
        let fin = compare(&self.final_radiance, &composite(surface, inscatter, &self.transmittance), &self.tone)?;
        Ok((lin.psnr_db, fin.flip_mean))
    }
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
            let mut scene = load_scene(scene_name)?;
            scene.render.width = w;
            scene.render.height = h;
            let desc = frame_desc(&scene);
            if let Some(g) = gpu {
                g.check_texture_size("image size", w, h)?;
            }
            let spot = match &scene.light {
                crepuscular::Light::Spot { texture, .. } => texture.as_deref(),
                _ => None,
            };
            progress(&format!("{} {w}×{h}: host frame ×{}", scene.name, plan.warmup + plan.repeat));
            // The host frame (no scattering), timed like a technique; its outputs feed every row.
            let mut host_frames = Vec::new();
            let (depth, surface, shadow_map, gpu_tex) = match gpu {
                Some(g) => {
                    let gh = GpuHost::new(g, &scene.geometry)?;
                    let mut last = None;
                    for i in 0..plan.warmup + plan.repeat {
                        let t = gh.render(g, &desc, spot)?;
                        if i >= plan.warmup {
                            host_frames.push(t.passes.clone());
                        }
                        last = Some(t);
                    }
                    let t = last.context("no host frame")?;
                    let depth = g.read_texture_f32(&t.depth, 0)?;
                    let surface = g.read_image(&t.surface)?;
                    let sm = host::read_shadow_map(g, &t, &desc)?;
                    (depth, surface, sm, Some(t))
                }
                None => {
                    let mut last = None;
                    for i in 0..plan.warmup + plan.repeat {
                        let hc = host_cpu::render(&scene.geometry, &desc);
                        if i >= plan.warmup {
                            host_frames.push(hc.passes.clone());
                        }
                        last = Some(hc);
                    }
                    let hc = last.context("no host frame")?;
                    (hc.depth, hc.surface, hc.shadow_map, None)
                }
            };
            let (passes, total_ms) = summarise(&host_frames);
            host_records.push(HostRecord { scene: scene.name.clone(), size: [w, h], passes, total_ms });
            let cpu_frame = CpuFrame { desc: &desc, depth: &depth, shadow_map: &shadow_map, surface: Some(&surface) };
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
                let choice = TechniqueChoice::parse(&v.technique, &scene, &v.overrides)?;
                progress(&format!("{} {w}×{h}: {} ×{}", scene.name, v.label(), plan.warmup + plan.repeat));
                let mut frames = Vec::new();
                let mut last: Option<(Image, TechniqueStats)> = None;
                match (gpu, &gpu_tex) {
                    (Some(g), Some(t)) => {
                        let Some(mut runner) = choice.gpu_runner(g)? else {
                            bail!("`{}` has no GPU implementation; bench it with --backend cpu", v.technique)
                        };
                        let out = g.create_output_texture(w, h);
                        let out_view = out.create_view(&Default::default());
                        let (dv, sv) = (t.depth_view(), t.shadow_view());
                        let spot_view = t.spot_texture.create_view(&Default::default());
                        let frame = GpuFrame {
                            desc: &desc,
                            depth: &dv,
                            shadow_map: &sv,
                            spot_texture: spot.map(|_| &spot_view),
                        };
                        let mut stats = None;
                        for i in 0..plan.warmup + plan.repeat {
                            let s = runner.render(g, &frame, &out_view)?;
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
                            let (img, s) = choice.run_cpu(&cpu_frame, &|_, _| {})?;
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
    };
    Ok((report, kept))
}

fn fmt_opt(v: Option<f64>, digits: usize) -> String {
    match v {
        Some(x) if x.is_finite() => format!("{x:.digits$}"),
        Some(x) => format!("{x}"),
        None => "–".into(),
    }
}

fn device_line(r: &BenchReport) -> String {
    format!(
        "{} ({}, {}, {}{}), timing by {}",
        r.adapter.name,
        r.adapter.backend,
        r.adapter.device_type,
        r.adapter.driver.trim(),
        if r.adapter.software { ", software" } else { "" },
        r.timing
    )
}

/// `bench.md`: the tables, with device, date and command.
pub fn markdown(r: &BenchReport) -> String {
    let mut s = String::new();
    s += &format!("# bench: {}\n\n{}\n\n", r.plan.name, r.plan.description);
    s += &format!("- device: {}\n- date: {}\n- command: `{}`\n", device_line(r), r.date, r.command);
    s += &format!(
        "- {} timed frames after {} warm-up frames; times are median (min–max) in ms\n",
        r.plan.repeat, r.plan.warmup
    );
    if r.plan.reference_steps > 0 {
        s += &format!(
            "- quality vs `reference` ({} steps): PSNR of the linear in-scattering (dB), FLIP mean of the tone-mapped final image\n",
            r.plan.reference_steps
        );
    }
    s += "\n## Frame without scattering (host passes)\n\n| scene | size | total ms | passes |\n|---|---|---|---|\n";
    for h in &r.host {
        s += &format!(
            "| {} | {}×{} | {:.2} ({:.2}–{:.2}) | {} |\n",
            h.scene,
            h.size[0],
            h.size[1],
            h.total_ms[0],
            h.total_ms[1],
            h.total_ms[2],
            h.passes.iter().map(|p| format!("{} {:.2}", p.name, p.median_ms)).collect::<Vec<_>>().join(", ")
        );
    }
    s += "\n## Techniques\n\n| scene | size | configuration | technique ms | frame ms (host + technique) | passes (median ms) | ray-marched samples | GPU memory | PSNR dB | FLIP |\n|---|---|---|---|---|---|---|---|---|---|\n";
    for x in &r.records {
        let host = r.host.iter().find(|h| h.scene == x.scene && h.size == x.size).map(|h| h.total_ms[0]).unwrap_or(0.0);
        s += &format!(
            "| {} | {}×{} | {} | {:.2} ({:.2}–{:.2}) | {:.2} | {} | {} | {:.1} KiB | {} | {} |\n",
            x.scene,
            x.size[0],
            x.size[1],
            x.label,
            x.total_ms[0],
            x.total_ms[1],
            x.total_ms[2],
            host + x.total_ms[0],
            x.passes.iter().map(|p| format!("{} {:.2}", p.name, p.median_ms)).collect::<Vec<_>>().join(", "),
            x.raymarched_samples,
            x.gpu_memory_bytes as f64 / 1024.0,
            fmt_opt(x.psnr_db, 2),
            fmt_opt(x.flip_mean, 4),
        );
    }
    s
}

const COLORS: [plotters::style::RGBColor; 8] = [
    plotters::style::RGBColor(31, 119, 180),
    plotters::style::RGBColor(255, 127, 14),
    plotters::style::RGBColor(44, 160, 44),
    plotters::style::RGBColor(214, 39, 40),
    plotters::style::RGBColor(148, 103, 189),
    plotters::style::RGBColor(140, 86, 75),
    plotters::style::RGBColor(227, 119, 194),
    plotters::style::RGBColor(127, 127, 127),
];

type Curves = Vec<(String, Vec<(f64, f64)>)>;

fn line_plot(path: &Path, title: &str, x_desc: &str, y_desc: &str, log_x: bool, curves: &Curves) -> Result<()> {
    use plotters::prelude::*;
    let pts: Vec<(f64, f64)> =
        curves.iter().flat_map(|c| c.1.iter().copied()).filter(|p| p.0.is_finite() && p.1.is_finite()).collect();
    if pts.is_empty() {
        return Ok(());
    }
    let (mut x0, mut x1) = pts.iter().fold((f64::MAX, f64::MIN), |a, p| (a.0.min(p.0), a.1.max(p.0)));
    let (mut y0, mut y1) = pts.iter().fold((f64::MAX, f64::MIN), |a, p| (a.0.min(p.1), a.1.max(p.1)));
    if log_x {
        x0 = (x0 * 0.8).max(1e-6);
        x1 = (x1 * 1.25).max(x0 * 10.0);
    } else {
        let pad = ((x1 - x0) * 0.05).max(1e-3);
        (x0, x1) = (x0 - pad, x1 + pad);
    }
    let pad = ((y1 - y0) * 0.08).max(1e-3);
    (y0, y1) = (y0 - pad, y1 + pad);
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (900, 560)).into_drawing_area();
        root.fill(&WHITE).map_err(|e| anyhow::anyhow!("{e:?}"))?;
        let mut b = ChartBuilder::on(&root);
        b.caption(title, ("sans-serif", 16)).margin(12).x_label_area_size(44).y_label_area_size(64);
        macro_rules! draw {
            ($chart:expr) => {{
                let mut chart = $chart;
                chart.configure_mesh().x_desc(x_desc).y_desc(y_desc).draw().map_err(|e| anyhow::anyhow!("{e:?}"))?;
                for (i, (name, c)) in curves.iter().enumerate() {
                    let col = COLORS[i % COLORS.len()];
                    let mut c = c.clone();
                    c.sort_by(|a, b| a.0.total_cmp(&b.0));
                    chart
                        .draw_series(LineSeries::new(c.clone(), col.stroke_width(2)))
                        .map_err(|e| anyhow::anyhow!("{e:?}"))?
                        .label(name.as_str())
                        .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 18, y)], col.stroke_width(2)));
                    chart
                        .draw_series(c.iter().map(|&p| Circle::new(p, 3, col.filled())))
                        .map_err(|e| anyhow::anyhow!("{e:?}"))?;
                }
                chart
                    .configure_series_labels()
                    .background_style(WHITE.mix(0.9))
                    .border_style(BLACK)
                    .draw()
                    .map_err(|e| anyhow::anyhow!("{e:?}"))?;
            }};
        }
        if log_x {
            draw!(b.build_cartesian_2d((x0..x1).log_scale(), y0..y1).map_err(|e| anyhow::anyhow!("{e:?}"))?);
        } else {
            draw!(b.build_cartesian_2d(x0..x1, y0..y1).map_err(|e| anyhow::anyhow!("{e:?}"))?);
        }
        root.present().map_err(|e| anyhow::anyhow!("{e:?}"))?;
    }
    crate::output::write_atomic(path, svg.as_bytes())
}

/// Writes bench.json, bench.md and the plots into `dir`; returns the paths written.
pub fn write(r: &BenchReport, dir: &Path) -> Result<Vec<PathBuf>> {
    std::fs::create_dir_all(dir).with_context(|| format!("{}: cannot create the output directory", dir.display()))?;
    let mut written = Vec::new();
    let p = dir.join("bench.json");
    crate::output::write_json(&p, r)?;
    written.push(p);
    let p = dir.join("bench.md");
    crate::output::write_atomic(&p, markdown(r).as_bytes())?;
    written.push(p);
    let dev = format!("{} · {}", r.adapter.name, r.date);
    // Time vs quality: one plot per scene and size, each series a curve over its swept setting.
    if r.plan.reference_steps > 0 {
        for scene in &r.plan.scenes {
            for &(w, h) in &r.plan.sizes {
                let mut curves: Curves = Vec::new();
                for x in r.records.iter().filter(|x| &x.scene == scene && x.size == [w, h]) {
                    let Some(q) = x.psnr_db else { continue };
                    let pt = (x.total_ms[0].max(1e-4), q);
                    match curves.iter_mut().find(|c| c.0 == x.series) {
                        Some(c) => c.1.push(pt),
                        None => curves.push((x.series.clone(), vec![pt])),
                    }
                }
                let name: String =
                    scene.chars().map(|c| if c.is_ascii_alphanumeric() || c == '-' { c } else { '_' }).collect();
                let p = dir.join(format!("time_vs_quality_{name}_{w}x{h}.svg"));
                line_plot(
                    &p,
                    &format!("time vs quality — {name} {w}×{h} — {dev}"),
                    "technique time per frame, ms (median)",
                    "PSNR vs reference, dB",
                    true,
                    &curves,
                )?;
                written.push(p);
            }
        }
    }
    // Time per scene: scene independence, one curve per configuration.
    if r.plan.scenes.len() > 1 {
        let size = r.plan.sizes[0];
        let mut curves: Curves = Vec::new();
        for x in r.records.iter().filter(|x| x.size == [size.0, size.1]) {
            let i = r.plan.scenes.iter().position(|s| load_name_matches(s, &x.scene)).unwrap_or(0) as f64;
            match curves.iter_mut().find(|c| c.0 == x.label) {
                Some(c) => c.1.push((i, x.total_ms[0])),
                None => curves.push((x.label.clone(), vec![(i, x.total_ms[0])])),
            }
        }
        let p = dir.join("time_per_scene.svg");
        line_plot(
            &p,
            &format!("time per scene ({}) — {}×{} — {dev}", r.plan.scenes.join(", "), size.0, size.1),
            "scene (index in the list above)",
            "technique time per frame, ms (median)",
            false,
            &curves,
        )?;
        written.push(p);
    }
    // Time vs resolution.
    if r.plan.sizes.len() > 1 {
        let mut curves: Curves = Vec::new();
        for x in r.records.iter().filter(|x| x.scene == r.records[0].scene) {
            let mp = x.size[0] as f64 * x.size[1] as f64 / 1e6;
            match curves.iter_mut().find(|c| c.0 == x.label) {
                Some(c) => c.1.push((mp, x.total_ms[0])),
                None => curves.push((x.label.clone(), vec![(mp, x.total_ms[0])])),
            }
        }
        let p = dir.join("time_vs_resolution.svg");
        line_plot(
            &p,
            &format!("time vs resolution — {} — {dev}", r.records.first().map(|x| x.scene.as_str()).unwrap_or("")),
            "megapixels",
            "technique time per frame, ms (median)",
            false,
            &curves,
        )?;
        written.push(p);
    }
    Ok(written)
}

fn load_name_matches(arg: &str, scene_name: &str) -> bool {
    arg == scene_name || Path::new(arg).file_stem().is_some_and(|s| s == scene_name)
}
