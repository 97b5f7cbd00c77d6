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

use crate::animate::{AnimatedTechnique, Flicker, FlickerMeter, MotionPath, PathRenderer, frame_time};
use crate::metrics::Quality;
use crate::render::{self, AdapterStats, adapter_stats, frame_desc, load_scene, parse_technique};
use anyhow::{Context, Result, bail};
use crepuscular::TechniqueSettings;
use crepuscular::frame::surface_transmittance;
use crepuscular::gpu::GpuContext;
use crepuscular::stats::TechniqueStats;
use crepuscular::techniques::reference::{self, ReferenceSettings};
use crepuscular::tonemap::{ToneMap, composite};
use crepuscular::{CpuFrame, Image};
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
            "brute-force" | "interleaved" | "subsampled" | "epipolar" => {
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
        "engelhardt-fig9",
        "Engelhardt & Dachsbacher 2010 Fig. 9: naïve subsampling at 256×256 vs epipolar sampling with 1024 lines and 8 initial samples, 150 steps, 1920×1080, textured spot light",
    ),
    (
        "engelhardt-fig10",
        "Engelhardt & Dachsbacher 2010 Fig. 10: 256 / 512 / 1024 epipolar lines → ray-marched samples and error, with brute-force at the same 150 steps, 1920×1080",
    ),
    (
        "engelhardt-timings",
        "Engelhardt & Dachsbacher 2010 §6: epipolar per-pass breakdown (lines, discontinuity search, ray marching, interpolation, upsampling) at 1920×1080, 1024 lines, 32 initial samples, 500 steps",
    ),
    (
        "wyman-steps",
        "Wyman & Ramsey 2008 App. B: the four spot-step policies at equal N (16, 32, 64 steps), spot light",
    ),
    (
        "klehm-table1",
        "Klehm, Seidel & Eisemann 2014 Table 1: prefiltered's regions per slice (1–4) × bases per thread (4, 8, 16; 32 = naive) → prefix-sum and scattering time, M = 32, map 1024×1024, 1920×1080",
    ),
    (
        "klehm-table2",
        "Klehm, Seidel & Eisemann 2014 Table 2: prefiltered's shadow-map size (512–4096 × 1024, 1024 × 512–1536) and bases M (16–128) → prefix-sum and scattering time and memory, 1920×1080",
    ),
    (
        "lights",
        "many lights: every GPU technique at 0, 1, 2, 4 and 8 lights of night-street (lamps first) → time per light added and PSNR vs reference, 480×270",
    ),
    (
        "klehm-fig5",
        "Klehm, Seidel & Eisemann 2014 §5 / Fig. 5: prefiltered, minmax (Chen et al. 2011), epipolar and brute-force on forest and terrain at 1920×1080, each at its quality-optimal settings and swept down to equal time; nodes visited per ray",
    ),
    (
        "klehm-scenes",
        "Klehm, Seidel & Eisemann 2014 §5: scene independence and speed — prefiltered (defaults) on every built-in scene against brute-force at 256 steps, 1920×1080",
    ),
];

/// The scene of the `lights` preset and the light counts it sweeps.
const LIGHTS_SCENE: &str = "night-street";
const LIGHT_COUNTS: [usize; 5] = [0, 1, 2, 4, 8];

/// The light count of a `NAME:lights=N` scene name.
fn light_count(scene: &str) -> Option<usize> {
    scene.rsplit_once(":lights=").and_then(|(_, n)| n.parse().ok())
}

/// `lights`: per technique, the time at each light count, the first light's cost t1 − t0, each
/// added light's (tN − t1)/(N − 1), their ratio, and PSNR vs reference at each N.
fn lights_table(r: &BenchReport) -> String {
    let mut s = String::from(
        "\n## Lights table\n\nms per frame (median); first = t1 − t0 (t0: no light reaches the effect); added = \
         (tN − t1)/(N − 1), the cost of each light after the first; ratio = added / first (goal for the \
         march-based techniques: ≤ 0.5); PSNR vs reference (dB) in brackets.\n\n\
         | technique | t0 | t1 | t2 | t4 | t8 | first | added (2) | added (4) | added (8) | ratio (8) |\n\
         |---|---|---|---|---|---|---|---|---|---|---|\n",
    );
    let mut techniques: Vec<&str> = Vec::new();
    for x in &r.records {
        if !techniques.contains(&x.technique.as_str()) {
            techniques.push(&x.technique);
        }
    }
    for t in techniques {
        let at = |n: usize| r.records.iter().find(|x| x.technique == t && light_count(&x.scene) == Some(n));
        let time = |n: usize| at(n).map(|x| x.total_ms[0]);
        let cell =
            |n: usize| at(n).map_or("–".into(), |x| format!("{:.1} ({})", x.total_ms[0], fmt_opt(x.psnr_db, 1)));
        let first = time(1).zip(time(0)).map(|(a, b)| a - b);
        let added = |n: usize| time(n).zip(time(1)).map(|(a, b)| (a - b) / (n - 1) as f64);
        let f = |v: Option<f64>| v.map_or("–".into(), |v| format!("{v:.1}"));
        let ratio = added(8).zip(first).map(|(a, b)| if b > 0.0 { a / b } else { f64::NAN });
        s += &format!(
            "| {t} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} |\n",
            cell(0),
            cell(1),
            cell(2),
            cell(4),
            cell(8),
            f(first),
            f(added(2)),
            f(added(4)),
            f(added(8)),
            ratio.map_or("–".into(), |v| format!("{v:.2}")),
        );
    }
    s
}

/// The scene of the Klehm et al. 2014 presets: their San Miguel is a sun through a tree's
/// leaves (a complex shadow map), which `forest` is.
const KLEHM_SCENE: &str = "forest";

/// Table 1 of Klehm et al. 2014: (regions per slice, bases per thread), in the paper's row
/// order, with the naive parallelisation (one region, one thread per slice for all 32 bases,
/// the reference of the paper's last column) added after the one-region rows.
pub const KLEHM_TABLE1: &[(u32, u32)] =
    &[(1, 4), (1, 8), (1, 16), (1, 32), (2, 4), (2, 8), (2, 16), (3, 4), (3, 8), (3, 16), (4, 4), (4, 8), (4, 16)];

/// Table 2 of Klehm et al. 2014: (map columns, map rows, bases M), in the paper's row order.
pub const KLEHM_TABLE2: &[(u32, u32, u32)] = &[
    (512, 1024, 32),
    (1024, 1024, 32),
    (2048, 1024, 32),
    (4096, 1024, 32),
    (1024, 512, 32),
    (1024, 768, 32),
    (1024, 1536, 32),
    (1024, 1024, 16),
    (1024, 1024, 64),
    (1024, 1024, 128),
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
        "engelhardt-fig9" => BenchPlan {
            name: name.into(),
            description: "Engelhardt & Dachsbacher 2010, Fig. 9: naïve subsampling and ray marching (150 steps) \
                          with 256×256 samples against epipolar sampling with 1024 lines and 8 initial \
                          samples per line at the same 150 steps, at 1920×1080 on the textured spot light \
                          (`stained-glass`). The paper found them at comparable speed (40 vs 46 fps) with \
                          epipolar much crisper, ray-marching about 17 000 samples. brute-force at 150 \
                          steps is the per-pixel baseline."
                .into(),
            scenes: vec!["stained-glass".into()],
            sizes: vec![(1920, 1080)],
            variants: vec![
                Variant::new("subsampled", &["grid=[256, 256]", "steps=150"], "naïve subsampling 256×256", None),
                Variant::new(
                    "epipolar",
                    &["slices=1024", "initial_samples=8", "steps=150"],
                    "epipolar, 1024 lines, 8 initial samples",
                    None,
                ),
                Variant::new("brute-force", &["steps=150"], "brute-force", None),
            ],
            repeat: 3,
            warmup: 1,
            reference_steps: 256,
        },
        "engelhardt-fig10" => {
            let mut variants: Vec<Variant> = [256u32, 512, 1024]
                .into_iter()
                .map(|n| {
                    let o = format!("slices={n}");
                    Variant::new("epipolar", &[&o, "steps=150"], "epipolar, 150 steps", Some(("slices", n as f64)))
                })
                .collect();
            variants.push(Variant::new("brute-force", &["steps=150"], "brute-force, 150 steps", None));
            BenchPlan {
                name: name.into(),
                description: "Engelhardt & Dachsbacher 2010, Fig. 10: the number of epipolar lines (256, 512, \
                              1024) against ray-marched samples and error at 150 steps, with per-pixel ray \
                              marching at the same steps for reference (the paper: fewer lines are blurrier; \
                              200k / 273k / 443k samples). Scene: `colonnade`, sun shafts."
                    .into(),
                scenes: vec!["colonnade".into()],
                sizes: vec![(1920, 1080)],
                variants,
                repeat: 3,
                warmup: 1,
                reference_steps: 256,
            }
        }
        "engelhardt-timings" => BenchPlan {
            name: name.into(),
            description: "Engelhardt & Dachsbacher 2010, §6: the per-pass breakdown of epipolar sampling at \
                          1920×1080 with 1024 lines, 32 initial samples and 500 steps per ray (paper, HD4850: \
                          lines 1.2 ms, discontinuity search 6.0 ms, ray marching 16.7 ms, interpolation \
                          4.4 ms; 5.8 % of the pixels ray-marched). Our passes: lines, refine (discontinuity \
                          search + compaction), march, interpolate, upsample."
                .into(),
            scenes: vec!["colonnade".into(), "stained-glass".into()],
            sizes: vec![(1920, 1080)],
            variants: vec![Variant::new(
                "epipolar",
                &["slices=1024", "initial_samples=32", "steps=500"],
                "epipolar, 1024 lines, 32 initial samples, 500 steps",
                None,
            )],
            repeat: 3,
            warmup: 1,
            reference_steps: 0,
        },
        "klehm-table1" => {
            let variants = KLEHM_TABLE1
                .iter()
                .map(|&(r, b)| {
                    let (o1, o2) = (format!("regions={r}"), format!("bases_per_thread={b}"));
                    Variant::new(
                        "prefiltered",
                        &["bases=32", "map_size=[1024, 1024]", "bands=1", &o1, &o2],
                        &format!("{r} region{} per slice", if r == 1 { "" } else { "s" }),
                        Some(("bases_per_thread", b as f64)),
                    )
                })
                .collect();
            BenchPlan {
                name: name.into(),
                description: "Klehm, Seidel & Eisemann 2014, §3.3 and Table 1: the two parallelisations of the \
                              prefilter (the fused basis transform and weighted prefix sum, Listing 3) — rows \
                              split into 1–4 regions per slice, each prefix-summed by its own threads, and 4, 8 \
                              or 16 of the M = 32 bases per thread — against the naive one (1 region, 32 bases \
                              per thread: one thread per slice), at 1920×1080 with a 1024×1024 rectified map \
                              on `forest` (the paper's San Miguel: sun through foliage) and the paper's one \
                              reference ray per slice (`bands = 1`; the default 4 bands run the prefix sum 4 \
                              times). Prefix sum = the `prefilter` pass, scattering = `evaluate` + `epipole` \
                              (more regions: one more lookup per region in front of the surface); the map's \
                              creation (`rasterize (host)` or `rectify`) is excluded, as in the paper. Paper \
                              (NVIDIA Titan): 3 regions × 8 bases per thread best, about 20 % faster than \
                              naive; the best split is hardware dependent. bench.md's `Paper table` gives the \
                              +% column as t_naive / t − 1."
                    .into(),
                scenes: vec![KLEHM_SCENE.into()],
                sizes: vec![(1920, 1080)],
                variants,
                repeat: 3,
                warmup: 1,
                reference_steps: 0,
            }
        }
        "klehm-table2" => {
            let variants = KLEHM_TABLE2
                .iter()
                .map(|&(w, h, m)| {
                    let (o1, o2) = (format!("map_size=[{w}, {h}]"), format!("bases={m}"));
                    let o = [o1.as_str(), o2.as_str(), "bands=1"];
                    let texels = w as f64 * h as f64 / 1048576.0;
                    let (series, sweep) = match (m, h) {
                        (32, 1024) => ("map columns × 1024 rows, M = 32", ("map_mtexels", texels)),
                        (32, _) => ("1024 columns × map rows, M = 32", ("map_mtexels", texels)),
                        _ => ("M bases, map 1024×1024", ("bases", m as f64)),
                    };
                    Variant::new("prefiltered", &o, series, Some(sweep))
                })
                .collect();
            BenchPlan {
                name: name.into(),
                description: "Klehm, Seidel & Eisemann 2014, §5 and Table 2: prefiltered's cost and memory against \
                              the rectified shadow map's size (columns along the view rays × rows, one per \
                              epipolar slice: 512–4096 × 1024 and 1024 × 512–1536 at M = 32) and the number of \
                              Fourier bases M (16, 64, 128 at 1024×1024), at 1920×1080 on `forest` (the \
                              paper's San Miguel) with the paper's one reference ray per slice (`bands = 1`; \
                              the default 4 bands hold 4 sets of bases). Prefix sum = `prefilter`, scattering \
                              = `evaluate` + `epipole`; memory = the filtered bases (`basis_bytes`, \
                              columns·rows·M bytes at 8 bits) and all the technique holds (GPU memory). Paper \
                              (NVIDIA Titan): the prefix sum linear in the map's texels, the scattering \
                              constant in map size, both sub-linear in M; 32 MB at 1024×1024, M = 32. Quality \
                              vs `reference` shows what M and the map buy."
                    .into(),
                scenes: vec![KLEHM_SCENE.into()],
                sizes: vec![(1920, 1080)],
                variants,
                repeat: 3,
                warmup: 1,
                reference_steps: 256,
            }
        }
        "klehm-fig5" => {
            let mut variants = vec![
                Variant::new("brute-force", &["steps=256"], "optimal", None),
                Variant::new(
                    "epipolar",
                    &["initial_samples=64", "threshold_growth=0.02", "taps=5", "steps=256"],
                    "optimal",
                    None,
                ),
                Variant::new(
                    "prefiltered",
                    &["map_size=[2048, 2048]", "bases=64", "bands=8", "epipole_radius=16", "epipole_steps=256"],
                    "optimal",
                    None,
                ),
                Variant::new(
                    "minmax",
                    &["map_size=[2048, 2048]", "light_steps=128", "epipole_radius=16", "epipole_steps=256"],
                    "optimal",
                    None,
                ),
                Variant::new(
                    "epipolar",
                    &[
                        "initial_samples=64",
                        "threshold_growth=0.02",
                        "taps=5",
                        "steps=256",
                        "march=\"minmax\"",
                        "minmax_map_size=[2048, 2048]",
                    ],
                    "optimal, min-max march",
                    None,
                ),
            ];
            for steps in [32, 64, 128] {
                let o = format!("steps={steps}");
                for t in ["brute-force", "epipolar"] {
                    variants.push(Variant::new(t, &[&o], &format!("{t} (steps)"), Some(("steps", steps as f64))));
                }
            }
            for map in [256, 512, 1024] {
                let o = format!("map_size=[{map}, {map}]");
                for t in ["prefiltered", "minmax"] {
                    variants.push(Variant::new(t, &[&o], &format!("{t} (map)"), Some(("map_size", map as f64))));
                }
                let o = format!("minmax_map_size=[{map}, {map}]");
                variants.push(Variant::new(
                    "epipolar",
                    &["march=\"minmax\"", &o],
                    "epipolar, min-max march (map)",
                    Some(("map_size", map as f64)),
                ));
            }
            BenchPlan {
                name: name.into(),
                description: "Klehm, Seidel & Eisemann 2014, §5 and Fig. 5: their filtered technique against the 1D \
                              min-max mipmaps of Chen et al. 2011 (\"over 20× faster\" on a tree, 1.8× on a \
                              terrain) — here prefiltered, minmax, epipolar and brute-force on `forest` (the dense \
                              canopy) and `terrain`. (a) Each at its quality-optimal settings (the \
                              `reference-like` presets: brute-force and epipolar 256 steps, prefiltered 2048² \
                              map with M = 64 and 8 bands, minmax 2048² map); (b) swept down in cost — steps \
                              32–128 for the marching ones, rectified maps 256²–1024² for the map-based ones, as \
                              the paper lowered the shadow-map resolution of the slower technique — and read at \
                              equal time: bench.md's `Fig. 5 table` gives, per technique, the best PSNR within \
                              the time of minmax at its default 1024² map. minmax's cost grows with how often \
                              the visibility along a ray changes: `nodes per ray` in the table. epipolar runs \
                              both marches: its `steps` and, as Yusov 2013 combines them, its samples walking \
                              the min-max tree (`march = \"minmax\"`, maps 256²–2048²)."
                    .into(),
                scenes: vec!["forest".into(), "terrain".into()],
                sizes: vec![(1920, 1080)],
                variants,
                repeat: 3,
                warmup: 1,
                reference_steps: 256,
            }
        }
        "klehm-scenes" => BenchPlan {
            name: name.into(),
            description: "Klehm, Seidel & Eisemann 2014, §5: \"our method shows constant performance\" — its cost is \
                          O(wh + ad) (w×h pixels, a slices, d columns) against brute-force ray marching's \
                          O(whd) — and \"below 3 ms\" at 1920×1080 where ray marching is far slower. \
                          prefiltered at its defaults (M = 32, 1024×1024 map, 4 bands, auto rectification) on every \
                          built-in scene, and brute-force at 256 steps per pixel on the same frames. \
                          bench.md's `Paper table` gives each scene's times, the speed-up and the spread of \
                          prefiltered's time over the scenes."
                .into(),
            scenes: crepuscular_scene::builtin::builtin_names().iter().map(|(n, _)| n.to_string()).collect(),
            sizes: vec![(1920, 1080)],
            variants: vec![
                Variant::new("prefiltered", &[], "prefiltered", None),
                Variant::new("brute-force", &["steps=256"], "brute-force, 256 steps", None),
            ],
            repeat: 3,
            warmup: 1,
            reference_steps: 256,
        },
        "lights" => BenchPlan {
            name: name.into(),
            description: "Many lights: every GPU technique at its defaults on `night-street` with its first 0, 1, \
                          2, 4 and 8 lights (`night-street:lights=N`: four street lamps, then the lantern \
                          (point), the moon and two more lamps; 0 = the first lamp with its scattering off, the \
                          work that does not depend on the lights). bench.md's `Lights table` gives, per \
                          technique, the first light's cost (t1 − t0), each added light's (tN − t1)/(N − 1) and \
                          their ratio (goal for the march-based techniques: ≤ 0.5), and PSNR vs reference at \
                          each N."
                .into(),
            scenes: LIGHT_COUNTS.iter().map(|n| format!("{LIGHTS_SCENE}:lights={n}")).collect(),
            sizes: vec![(480, 270)],
            variants: crepuscular::techniques::TECHNIQUES
                .iter()
                .filter(|t| t.gpu)
                .map(|t| Variant::new(t.name, &[], t.name, None))
                .collect(),
            repeat: 3,
            warmup: 1,
            reference_steps: 256,
        },
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
    /// Size the flicker was measured at.
    pub flicker_size: Option<[u32; 2]>,
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
            let mut scene = load_scene(scene_name)?;
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
        let mut scene = load_scene(scene_arg)?;
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

/// Checks `--flicker-frames` against the plan before any work.
pub fn check_flicker_frames(frames: u32, reference_steps: u32) -> Result<()> {
    if frames == 1 || frames > 1000 {
        bail!("--flicker-frames {frames}: must be 0 (no flicker) or in 2..=1000");
    }
    if frames > 0 && reference_steps == 0 {
        bail!("--flicker-frames {frames}: flicker is measured against the reference; it needs --reference-steps > 0");
    }
    Ok(())
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
    if let (true, Some([fw, fh])) = (r.flicker_frames > 0, r.flicker_size) {
        s += &format!(
            "- flicker: {} frames 1/24 of the scene's `animate` loop apart at {fw}×{fh}; the mean over pixels and frame pairs of |e(t+1) − e(t)|, e = luminance of (technique − reference) in-scattering, as a percentage of the reference's mean luminance (rows of the smallest size only)\n",
            r.flicker_frames
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
    let fl = r.flicker_frames > 0;
    s += "\n## Techniques\n\n| scene | size | configuration | technique ms | frame ms (host + technique) | passes (median ms) | ray-marched samples | GPU memory | PSNR dB | FLIP |";
    s += if fl {
        " flicker % |\n|---|---|---|---|---|---|---|---|---|---|---|\n"
    } else {
        "\n|---|---|---|---|---|---|---|---|---|---|\n"
    };
    for x in &r.records {
        let host = r.host.iter().find(|h| h.scene == x.scene && h.size == x.size).map(|h| h.total_ms[0]).unwrap_or(0.0);
        s += &format!(
            "| {} | {}×{} | {} | {:.2} ({:.2}–{:.2}) | {:.2} | {} | {} | {:.1} KiB | {} | {} |{}\n",
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
            if fl { format!(" {} |", fmt_opt(x.flicker.map(|f| 100.0 * f.relative), 3)) } else { String::new() },
        );
    }
    s += &paper_table(r);
    s
}

/// `klehm-scenes`: per scene and size, prefiltered's passes and whole time against brute-force's,
/// and the spread of prefiltered's time over the scenes; times as "median (fastest frame)".
fn scenes_table(r: &BenchReport) -> String {
    let mut s = String::from(
        "\n## Paper table\n\nprefiltered: map = `rasterize (host)` or `rectify`, prefix sum = `prefilter`, scattering = \
         `evaluate` + `epipole`, total = the whole technique; ms as median (fastest frame); speed-up = brute-force \
         total / prefiltered total (of medians, and of fastest frames).\n\n\
         | scene | size | rectification | map | prefix sum | scattering | prefiltered total | prefiltered PSNR dB | brute-force total | brute-force PSNR dB | speed-up |\n\
         |---|---|---|---|---|---|---|---|---|---|---|\n",
    );
    let mut spread: BTreeMap<[u32; 2], Vec<[f64; 2]>> = BTreeMap::new();
    let mut seen: Vec<(&str, [u32; 2])> = Vec::new();
    for x in &r.records {
        if !seen.contains(&(x.scene.as_str(), x.size)) {
            seen.push((x.scene.as_str(), x.size));
        }
    }
    let cell = |x: Option<&BenchRecord>, names: &[&str]| {
        x.map_or("–".into(), |x| {
            let med: f64 = names.iter().map(|n| pass_ms(x, n)).sum();
            let min: f64 = names.iter().map(|n| pass_min_ms(x, n)).sum();
            format!("{med:.1} ({min:.1})")
        })
    };
    let total =
        |x: Option<&BenchRecord>| x.map_or("–".into(), |x| format!("{:.1} ({:.1})", x.total_ms[0], x.total_ms[1]));
    for (scene, size) in seen {
        let row = |t: &str| r.records.iter().find(|x| x.technique == t && x.scene == scene && x.size == size);
        let (pf, bf) = (row("prefiltered"), row("brute-force"));
        let mode = match pf.and_then(|x| x.extra.get("projective")) {
            Some(&p) if p > 0.5 => "projective",
            Some(_) => "epipolar",
            None => "–",
        };
        if let Some(x) = pf {
            spread.entry(size).or_default().push([x.total_ms[0], x.total_ms[1]]);
        }
        let speedup = match (pf, bf) {
            (Some(p), Some(b)) if p.total_ms[0] > 0.0 && p.total_ms[1] > 0.0 => {
                format!("{:.1}× ({:.1}×)", b.total_ms[0] / p.total_ms[0], b.total_ms[1] / p.total_ms[1])
            }
            _ => "–".into(),
        };
        s += &format!(
            "| {scene} | {}×{} | {mode} | {} | {} | {} | {} | {} | {} | {} | {speedup} |\n",
            size[0],
            size[1],
            cell(pf, &["rasterize (host)", "rectify"]),
            cell(pf, &["prefilter"]),
            cell(pf, &["evaluate", "epipole"]),
            total(pf),
            fmt_opt(pf.and_then(|x| x.psnr_db), 2),
            total(bf),
            fmt_opt(bf.and_then(|x| x.psnr_db), 2),
        );
    }
    for (size, v) in spread {
        for (k, what) in [(0, "medians"), (1, "fastest frames")] {
            let (lo, hi) = v.iter().fold((f64::MAX, f64::MIN), |a, t| (a.0.min(t[k]), a.1.max(t[k])));
            let mean = v.iter().map(|t| t[k]).sum::<f64>() / v.len() as f64;
            s += &format!(
                "\nprefiltered at {}×{} over {} scenes ({what}): {lo:.1}–{hi:.1} ms, max/min − 1 = {:.1} %, \
                 (max − min)/mean = {:.1} %\n",
                size[0],
                size[1],
                v.len(),
                100.0 * (hi / lo - 1.0),
                100.0 * (hi - lo) / mean,
            );
        }
    }
    s
}

/// `klehm-fig5`: per scene and size, (a) each technique at its quality-optimal settings — time,
/// PSNR, FLIP, minmax's nodes per ray —, and (b) at equal time: the best PSNR each technique
/// reaches within the median time of minmax at its default 1024² map (+10 %), and with which
/// setting. epipolar has a row per march. Times are medians (fastest frame).
fn fig5_table(r: &BenchReport) -> String {
    let mut s = String::from(
        "\n## Fig. 5 table\n\n(a) quality-optimal settings; (b) equal time: the best PSNR within the budget = minmax's \
         time at its default 1024² map (+10 %). ms as median (fastest frame).\n\n\
         | scene | size | technique | (a) ms | (a) PSNR dB | (a) FLIP | (a) nodes per ray (max) | (b) setting | (b) ms | (b) PSNR dB |\n\
         |---|---|---|---|---|---|---|---|---|---|\n",
    );
    let mut seen: Vec<(&str, [u32; 2])> = Vec::new();
    for x in &r.records {
        if !seen.contains(&(x.scene.as_str(), x.size)) {
            seen.push((x.scene.as_str(), x.size));
        }
    }
    // The rows: a technique and whether its samples walk the min-max tree.
    let walks = |x: &BenchRecord| x.series.contains("min-max march");
    let kinds: [(&str, &str, bool); 5] = [
        ("prefiltered", "prefiltered", false),
        ("minmax", "minmax", false),
        ("epipolar", "epipolar (steps)", false),
        ("epipolar", "epipolar (min-max march)", true),
        ("brute-force", "brute-force", false),
    ];
    for (scene, size) in seen {
        let rows: Vec<&BenchRecord> = r.records.iter().filter(|x| x.scene == scene && x.size == size).collect();
        let budget = rows
            .iter()
            .find(|x| x.technique == "minmax" && x.sweep.as_ref().is_some_and(|(_, v)| *v == 1024.0))
            .map(|x| x.total_ms[0] * 1.1);
        for (t, label, walk) in kinds {
            let mine = |x: &&&BenchRecord| x.technique == t && walks(x) == walk;
            let Some(a) = rows.iter().filter(mine).find(|x| x.series.starts_with("optimal")) else { continue };
            let nodes = match (a.extra.get("nodes_per_ray"), a.extra.get("max_nodes_per_ray")) {
                (Some(n), Some(m)) => format!("{n:.1} ({m:.0})"),
                _ => "–".into(),
            };
            let best = budget.and_then(|b| {
                rows.iter()
                    .filter(mine)
                    .filter(|x| x.total_ms[0] <= b && x.psnr_db.is_some())
                    .max_by(|p, q| p.psnr_db.partial_cmp(&q.psnr_db).unwrap_or(std::cmp::Ordering::Equal))
            });
            let (setting, ms, psnr) = match best {
                Some(x) => (
                    x.sweep.as_ref().map_or("optimal".into(), |(k, v)| format!("{k} {v}")),
                    format!("{:.1} ({:.1})", x.total_ms[0], x.total_ms[1]),
                    fmt_opt(x.psnr_db, 2),
                ),
                None => ("none within budget".into(), "–".into(), "–".into()),
            };
            s += &format!(
                "| {scene} | {}×{} | {label} | {:.1} ({:.1}) | {} | {} | {nodes} | {setting} | {ms} | {psnr} |\n",
                size[0],
                size[1],
                a.total_ms[0],
                a.total_ms[1],
                fmt_opt(a.psnr_db, 2),
                fmt_opt(a.flip_mean, 4),
            );
        }
        if let Some(b) = budget {
            s += &format!("\n{scene} {}×{}: budget {b:.1} ms\n\n", size[0], size[1]);
        }
    }
    s
}

/// Median ms of the pass `name` of a row (0 when it has none).
fn pass_ms(x: &BenchRecord, name: &str) -> f64 {
    x.passes.iter().filter(|p| p.name == name).map(|p| p.median_ms).sum()
}

/// Fastest frame's ms of the pass `name` of a row (0 when it has none).
fn pass_min_ms(x: &BenchRecord, name: &str) -> f64 {
    x.passes.iter().filter(|p| p.name == name).map(|p| p.min_ms).sum()
}

/// The rows of a `klehm-*` preset laid out as the paper's table: prefix sum (`prefilter`),
/// scattering (`evaluate` + `epipole`), their sum, and the change against the naive
/// configuration (Table 1) or the memory (Table 2), each time as "median (fastest frame)": on a
/// shared or software device the fastest frame is the one least disturbed by other work. The
/// map's creation (`rasterize (host)` or `rectify`), which the paper excludes, is given
/// separately. Empty for other plans.
fn paper_table(r: &BenchReport) -> String {
    use crepuscular::techniques::prefiltered::PrefilteredSettings;
    if r.plan.name == "klehm-scenes" {
        return scenes_table(r);
    }
    if r.plan.name == "lights" {
        return lights_table(r);
    }
    if r.plan.name == "klehm-fig5" {
        return fig5_table(r);
    }
    let table1 = r.plan.name == "klehm-table1";
    if !table1 && r.plan.name != "klehm-table2" {
        return String::new();
    }
    let settings = |x: &BenchRecord| -> Option<PrefilteredSettings> {
        match &x.settings {
            TechniqueSettings::Prefiltered(p) => Some(p.clone()),
            _ => None,
        }
    };
    // [median, fastest] of the map's creation, the prefix sum, the scattering (the per-pixel
    // evaluation with the epipole disc it ray-marches, §5) and the paper's sum.
    let times = |x: &BenchRecord| -> [[f64; 2]; 4] {
        let both = |n: &str| [pass_ms(x, n), pass_min_ms(x, n)];
        let (raster, rectify, pre, eval, epi) =
            (both("rasterize (host)"), both("rectify"), both("prefilter"), both("evaluate"), both("epipole"));
        let scatter = [eval[0] + epi[0], eval[1] + epi[1]];
        [[raster[0] + rectify[0], raster[1] + rectify[1]], pre, scatter, [pre[0] + scatter[0], pre[1] + scatter[1]]]
    };
    let cell = |v: [f64; 2]| format!("{:.1} ({:.1})", v[0], v[1]);
    let mut s = String::from(
        "\n## Paper table\n\nPrefix sum = `prefilter`, scattering = `evaluate` + `epipole`, sum = both, ms as median \
         (fastest frame); map = the rectified map's creation (`rasterize (host)` or `rectify`), excluded from the \
         sum as in the paper.",
    );
    if table1 {
        s += " +% = t_naive / t − 1 against the naive row (1 region, 32 bases per thread) of the same scene and \
              size, positive = faster (of medians, and of fastest frames).\n\n\
              | scene | size | regions per slice | bases per thread | prefix sum | scattering | sum | +% | map |\n\
              |---|---|---|---|---|---|---|---|---|\n";
    } else {
        s += " Filtered bases = columns·rows·M bytes at 8 bits (`basis_bytes`, the paper's Memory column, MiB, \
              one set: `bands` × more are held); GPU memory = all the technique holds.\n\n\
              | scene | size | map size | bases M | prefix sum | scattering | sum | filtered bases MiB | GPU memory MiB | map | PSNR dB |\n\
              |---|---|---|---|---|---|---|---|---|---|---|\n";
    }
    for x in &r.records {
        let Some(p) = settings(x) else { continue };
        let (w, h) = (x.size[0], x.size[1]);
        let [map, pre, scatter, sum] = times(x);
        if table1 {
            let naive = r.records.iter().find(|n| {
                n.scene == x.scene
                    && n.size == x.size
                    && settings(n).is_some_and(|q| q.regions == 1 && q.bases_per_thread == q.bases)
            });
            let change = match naive.map(|n| times(n)[3]) {
                Some(n) if sum[0] > 0.0 && sum[1] > 0.0 => {
                    format!("{:+.0} % ({:+.0} %)", 100.0 * (n[0] / sum[0] - 1.0), 100.0 * (n[1] / sum[1] - 1.0))
                }
                _ => "–".into(),
            };
            s += &format!(
                "| {} | {w}×{h} | {} | {} | {} | {} | {} | {change} | {} |\n",
                x.scene,
                p.regions,
                p.bases_per_thread,
                cell(pre),
                cell(scatter),
                cell(sum),
                cell(map),
            );
        } else {
            let basis = x.extra.get("basis_bytes").copied().unwrap_or(p.basis_bytes() as f64);
            s += &format!(
                "| {} | {w}×{h} | {}×{} | {} | {} | {} | {} | {:.1} | {:.1} | {} | {} |\n",
                x.scene,
                p.map_size[0],
                p.map_size[1],
                p.bases,
                cell(pre),
                cell(scatter),
                cell(sum),
                basis / 1048576.0,
                x.gpu_memory_bytes as f64 / 1048576.0,
                cell(map),
                fmt_opt(x.psnr_db, 2),
            );
        }
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

/// Size of every plot, pixels (SVG user units and PNG pixels).
const PLOT_SIZE: (u32, u32) = (900, 560);

/// Writes a plot as SVG at `path` and as PNG beside it (same stem). Nothing is written when no
/// curve has a finite point.
fn line_plot(path: &Path, title: &str, x_desc: &str, y_desc: &str, log_x: bool, curves: &Curves) -> Result<bool> {
    let mut svg = String::new();
    {
        let root = plotters::prelude::SVGBackend::with_string(&mut svg, PLOT_SIZE);
        if !draw_plot(root, title, x_desc, y_desc, log_x, curves)? {
            return Ok(false);
        }
    }
    crate::output::write_atomic(path, svg.as_bytes())?;
    let mut png = pixel_plot::RgbBackend::new(PLOT_SIZE);
    draw_plot(&mut png, title, x_desc, y_desc, log_x, curves)?;
    crate::output::write_png_rgb8(&path.with_extension("png"), PLOT_SIZE.0, PLOT_SIZE.1, &png.rgb)?;
    Ok(true)
}

/// Draws the plot on any plotters backend; false when there is nothing to draw.
fn draw_plot<DB: plotters::prelude::DrawingBackend>(
    backend: DB,
    title: &str,
    x_desc: &str,
    y_desc: &str,
    log_x: bool,
    curves: &Curves,
) -> Result<bool> {
    use plotters::prelude::*;
    let pts: Vec<(f64, f64)> =
        curves.iter().flat_map(|c| c.1.iter().copied()).filter(|p| p.0.is_finite() && p.1.is_finite()).collect();
    if pts.is_empty() {
        return Ok(false);
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
    let root = backend.into_drawing_area();
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
                // 17 px: plotters sizes the legend box from its estimate of the font (≈ 0.46 em
                // per character), which at this size matches the PNG's 8-pixel glyphs.
                .label_font(("sans-serif", 17))
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
    Ok(true)
}

/// A plotters backend that draws into an 8-bit RGB buffer with the 8×8 bitmap font of the
/// contact sheet (`font8x8`, public domain), so PNG plots need no TrueType font: plotters'
/// own bitmap backend needs one (`ttf` or `ab_glyph` plus a font file), and enabling those
/// features would make the SVG plots depend on a font being found too.
mod pixel_plot {
    use plotters_backend::text_anchor::{HPos, VPos};
    use plotters_backend::{BackendColor, BackendCoord, BackendTextStyle, DrawingBackend, DrawingErrorKind};

    /// The buffer, white-initialised; `rgb` is tightly packed, row-major from the top left.
    pub struct RgbBackend {
        pub size: (u32, u32),
        pub rgb: Vec<u8>,
    }

    impl RgbBackend {
        pub fn new(size: (u32, u32)) -> Self {
            RgbBackend { size, rgb: vec![255; size.0 as usize * size.1 as usize * 3] }
        }
    }

    /// Font pixels per glyph pixel for a plotters font size (px): 12–17 px → 1, 18+ → 2.
    fn scale(size: f64) -> i32 {
        ((size / 12.0).floor() as i32).clamp(1, 4)
    }

    #[derive(Debug)]
    pub struct Never;
    impl std::fmt::Display for Never {
        fn fmt(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
            f.write_str("unreachable")
        }
    }
    impl std::error::Error for Never {}

    impl DrawingBackend for &mut RgbBackend {
        type ErrorType = Never;

        fn get_size(&self) -> (u32, u32) {
            self.size
        }

        fn ensure_prepared(&mut self) -> Result<(), DrawingErrorKind<Never>> {
            Ok(())
        }

        fn present(&mut self) -> Result<(), DrawingErrorKind<Never>> {
            Ok(())
        }

        fn draw_pixel(&mut self, (x, y): BackendCoord, c: BackendColor) -> Result<(), DrawingErrorKind<Never>> {
            let (w, h) = self.size;
            if x < 0 || y < 0 || x >= w as i32 || y >= h as i32 || c.alpha <= 0.0 {
                return Ok(());
            }
            let i = (y as usize * w as usize + x as usize) * 3;
            let a = c.alpha.min(1.0);
            for (k, v) in [c.rgb.0, c.rgb.1, c.rgb.2].into_iter().enumerate() {
                let old = self.rgb[i + k] as f64;
                self.rgb[i + k] = (old + (v as f64 - old) * a).round() as u8;
            }
            Ok(())
        }

        fn estimate_text_size<S: BackendTextStyle>(
            &self,
            text: &str,
            style: &S,
        ) -> Result<(u32, u32), DrawingErrorKind<Never>> {
            let s = scale(style.size()) as u32;
            Ok((text.chars().count() as u32 * 8 * s, 8 * s))
        }

        fn draw_text<S: BackendTextStyle>(
            &mut self,
            text: &str,
            style: &S,
            pos: BackendCoord,
        ) -> Result<(), DrawingErrorKind<Never>> {
            use font8x8::UnicodeFonts;
            let color = style.color();
            let s = scale(style.size());
            let (w, h) = (text.chars().count() as i32 * 8 * s, 8 * s);
            let dx = match style.anchor().h_pos {
                HPos::Left => 0,
                HPos::Right => -w,
                HPos::Center => -w / 2,
            };
            let dy = match style.anchor().v_pos {
                VPos::Top => 0,
                VPos::Center => -h / 2,
                VPos::Bottom => -h,
            };
            let trans = style.transform();
            for (n, ch) in text.chars().enumerate() {
                let ch = match ch {
                    '—' | '–' | '−' => '-',
                    c => c,
                };
                let glyph = font8x8::BASIC_FONTS
                    .get(ch)
                    .or_else(|| font8x8::LATIN_FONTS.get(ch))
                    .or_else(|| font8x8::GREEK_FONTS.get(ch))
                    .or_else(|| font8x8::BASIC_FONTS.get('?'))
                    .unwrap_or([0; 8]);
                for (row, bits) in glyph.iter().enumerate() {
                    for col in 0..8 {
                        if bits >> col & 1 == 1 {
                            for sy in 0..s {
                                for sx in 0..s {
                                    let x = n as i32 * 8 * s + col * s + sx + dx;
                                    let y = row as i32 * s + sy + dy;
                                    let (x, y) = trans.transform(x, y);
                                    self.draw_pixel((pos.0 + x, pos.1 + y), color)?;
                                }
                            }
                        }
                    }
                }
            }
            Ok(())
        }
    }
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
                if line_plot(
                    &p,
                    &format!("time vs quality — {name} {w}×{h} — {dev}"),
                    "technique time per frame, ms (median)",
                    "PSNR vs reference, dB",
                    true,
                    &curves,
                )? {
                    written.push(p.with_extension("png"));
                    written.push(p);
                }
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
        if line_plot(
            &p,
            &format!("time per scene ({}) — {}×{} — {dev}", r.plan.scenes.join(", "), size.0, size.1),
            "scene (index in the list above)",
            "technique time per frame, ms (median)",
            false,
            &curves,
        )? {
            written.push(p.with_extension("png"));
            written.push(p);
        }
    }
    // Time vs a swept setting: one plot per scene, size and setting, each series a curve.
    let mut keys: Vec<&str> = Vec::new();
    for v in &r.plan.variants {
        if let Some((k, _)) = &v.sweep
            && !keys.contains(&k.as_str())
        {
            keys.push(k);
        }
    }
    for key in keys {
        for scene in &r.plan.scenes {
            for &(w, h) in &r.plan.sizes {
                let mut curves: Curves = Vec::new();
                for x in r.records.iter().filter(|x| load_name_matches(scene, &x.scene) && x.size == [w, h]) {
                    let Some((k, v)) = &x.sweep else { continue };
                    if k != key {
                        continue;
                    }
                    let pt = (*v, x.total_ms[0]);
                    match curves.iter_mut().find(|c| c.0 == x.series) {
                        Some(c) => c.1.push(pt),
                        None => curves.push((x.series.clone(), vec![pt])),
                    }
                }
                if curves.iter().map(|c| c.1.len()).sum::<usize>() < 2 {
                    continue;
                }
                let name: String =
                    scene.chars().map(|c| if c.is_ascii_alphanumeric() || c == '-' { c } else { '_' }).collect();
                let p = dir.join(format!("time_vs_{key}_{name}_{w}x{h}.svg"));
                if line_plot(
                    &p,
                    &format!("time vs {key} — {name} {w}×{h} — {dev}"),
                    key,
                    "technique time per frame, ms (median)",
                    false,
                    &curves,
                )? {
                    written.push(p.with_extension("png"));
                    written.push(p);
                }
            }
        }
    }
    // Time and quality vs the number of lights (the `lights` preset): one curve per technique.
    if r.plan.scenes.iter().all(|s| light_count(s).is_some()) && r.plan.scenes.len() > 1 {
        for (what, file, quality) in [
            ("technique time per frame, ms (median)", "time_vs_lights", false),
            ("PSNR vs reference, dB", "psnr_vs_lights", true),
        ] {
            let mut curves: Curves = Vec::new();
            for x in &r.records {
                let Some(n) = light_count(&x.scene) else { continue };
                let y = if quality { x.psnr_db } else { Some(x.total_ms[0]) };
                let Some(y) = y.filter(|y| y.is_finite()) else { continue };
                match curves.iter_mut().find(|c| c.0 == x.series) {
                    Some(c) => c.1.push((n as f64, y)),
                    None => curves.push((x.series.clone(), vec![(n as f64, y)])),
                }
            }
            let p = dir.join(format!("{file}.svg"));
            let (w, h) = r.plan.sizes[0];
            if line_plot(
                &p,
                &format!("{what} vs lights — {LIGHTS_SCENE} {w}×{h} — {dev}"),
                "lights",
                what,
                false,
                &curves,
            )? {
                written.push(p.with_extension("png"));
                written.push(p);
            }
        }
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
        if line_plot(
            &p,
            &format!("time vs resolution — {} — {dev}", r.records.first().map(|x| x.scene.as_str()).unwrap_or("")),
            "megapixels",
            "technique time per frame, ms (median)",
            false,
            &curves,
        )? {
            written.push(p.with_extension("png"));
            written.push(p);
        }
    }
    Ok(written)
}

fn load_name_matches(arg: &str, scene_name: &str) -> bool {
    arg == scene_name || Path::new(arg).file_stem().is_some_and(|s| s == scene_name)
}
