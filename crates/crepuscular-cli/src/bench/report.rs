//! bench.md: the report's markdown and its per-preset tables (Fig. 5, Paper, Lights, Scenes).

use super::*;

pub(super) fn fmt_opt(v: Option<f64>, digits: usize) -> String {
    match v {
        Some(x) if x.is_finite() => format!("{x:.digits$}"),
        Some(x) => format!("{x}"),
        None => "–".into(),
    }
}

pub(super) fn device_line(r: &BenchReport) -> String {
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
    if let Some(f) = r.plan.shadow_filter {
        s += &format!("- shadow filter: `{}` on every light (pinned by the plan)\n", f.name());
    }
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
    s += &temporal_table(r);
    s += &paper_table(r);
    s
}

/// The temporal column (`bench --temporal`): each measured row as configured and with jitter +
/// the temporal stage, after the slow move's last frame.
fn temporal_table(r: &BenchReport) -> String {
    let (Some(t), Some([w, h])) = (&r.temporal, r.flicker_size) else { return String::new() };
    if r.temporal_frames == 0 {
        return String::new();
    }
    let mut s = format!(
        "\n## Temporal stage\n\nEach row along a slow camera move at {w}×{h}: {} frames of the scene's `animate` path \
         1/{} of its loop apart, lights still, each frame against its own reference; PSNR (dB) and FLIP of the last \
         frame (the ones before it are its history), flicker (%) over all of them. \"as configured\" is the row \
         itself; \"jitter + stage\" the row with `jitter=true` (where it has the setting; †: it has none) and \
         `frame_index` advanced per frame, followed by the temporal stage (`history_weight` {}, `clip_sigma` {}, \
         `history_filter` {}, `adaptive_weight` {}, `young_frames` {}, `light_disc_radius` {}, `scattering_distance` {}). Stage ms: its wall clock per frame.\n\n\
         | scene | configuration | as configured PSNR / FLIP / flicker | jitter + stage PSNR / FLIP / flicker | ΔPSNR dB | flicker × | stage ms |\n\
         |---|---|---|---|---|---|---|\n",
        r.temporal_frames,
        TEMPORAL_LOOP,
        t.history_weight,
        t.clip_sigma,
        serde_json::to_string(&t.history_filter).unwrap_or_default(),
        t.adaptive_weight,
        t.young_frames,
        t.light_disc_radius,
        t.scattering_distance,
    );
    for x in &r.records {
        let Some(c) = &x.temporal else { continue };
        let ratio =
            if c.flicker_without.relative > 0.0 { c.flicker.relative / c.flicker_without.relative } else { f64::NAN };
        s += &format!(
            "| {} | {}{} | {:.2} / {:.4} / {:.3} | {:.2} / {:.4} / {:.3} | {:+.2} | {:.2} | {:.1} |\n",
            x.scene,
            x.label,
            if x.settings_have_jitter() { "" } else { " †" },
            c.psnr_db_without,
            c.flip_without,
            100.0 * c.flicker_without.relative,
            c.psnr_db,
            c.flip,
            100.0 * c.flicker.relative,
            c.psnr_db - c.psnr_db_without,
            ratio,
            c.stage_ms,
        );
    }
    s += &light_jump_table(r);
    s
}

/// The temporal column's ghosting measure (`--ghost-frames`): per row, the frames after the
/// light jump, as configured and with jitter + the stage.
fn light_jump_table(r: &BenchReport) -> String {
    if r.ghost_frames == 0 {
        return String::new();
    }
    let mut s = format!(
        "\n### Light jump\n\nAfter the slow move's {} frames, every light turned by {}° (the camera moving on), {} \
         frames against their own references: PSNR (dB) of the jump frame and of the frame after it, the steady \
         state (the mean of the last 4 frames), and the frames until the PSNR is within 1 dB of that steady state \
         (0: the jump frame is; never: not within the frames).\n\n\
         | scene | configuration | as configured: jump, next, steady | recovery | jitter + stage: jump, next, steady | recovery |\n\
         |---|---|---|---|---|---|\n",
        r.temporal_frames,
        crate::animate::LIGHT_JUMP_DEGREES,
        r.ghost_frames,
    );
    let recovery = |f: Option<u32>| f.map_or_else(|| "never".to_string(), |n| n.to_string());
    let figures = |p: &[f64]| {
        let steady = p[p.len().saturating_sub(4)..].iter().sum::<f64>() / p.len().clamp(1, 4) as f64;
        format!("{:.2}, {:.2}, {:.2}", p[0], p.get(1).copied().unwrap_or(f64::NAN), steady)
    };
    for x in &r.records {
        let Some(j) = x.temporal.as_ref().and_then(|c| c.light_jump.as_ref()) else { continue };
        if j.psnr_db.is_empty() || j.psnr_db_without.is_empty() {
            continue;
        }
        s += &format!(
            "| {} | {} | {} | {} | {} | {} |\n",
            x.scene,
            x.label,
            figures(&j.psnr_db_without),
            recovery(j.recovery_frames_without),
            figures(&j.psnr_db),
            recovery(j.recovery_frames),
        );
    }
    s
}

/// `klehm-scenes`: per scene and size, prefiltered's passes and whole time against brute-force's,
/// and the spread of prefiltered's time over the scenes; times as "median (fastest frame)".
pub(super) fn scenes_table(r: &BenchReport) -> String {
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
pub(super) fn fig5_table(r: &BenchReport) -> String {
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
pub(super) fn pass_ms(x: &BenchRecord, name: &str) -> f64 {
    x.passes.iter().filter(|p| p.name == name).map(|p| p.median_ms).sum()
}

/// Fastest frame's ms of the pass `name` of a row (0 when it has none).
pub(super) fn pass_min_ms(x: &BenchRecord, name: &str) -> f64 {
    x.passes.iter().filter(|p| p.name == name).map(|p| p.min_ms).sum()
}

/// The rows of a `klehm-*` preset laid out as the paper's table: prefix sum (`prefilter`),
/// scattering (`evaluate` + `epipole`), their sum, and the change against the naive
/// configuration (Table 1) or the memory (Table 2), each time as "median (fastest frame)": on a
/// shared or software device the fastest frame is the one least disturbed by other work. The
/// map's creation (`rasterize (host)` or `rectify`), which the paper excludes, is given
/// separately. Empty for other plans.
pub(super) fn paper_table(r: &BenchReport) -> String {
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

/// `lights`: per technique, the time at each light count, the first light's cost t1 − t0, each
/// added light's (tN − t1)/(N − 1), their ratio, and PSNR vs reference at each N.
pub(super) fn lights_table(r: &BenchReport) -> String {
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
