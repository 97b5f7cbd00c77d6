//! The binary as a user meets it: renders end to end on the CPU backend, writes every output,
//! diffs, and fails on bad scene files with one line that names the file and the key.

use std::path::{Path, PathBuf};
use std::process::Command;

fn bin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_crepuscular"))
}

fn tmp(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("crepuscular-cli-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

#[test]
fn render_writes_png_exr_and_stats_and_diff_reads_them() {
    let d = tmp("render");
    let run = |technique: &str, stem: &str| {
        let out = bin()
            .args([
                "render",
                "colonnade",
                "--technique",
                technique,
                "--backend",
                "cpu",
                "--size",
                "96x54",
                "--shadow-map-size",
                "512",
            ])
            .args(["--set", if technique == "reference" { "steps=64" } else { "steps=32" }])
            .arg("--output")
            .arg(d.join(format!("{stem}.png")))
            .arg("--exr")
            .arg(d.join(format!("{stem}.exr")))
            .arg("--stats")
            .arg(d.join(format!("{stem}.json")))
            .output()
            .unwrap();
        assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    };
    run("brute-force", "bf");
    run("reference", "ref");
    for f in ["bf.png", "bf.exr", "bf.final.exr", "bf.json", "ref.exr"] {
        assert!(d.join(f).metadata().unwrap().len() > 0, "{f} missing");
    }
    let stats: serde_json::Value = serde_json::from_slice(&std::fs::read(d.join("bf.json")).unwrap()).unwrap();
    assert_eq!(stats["technique"]["raymarched_samples"], 96 * 54 * 32);
    assert_eq!(stats["settings"]["steps"], 32);
    assert_eq!(stats["adapter"]["name"], "cpu");
    let rstats: serde_json::Value = serde_json::from_slice(&std::fs::read(d.join("ref.json")).unwrap()).unwrap();
    assert!(rstats["technique"]["extra"]["convergence_mean_rel_change_half_vs_full"].as_f64().is_some());
    let out = bin()
        .arg("diff")
        .arg(d.join("ref.exr"))
        .arg(d.join("bf.exr"))
        .arg("--heatmap")
        .arg(d.join("heat.png"))
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(text.contains("RMSE") && text.contains("PSNR") && text.contains("FLIP"), "{text}");
    assert!(d.join("heat.png").exists());
    // Identical images: zero error.
    let out = bin().arg("diff").arg(d.join("bf.exr")).arg(d.join("bf.exr")).output().unwrap();
    assert!(
        String::from_utf8_lossy(&out.stdout).contains("RMSE       0.000000e0"),
        "{}",
        String::from_utf8_lossy(&out.stdout)
    );
}

#[test]
fn scenes_and_techniques_list_one_line_each() {
    let out = bin().arg("scenes").output().unwrap();
    let text = String::from_utf8(out.stdout).unwrap();
    for name in ["colonnade", "forest", "stained-glass", "cage", "terrain"] {
        assert_eq!(text.lines().filter(|l| l.starts_with(name)).count(), 1, "{text}");
    }
    let out = bin().arg("techniques").output().unwrap();
    let text = String::from_utf8(out.stdout).unwrap();
    assert!(text.lines().any(|l| l.starts_with("brute-force")) && text.lines().any(|l| l.starts_with("reference")));
}

const GOOD: &str = r#"
[camera]
position = [0, 2, 10]
look_at = [0, 1, 0]
[medium]
scattering = [0.05, 0.05, 0.05]
absorption = [0.01, 0.01, 0.01]
phase = { kind = "henyey-greenstein", g = 0.6 }
[light]
kind = "directional"
direction = [0.2, -0.4, -1]
intensity = 4
[[objects]]
kind = "box"
translate = [0, 1, 0]
[render]
width = 64
height = 36
shadow_map_size = 256
"#;

fn bad_scene(dir: &Path, name: &str, text: &str) -> (bool, String) {
    let p = dir.join(name);
    std::fs::write(&p, text).unwrap();
    let out =
        bin().args(["render"]).arg(&p).args(["--backend", "cpu", "--output"]).arg(dir.join("x.png")).output().unwrap();
    (out.status.success(), String::from_utf8_lossy(&out.stderr).trim().to_string())
}

#[test]
fn bad_scene_files_fail_with_one_line_naming_file_and_key() {
    let d = tmp("bad");
    let (ok, err) = bad_scene(&d, "good.toml", GOOD);
    assert!(ok, "the good scene must render: {err}");
    let cases: &[(&str, String, &str)] = &[
        ("syntax.toml", GOOD.replace("width = 64", "width = = 64"), "width"),
        ("unknown.toml", GOOD.replace("width = 64", "widht = 64"), "widht"),
        ("type.toml", GOOD.replace("width = 64", "width = \"wide\""), "width"),
        (
            "negative.toml",
            GOOD.replace("scattering = [0.05, 0.05, 0.05]", "scattering = [-0.05, 0.05, 0.05]"),
            "scattering",
        ),
        ("nan.toml", GOOD.replace("absorption = [0.01, 0.01, 0.01]", "absorption = [nan, 0.01, 0.01]"), "absorption"),
        ("zero.toml", GOOD.replace("height = 36", "height = 0"), "height"),
        ("mesh.toml", format!("{GOOD}\n[[objects]]\nkind = \"mesh\"\npath = \"missing.obj\"\n"), "path"),
        ("escape.toml", format!("{GOOD}\n[[objects]]\nkind = \"mesh\"\npath = \"../../etc/passwd.obj\"\n"), "path"),
    ];
    for (file, text, key) in cases {
        let (ok, err) = bad_scene(&d, file, text);
        assert!(!ok, "{file} must fail");
        let lines: Vec<_> = err.lines().filter(|l| !l.contains("XDG_RUNTIME_DIR")).collect();
        assert_eq!(lines.len(), 1, "{file}: expected one line, got {err:?}");
        assert!(lines[0].contains(file), "{file}: message does not name the file: {}", lines[0]);
        assert!(lines[0].contains(key), "{file}: message does not name `{key}`: {}", lines[0]);
        assert!(!err.contains("panicked"), "{file}: panicked: {err}");
    }
}

#[test]
fn bad_command_line_values_fail_cleanly() {
    for args in [
        vec!["render", "no-such-scene", "--backend", "cpu"],
        vec!["render", "colonnade", "--size", "0x10", "--backend", "cpu"],
        vec!["render", "colonnade", "--technique", "nope", "--backend", "cpu"],
        vec!["render", "colonnade", "--set", "steps=0", "--backend", "cpu"],
        vec!["render", "colonnade", "--set", "stepz=3", "--backend", "cpu"],
    ] {
        let out = bin().args(&args).output().unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success(), "{args:?} must fail");
        assert!(!err.contains("panicked"), "{args:?} panicked: {err}");
    }
}

#[test]
fn example_scene_files_render() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../examples/scenes");
    let d = tmp("examples");
    let mut n = 0;
    for e in std::fs::read_dir(&dir).unwrap() {
        let p = e.unwrap().path();
        if p.extension().is_some_and(|x| x == "toml") {
            let out = bin()
                .arg("render")
                .arg(&p)
                .args(["--backend", "cpu", "--size", "64x36", "--shadow-map-size", "256", "--output"])
                .arg(d.join("e.png"))
                .output()
                .unwrap();
            assert!(out.status.success(), "{}: {}", p.display(), String::from_utf8_lossy(&out.stderr));
            n += 1;
        }
    }
    assert!(n > 0);
}

#[test]
fn bench_writes_json_markdown_and_plots_with_the_device() {
    let d = tmp("bench");
    let out = bin()
        .args(["bench", "--backend", "cpu", "--scenes", "cage,stained-glass", "--techniques", "brute-force,subsampled"])
        .args(["--sizes", "48x27,64x36", "--repeat", "2", "--warmup", "1", "--reference-steps", "16", "--output"])
        .arg(&d)
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let r: serde_json::Value = serde_json::from_slice(&std::fs::read(d.join("bench.json")).unwrap()).unwrap();
    assert_eq!(r["adapter"]["name"], "cpu");
    // 2 scenes × 2 sizes × 2 techniques × 4 step counts.
    let recs = r["records"].as_array().unwrap();
    assert_eq!(recs.len(), 32);
    for x in recs {
        let t = x["total_ms"].as_array().unwrap();
        let (med, min, max) = (t[0].as_f64().unwrap(), t[1].as_f64().unwrap(), t[2].as_f64().unwrap());
        assert!(min <= med && med <= max && min > 0.0, "{x}");
        assert!(x["psnr_db"].as_f64().is_some() && x["flip_mean"].as_f64().is_some(), "{x}");
    }
    let md = std::fs::read_to_string(d.join("bench.md")).unwrap();
    assert!(md.contains("device: cpu"), "{md}");
    for f in ["time_vs_quality_cage_48x27.svg", "time_per_scene.svg", "time_vs_resolution.svg"] {
        let svg = std::fs::read_to_string(d.join(f)).unwrap_or_else(|e| panic!("{f}: {e}"));
        assert!(svg.starts_with("<svg") && svg.contains("cpu"), "{f}");
    }
    // Presets are listed, and an unknown one fails with the list.
    let out = bin().args(["bench", "--list-presets"]).output().unwrap();
    let list = String::from_utf8_lossy(&out.stdout);
    for preset in ["toth-interleaving", "klehm-table1", "klehm-table2", "klehm-fig5", "klehm-scenes"] {
        assert!(list.lines().any(|l| l.starts_with(preset)), "{preset} not listed: {list}");
    }
    let out = bin().args(["bench", "--preset", "nope", "--backend", "cpu"]).output().unwrap();
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("wyman-steps"));
}

/// The `lights` preset runs small on the CPU and writes its table: every technique at every
/// light count, the first light's cost and each added light's, and the plots.
#[test]
fn the_lights_preset_writes_its_table() {
    let d = tmp("lights");
    let out = bin()
        .args(["bench", "--preset", "lights", "--backend", "cpu", "--sizes", "32x18", "--repeat", "1"])
        .args(["--warmup", "0", "--reference-steps", "8", "--flicker-frames", "0", "--output"])
        .arg(&d)
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let r: serde_json::Value = serde_json::from_slice(&std::fs::read(d.join("bench.json")).unwrap()).unwrap();
    let recs = r["records"].as_array().unwrap();
    let techniques = crepuscular::techniques::TECHNIQUES.iter().filter(|t| t.gpu).count();
    assert_eq!(recs.len(), techniques * 5, "every GPU technique × 5 light counts");
    for n in [0, 1, 2, 4, 8] {
        let scene = format!("night-street:lights={n}");
        let lights: Vec<f64> = recs
            .iter()
            .filter(|x| x["scene"] == scene.as_str())
            .map(|x| x["extra"]["lights"].as_f64().unwrap())
            .collect();
        assert_eq!(lights, vec![n as f64; techniques], "{scene}: the lights that reach the view");
    }
    let md = std::fs::read_to_string(d.join("bench.md")).unwrap();
    let table = md.split("## Lights table").nth(1).unwrap_or_else(|| panic!("no lights table\n{md}"));
    let rows: Vec<&str> = table.lines().filter(|l| l.starts_with("| ") && !l.starts_with("| technique")).collect();
    assert_eq!(rows.len(), techniques, "{table}");
    assert!(rows.iter().all(|r| r.split('|').filter(|c| c.trim() == "–").count() == 0), "{table}");
    for f in ["time_vs_lights.svg", "time_vs_lights.png", "psnr_vs_lights.svg"] {
        assert!(d.join(f).exists(), "{f} missing");
    }
}

/// The Klehm et al. 2014 presets run at a small screen size (their maps keep the paper's sizes)
/// and lay their rows out as the paper's tables.
#[test]
fn klehm_presets_run_small_and_write_the_papers_tables() {
    let d = tmp("klehm");
    let scenes = crepuscular_scene::builtin::builtin_names().len();
    for (preset, rows) in [("klehm-table1", 13), ("klehm-table2", 10), ("klehm-scenes", 2 * scenes)] {
        let out = bin()
            .args(["bench", "--preset", preset, "--backend", "cpu", "--sizes", "32x18", "--repeat", "1"])
            .args(["--warmup", "0", "--reference-steps", "0", "--output"])
            .arg(d.join(preset))
            .output()
            .unwrap();
        assert!(out.status.success(), "{preset}: {}", String::from_utf8_lossy(&out.stderr));
        let r: serde_json::Value =
            serde_json::from_slice(&std::fs::read(d.join(preset).join("bench.json")).unwrap()).unwrap();
        let recs = r["records"].as_array().unwrap();
        assert_eq!(recs.len(), rows, "{preset}");
        let md = std::fs::read_to_string(d.join(preset).join("bench.md")).unwrap();
        let table = md.split("## Paper table").nth(1).unwrap_or_else(|| panic!("{preset}: no paper table\n{md}"));
        let lines = table.lines().filter(|l| l.starts_with("| ") && !l.starts_with("| scene")).count();
        assert_eq!(lines, if preset == "klehm-scenes" { scenes } else { rows }, "{preset}: {table}");
        if preset == "klehm-table2" {
            // The paper's Memory column: columns · rows · M bytes.
            for x in recs {
                let s = &x["settings"];
                let (w, h, m) = (
                    s["map_size"][0].as_f64().unwrap(),
                    s["map_size"][1].as_f64().unwrap(),
                    s["bases"].as_f64().unwrap(),
                );
                assert_eq!(x["extra"]["basis_bytes"].as_f64().unwrap(), w * h * m, "{x}");
            }
            assert!(table.contains("| 4096×1024 | 32 |") && table.contains("| 128.0 |"), "{table}");
        }
        if preset == "klehm-table1" {
            assert!(
                table.contains("| 1 | 32 |") && table.contains("+0 % (+0 %)"),
                "the naive row is the reference: {table}"
            );
            assert!(d.join(preset).join("time_vs_bases_per_thread_forest_32x18.svg").exists());
        }
    }
}

#[test]
fn compare_writes_a_contact_sheet_and_reports() {
    let d = tmp("compare");
    let out = bin()
        .args(["compare", "stained-glass", "--backend", "cpu", "--size", "64x36", "--reference-steps", "32"])
        .args(["--techniques", "brute-force,interleaved,subsampled", "--repeat", "1", "--output"])
        .arg(&d)
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let sheet = image::open(d.join("sheet.png")).unwrap();
    // Four rows (reference + 3) of 64-pixel-wide tiles, three columns.
    assert!(sheet.width() >= 3 * 64 && sheet.height() >= 4 * 36, "{}x{}", sheet.width(), sheet.height());
    let r: serde_json::Value = serde_json::from_slice(&std::fs::read(d.join("report.json")).unwrap()).unwrap();
    assert_eq!(r["records"].as_array().unwrap().len(), 3);
    let md = std::fs::read_to_string(d.join("report.md")).unwrap();
    assert!(md.contains("interleaved") && md.contains("sheet.png"), "{md}");
}

#[test]
fn debug_views_are_written_for_their_techniques_and_refused_for_others() {
    let d = tmp("debug-views");
    for (technique, view, size) in [
        ("epipolar", "classification", (64, 36)),
        ("epipolar", "radiance", (0, 0)),
        ("interleaved", "pattern", (64, 36)),
        ("minmax", "nodes", (64, 36)),
    ] {
        let out = d.join(format!("{technique}.png"));
        let r = bin()
            .args([
                "render",
                "stained-glass",
                "--backend",
                "cpu",
                "--size",
                "64x36",
                "-t",
                technique,
                "--debug",
                view,
                "-o",
            ])
            .arg(&out)
            .output()
            .unwrap();
        assert!(r.status.success(), "{technique} {view}: {}", String::from_utf8_lossy(&r.stderr));
        let p = out.with_extension(format!("{view}.png"));
        let img = image::open(&p).unwrap_or_else(|e| panic!("{}: {e}", p.display()));
        if size != (0, 0) {
            assert_eq!((img.width(), img.height()), size, "{view} has the frame's size");
        } else {
            assert!(
                img.width() >= 256 && img.height() >= 256,
                "the radiance texture is scaled up: {}×{}",
                img.width(),
                img.height()
            );
        }
        // The view is not the plain image: it draws over it.
        let plain = image::open(&out).unwrap().to_rgb8();
        if size != (0, 0) {
            assert_ne!(plain.as_raw(), img.to_rgb8().as_raw(), "{view} draws nothing");
        }
    }
    let r = bin()
        .args(["render", "colonnade", "--backend", "cpu", "--size", "32x18", "--debug", "pattern", "-o"])
        .arg(d.join("bf.png"))
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&r.stderr);
    assert!(!r.status.success() && err.contains("not a debug view of `brute-force`"), "{err}");
    assert!(!d.join("bf.png").exists(), "refused before rendering");
}

/// Scene options after the name (`render::load_scene`): `:lights=N` and `:shadow_filter=…`,
/// in either order, each changing what it names; a bad value is an error naming it.
#[test]
fn scene_options_combine_and_bad_ones_are_named() {
    use crepuscular::ShadowFilter;
    use crepuscular_cli::render::load_scene;
    let plain = load_scene("night-street").unwrap();
    assert_eq!(plain.render.shadow.filter, ShadowFilter::Bilinear, "the default");
    assert!(plain.lights.len() > 2);
    for name in ["night-street:lights=2:shadow_filter=nearest", "night-street:shadow_filter=nearest:lights=2"] {
        let s = load_scene(name).unwrap();
        assert_eq!(s.lights.len(), 2, "{name}");
        assert_eq!(s.render.shadow.filter, ShadowFilter::Nearest, "{name}");
        let desc = crepuscular_cli::render::frame_desc(&s).unwrap();
        assert!(desc.lights.iter().all(|l| l.shadow_filter == ShadowFilter::Nearest), "{name}: reaches the frame");
    }
    let e = load_scene("night-street:shadow_filter=pcf").unwrap_err().to_string();
    assert!(e.contains("night-street:shadow_filter=pcf") && e.contains("\"pcf\"") && e.contains("bilinear"), "{e}");
    let e = load_scene("night-street:lights=x").unwrap_err().to_string();
    assert!(e.contains("lights=") && e.contains("`x`"), "{e}");
    // Too many lights: the error gives the range to keep (it once printed the scene's name
    // where the count belongs).
    let n = plain.lights.len();
    let e = load_scene(&format!("night-street:lights={}", n + 1)).unwrap_err().to_string();
    assert!(e.contains(&format!("has {n} light(s); keep 0 to {n}")), "{e}");
}
