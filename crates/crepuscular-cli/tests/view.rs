//! `crepuscular view`: a real window under Xvfb (when xvfb-run and a GPU adapter exist) that
//! renders a few frames and saves the scene image; clean one-line failures without a display
//! or without an adapter; `render --preset`.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn bin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_crepuscular"))
}

fn tmp(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("crepuscular-view-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn require_gpu() -> bool {
    std::env::var("CREPUSCULAR_REQUIRE_GPU").is_ok_and(|v| v == "1")
}

fn xvfb_run() -> Option<PathBuf> {
    let paths = std::env::var_os("PATH")?;
    std::env::split_paths(&paths).map(|p| p.join("xvfb-run")).find(|p| p.is_file())
}

/// A command run under `xvfb-run -a` with a 1280×720 screen.
fn under_xvfb(xvfb: &Path) -> Command {
    let mut c = Command::new(xvfb);
    c.args(["-a", "-s", "-screen 0 1280x720x24"]).arg(env!("CARGO_BIN_EXE_crepuscular"));
    // The Vulkan loader wants a runtime dir on headless machines.
    if std::env::var_os("XDG_RUNTIME_DIR").is_none() {
        let d = std::env::temp_dir().join(format!("crepuscular-xdg-{}", std::process::id()));
        let _ = std::fs::create_dir_all(&d);
        c.env("XDG_RUNTIME_DIR", d);
    }
    c
}

fn text(out: &Output) -> String {
    format!("{}{}", String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr))
}

fn has_adapter() -> Result<(), String> {
    let out = bin().arg("adapter").output().unwrap();
    if out.status.success() { Ok(()) } else { Err(text(&out).trim().to_string()) }
}

#[test]
fn view_renders_frames_under_xvfb_and_saves_the_scene_image() {
    let test = "view_renders_frames_under_xvfb_and_saves_the_scene_image";
    let Some(xvfb) = xvfb_run() else {
        eprintln!("SKIPPED {test}: xvfb-run is not installed (apt-get install xvfb)");
        return;
    };
    if let Err(e) = has_adapter() {
        assert!(!require_gpu(), "{test}: CREPUSCULAR_REQUIRE_GPU=1 but no adapter: {e}");
        eprintln!("SKIPPED {test}: no GPU adapter ({e})");
        return;
    }
    let d = tmp("shot");
    // prefiltered with a small map, so the software adapter's prefilter stays quick.
    for (technique, scene, set) in [
        ("brute-force", "colonnade", None),
        ("epipolar", "cage", None),
        ("prefiltered", "forest", Some("map_size=[256, 256]")),
    ] {
        let png = d.join(format!("{technique}.png"));
        let mut cmd = under_xvfb(&xvfb);
        cmd.args(["view", scene, "--technique", technique, "--size", "320x180", "--scale", "1"]);
        if let Some(kv) = set {
            cmd.args(["--set", kv]);
        }
        let out = cmd.args(["--screenshot-after", "3", "--output"]).arg(&png).output().unwrap();
        let log = text(&out);
        assert!(out.status.success(), "{test}: view {technique} failed under xvfb-run: {log}");
        assert!(!log.contains("panicked"), "{log}");
        let img = image::open(&png).unwrap_or_else(|e| panic!("{}: {e}", png.display())).to_rgb8();
        assert_eq!(img.dimensions(), (320, 180));
        let mean: f64 =
            img.pixels().map(|p| p.0.iter().map(|&c| c as f64).sum::<f64>()).sum::<f64>() / (320.0 * 180.0 * 3.0);
        assert!(mean > 5.0, "{technique}: the scene image is black (mean {mean})");
    }
    // The scene image is the tone-mapped final image `render` writes for the same frame.
    let r = d.join("render.png");
    let out = bin()
        .args(["render", "colonnade", "--backend", "gpu", "--size", "320x180", "--output"])
        .arg(&r)
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", text(&out));
    let (a, b) = (image::open(&r).unwrap().to_rgb8(), image::open(d.join("brute-force.png")).unwrap().to_rgb8());
    // The same pixels up to float rounding: the GPU's exp/pow and the 8-bit conversion differ
    // from the CPU's in the last bits, which a steep tone curve can turn into a few levels at
    // a handful of pixels.
    let diff: Vec<u8> = a.as_raw().iter().zip(b.as_raw()).map(|(x, y)| x.abs_diff(*y)).collect();
    let mean = diff.iter().map(|&d| d as f64).sum::<f64>() / diff.len() as f64;
    let over = diff.iter().filter(|&&d| d > 2).count();
    assert!(mean < 0.25 && over * 1000 < diff.len(), "view vs render: mean {mean} levels, {over} channels > 2");
}

#[test]
fn view_without_a_display_fails_with_one_line() {
    let out = bin()
        .args(["view", "colonnade", "--screenshot-after", "1"])
        .env_remove("DISPLAY")
        .env_remove("WAYLAND_DISPLAY")
        .output()
        .unwrap();
    let log = text(&out);
    assert!(!out.status.success(), "{log}");
    assert!(log.contains("error: view: no display"), "{log}");
    assert!(!log.contains("panicked"), "{log}");
}

#[test]
fn view_without_an_adapter_fails_with_one_line() {
    let test = "view_without_an_adapter_fails_with_one_line";
    let Some(xvfb) = xvfb_run() else {
        eprintln!("SKIPPED {test}: xvfb-run is not installed");
        return;
    };
    // A display, but no Vulkan driver and no other backend: no adapter at all.
    let out = under_xvfb(&xvfb)
        .args(["view", "colonnade", "--size", "64x36", "--screenshot-after", "1", "--output"])
        .arg(tmp("noadapter").join("x.png"))
        .env("WGPU_BACKEND", "vulkan")
        .env("VK_ICD_FILENAMES", "/nonexistent/icd.json")
        .env("VK_DRIVER_FILES", "/nonexistent/icd.json")
        .output()
        .unwrap();
    let log = text(&out);
    assert!(!out.status.success(), "{log}");
    assert!(log.contains("error: view:"), "{log}");
    assert!(!log.contains("panicked"), "{log}");
}

#[test]
fn view_refuses_cpu_only_techniques_and_bad_flags_before_opening_a_window() {
    for args in [
        &["view", "--technique", "reference"][..],
        &["view", "--set", "steps=0"],
        &["view", "--scale", "0"],
        &["view", "--screenshot-after", "0"],
        &["view", "--preset", "ultra"],
    ] {
        let out = bin().args(args).env_remove("DISPLAY").output().unwrap();
        let log = text(&out);
        assert!(!out.status.success(), "{args:?}: {log}");
        assert!(!log.contains("no display") && !log.contains("panicked"), "{args:?}: {log}");
    }
}

#[test]
fn render_preset_chooses_the_presets_settings_and_set_overrides_it() {
    let d = tmp("preset");
    for (preset, extra, steps) in [("fast", None, 32), ("reference-like", None, 256), ("fast", Some("steps=48"), 48)] {
        let stats = d.join(format!("{preset}-{steps}.json"));
        let mut c = bin();
        c.args(["render", "colonnade", "--backend", "cpu", "--size", "32x18", "--shadow-map-size", "256"])
            .args(["--preset", preset, "--output"])
            .arg(d.join("x.png"))
            .arg("--stats")
            .arg(&stats);
        if let Some(e) = extra {
            c.args(["--set", e]);
        }
        let out = c.output().unwrap();
        assert!(out.status.success(), "{}", text(&out));
        let s: serde_json::Value = serde_json::from_slice(&std::fs::read(&stats).unwrap()).unwrap();
        assert_eq!(s["settings"]["steps"], steps, "{preset} {extra:?}");
    }
}
