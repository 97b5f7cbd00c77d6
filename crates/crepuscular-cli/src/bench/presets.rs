//! `bench --preset`: the named experiments that reproduce the papers' tables.

use super::*;

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
    (
        TEMPORAL_PRESET,
        "the temporal stage at each technique's default cost: every GPU technique at its defaults on every built-in scene, 320×180, with the temporal column (8 frames of a slow camera move, then the measured one, then 10 frames after a light jump)",
    ),
];

/// The presets that reproduce a paper's table or figure: they pin the nearest-texel shadow
/// filter ([`BenchPlan::shadow_filter`]).
pub const PAPER_PRESETS: &[&str] = &[
    "toth-interleaving",
    "engelhardt-fig9",
    "engelhardt-fig10",
    "engelhardt-timings",
    "wyman-steps",
    "klehm-table1",
    "klehm-table2",
    "klehm-fig5",
    "klehm-scenes",
];

/// The preset that turns the temporal column on ([`super::measure_temporal`]).
pub const TEMPORAL_PRESET: &str = "temporal";

/// The scene of the `lights` preset and the light counts it sweeps.
pub(super) const LIGHTS_SCENE: &str = "night-street";
pub(super) const LIGHT_COUNTS: [usize; 5] = [0, 1, 2, 4, 8];

/// The light count of a `NAME:lights=N` scene name.
pub(super) fn light_count(scene: &str) -> Option<usize> {
    scene.rsplit_once(":lights=").and_then(|(_, n)| n.parse().ok())
}

/// The scene of the Klehm et al. 2014 presets: their San Miguel is a sun through a tree's
/// leaves (a complex shadow map), which `forest` is.
pub(super) const KLEHM_SCENE: &str = "forest";

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

/// Every GPU technique at its defaults, one variant each (`lights`, `temporal`).
fn gpu_techniques_at_defaults() -> Vec<Variant> {
    crepuscular::techniques::TECHNIQUES
        .iter()
        .filter(|t| t.gpu)
        .map(|t| Variant::new(t.name, &[], t.name, None))
        .collect()
}

/// A named preset.
pub fn preset(name: &str) -> Result<BenchPlan> {
    let mut plan = match name {
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
            shadow_filter: None,
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
                shadow_filter: None,
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
            shadow_filter: None,
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
                shadow_filter: None,
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
            shadow_filter: None,
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
                shadow_filter: None,
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
                shadow_filter: None,
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
                shadow_filter: None,
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
            shadow_filter: None,
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
            variants: gpu_techniques_at_defaults(),
            repeat: 3,
            warmup: 1,
            reference_steps: 256,
            shadow_filter: None,
        },
        TEMPORAL_PRESET => BenchPlan {
            name: name.into(),
            description: "The temporal stage at each technique's default cost: every GPU technique at its \
                          defaults on every built-in scene at 320×180, and the temporal column (turned on by \
                          this preset, as `--temporal`): after 8 frames of a slow camera move, the row as \
                          configured against the row with jitter and the temporal stage (docs/MODEL.md §7), \
                          then 10 frames after a light jump (the ghosting measure, `--ghost-frames`). \
                          The goals it measures (docs/RESULTS.md, \"Temporal accumulation\"): PSNR ≥ 40 dB \
                          and FLIP ≤ 0.02, flicker at most half of the technique's own, recovery from the light jump within 4 frames."
                .into(),
            scenes: crepuscular_scene::builtin::builtin_names().iter().map(|(n, _)| n.to_string()).collect(),
            sizes: vec![(320, 180)],
            variants: gpu_techniques_at_defaults(),
            repeat: 3,
            warmup: 1,
            reference_steps: 256,
            shadow_filter: None,
        },
        other => {
            let names: Vec<_> = PRESETS.iter().map(|p| p.0).collect();
            bail!("unknown preset `{other}` (known: {})", names.join(", "))
        }
    };
    // The papers' presets read every shadow map with the nearest texel, the binary visibility
    // of their techniques and of every figure published from them (the default became
    // bilinear on 2026-12-07).
    if PAPER_PRESETS.contains(&name) {
        plan.shadow_filter = Some(crepuscular::ShadowFilter::Nearest);
    }
    Ok(plan)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The papers' presets read every map with the nearest texel, whatever the scene's default
    /// (bilinear); every other preset keeps each scene's own filter, and the scenes the plan
    /// loads carry the pinned filter.
    #[test]
    fn the_papers_presets_pin_the_nearest_filter() {
        for p in PAPER_PRESETS {
            assert!(PRESETS.iter().any(|(n, _)| n == p), "{p} is a preset");
        }
        for (name, _) in PRESETS {
            let plan = preset(name).unwrap();
            let want = PAPER_PRESETS.contains(name).then_some(crepuscular::ShadowFilter::Nearest);
            assert_eq!(plan.shadow_filter, want, "{name}");
            let scene = plan.load_scene(&plan.scenes[0]).unwrap();
            let own = crate::render::load_scene(&plan.scenes[0]).unwrap().render.shadow.filter;
            assert_eq!(own, crepuscular::ShadowFilter::Bilinear, "{name}: the scene's own default");
            assert_eq!(scene.render.shadow.filter, want.unwrap_or(own), "{name}");
        }
    }
}
