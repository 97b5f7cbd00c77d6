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

/// `exe` found on PATH.
fn on_path(exe: &str) -> Option<PathBuf> {
    let paths = std::env::var_os("PATH")?;
    std::env::split_paths(&paths).map(|p| p.join(exe)).find(|p| p.is_file())
}

fn xvfb_run() -> Option<PathBuf> {
    on_path("xvfb-run")
}

/// `xvfb-run -a` with a 1280×720 screen; the program and its arguments follow.
fn xvfb_command(xvfb: &Path) -> Command {
    let mut c = Command::new(xvfb);
    c.args(["-a", "-s", "-screen 0 1280x720x24"]);
    // The Vulkan loader wants a runtime dir on headless machines.
    if std::env::var_os("XDG_RUNTIME_DIR").is_none() {
        let d = std::env::temp_dir().join(format!("crepuscular-xdg-{}", std::process::id()));
        let _ = std::fs::create_dir_all(&d);
        c.env("XDG_RUNTIME_DIR", d);
    }
    c
}

/// `crepuscular` run under `xvfb-run -a` with a 1280×720 screen.
fn under_xvfb(xvfb: &Path) -> Command {
    let mut c = xvfb_command(xvfb);
    c.arg(env!("CARGO_BIN_EXE_crepuscular"));
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
        ("minmax", "stained-glass", Some("map_size=[256, 256]")),
        // Several lights (six lamps, a lantern and the moon): one march for all of them.
        ("brute-force", "night-street", None),
    ] {
        let png = d.join(format!("{technique}-{scene}.png"));
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
        // The screenshot's state lists every light of the scene.
        let state: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(png.with_extension("json")).unwrap()).unwrap();
        let lights = crepuscular_scene::builtin::builtin(scene).unwrap().lights.len();
        assert_eq!(state["lights"].as_array().map(|l| l.len()), Some(lights), "{technique} on {scene}: {state}");
    }
    // The temporal stage on (`--temporal`): the frame goes through its pass, the state names
    // its settings, and after a few jittered frames the picture is the same scene.
    let png = d.join("temporal.png");
    let out = under_xvfb(&xvfb)
        .args(["view", "colonnade", "--size", "320x180", "--scale", "1", "--temporal", "--screenshot-after", "4"])
        .arg("--output")
        .arg(&png)
        .output()
        .unwrap();
    let log = text(&out);
    assert!(out.status.success(), "{test}: view --temporal failed under xvfb-run: {log}");
    let state: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(png.with_extension("json")).unwrap()).unwrap();
    assert_eq!(state["temporal"]["history_weight"].as_f64().map(|w| (w * 100.0).round()), Some(90.0), "{state}");
    let passes: Vec<&str> =
        state["stats"]["passes"].as_array().unwrap().iter().filter_map(|p| p["name"].as_str()).collect();
    assert!(passes.contains(&"temporal"), "no temporal pass in {passes:?}");
    let (a, b) =
        (image::open(&png).unwrap().to_rgb8(), image::open(d.join("brute-force-colonnade.png")).unwrap().to_rgb8());
    let mean = a.as_raw().iter().zip(b.as_raw()).map(|(x, y)| x.abs_diff(*y) as f64).sum::<f64>() / a.len() as f64;
    eprintln!("view --temporal after 4 frames vs the plain frame: mean {mean:.2} levels");
    assert!(mean > 0.0 && mean < 3.0, "the temporal view is not the same scene (or not resolved at all): {mean}");

    // The scene image is the tone-mapped final image `render` writes for the same frame.
    let r = d.join("render.png");
    let out = bin()
        .args(["render", "colonnade", "--backend", "gpu", "--size", "320x180", "--output"])
        .arg(&r)
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", text(&out));
    let (a, b) =
        (image::open(&r).unwrap().to_rgb8(), image::open(d.join("brute-force-colonnade.png")).unwrap().to_rgb8());
    // The same pixels up to float rounding: the GPU's exp/pow and the 8-bit conversion differ
    // from the CPU's in the last bits, which a steep tone curve can turn into a few levels at
    // a handful of pixels.
    let diff: Vec<u8> = a.as_raw().iter().zip(b.as_raw()).map(|(x, y)| x.abs_diff(*y)).collect();
    let mean = diff.iter().map(|&d| d as f64).sum::<f64>() / diff.len() as f64;
    let over = diff.iter().filter(|&&d| d > 2).count();
    assert!(mean < 0.25 && over * 1000 < diff.len(), "view vs render: mean {mean} levels, {over} channels > 2");
}

/// Drives the viewer in a real window with X input events (xdotool: the X server's XTEST
/// extension, the same path a physical mouse and keyboard take through winit and egui-winit).
/// After each gesture F12 saves a screenshot and its JSON view state. The pauses spread each
/// gesture over several frames (a frame takes ~0.15 s here on llvmpipe), as a hand would.
const DRIVE_SCRIPT: &str = r#"
set -u
bin="$1"; d="$2"
"$bin" view colonnade --size 960x540 --scale 0.25 --output "$d/shot.png" >"$d/log" 2>&1 &
pid=$!
trap 'kill $pid 2>/dev/null; wait $pid 2>/dev/null' EXIT
wid=$(timeout 120 xdotool search --sync --onlyvisible --name '^crepuscular' | head -1)
[ -n "$wid" ] || { echo "no viewer window appeared"; cat "$d/log"; exit 1; }
xdotool windowfocus --sync "$wid" 2>/dev/null || true
n=0
shot() {
    n=$((n + 1))
    xdotool key F12
    for _ in $(seq 1 1200); do
        [ -s "$d/shot-$n.json" ] && return 0
        kill -0 $pid 2>/dev/null || { echo "viewer exited"; cat "$d/log"; exit 1; }
        sleep 0.1
    done
    echo "screenshot $n never came"; cat "$d/log"; exit 1
}
# drag BUTTON DX DY: press in the middle of the scene (clear of the panels), move in steps.
drag() {
    xdotool mousemove --window "$wid" 480 300; sleep 0.3
    xdotool mousedown "$1"; sleep 0.3
    for k in 1 2 3 4 5 6; do
        xdotool mousemove --window "$wid" $((480 + $2 * k / 6)) $((300 + $3 * k / 6)); sleep 0.3
    done
    xdotool mouseup "$1"; sleep 0.5
}
shot                                  # 1: as loaded
drag 1 60 0; shot                     # 2: left drag right: orbit
drag 3 60 -40; shot                   # 3: right drag: the sun turns
xdotool keydown w; sleep 1; xdotool keyup w; sleep 0.5; shot     # 4: fly forward
xdotool mousemove --window "$wid" 480 300
for _ in 1 2 3 4 5; do xdotool click 4; sleep 0.3; done; sleep 0.5; shot   # 5: wheel: dolly in
xdotool key n; sleep 1; shot          # 6: next built-in scene
xdotool key t; sleep 1; shot          # 7: next technique
cat "$d/log"
"#;

#[test]
fn view_follows_real_mouse_and_keyboard_events_under_xvfb() {
    let test = "view_follows_real_mouse_and_keyboard_events_under_xvfb";
    let (Some(xvfb), Some(_)) = (xvfb_run(), on_path("xdotool")) else {
        eprintln!("SKIPPED {test}: xvfb-run or xdotool is not installed (apt-get install xvfb xdotool)");
        return;
    };
    if let Err(e) = has_adapter() {
        assert!(!require_gpu(), "{test}: CREPUSCULAR_REQUIRE_GPU=1 but no adapter: {e}");
        eprintln!("SKIPPED {test}: no GPU adapter ({e})");
        return;
    }
    let d = tmp("drive");
    let out = xvfb_command(&xvfb)
        .args(["timeout", "600", "bash", "-c", DRIVE_SCRIPT, "drive"])
        .arg(env!("CARGO_BIN_EXE_crepuscular"))
        .arg(&d)
        .output()
        .unwrap();
    let log = text(&out);
    assert!(out.status.success(), "{test}: {log}");
    assert!(!log.contains("panicked"), "{log}");
    let state = |n: u32| -> serde_json::Value {
        let p = d.join(format!("shot-{n}.json"));
        serde_json::from_slice(&std::fs::read(&p).unwrap_or_else(|e| panic!("{}: {e}\n{log}", p.display()))).unwrap()
    };
    let v = |j: &serde_json::Value| -> [f64; 3] {
        let a = j.as_array().unwrap_or_else(|| panic!("not a vector: {j}"));
        [0, 1, 2].map(|k| a[k].as_f64().unwrap())
    };
    let sub = |a: [f64; 3], b: [f64; 3]| [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
    let dot = |a: [f64; 3], b: [f64; 3]| a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
    let len = |a: [f64; 3]| dot(a, a).sqrt();
    let s: Vec<serde_json::Value> = (1..=7).map(state).collect();
    let (pos, at) = (|k: usize| v(&s[k]["camera"]["position"]), |k: usize| v(&s[k]["camera"]["look_at"]));
    let sun = |k: usize| v(&s[k]["light"]["direction"]);
    eprintln!("{test}: camera positions {:?}", (0..7).map(pos).collect::<Vec<_>>());
    // 1 → 2, left drag: the camera orbits its target; the light stays.
    assert!(len(sub(pos(1), pos(0))) > 0.05, "left drag did not move the camera");
    assert!(len(sub(at(1), at(0))) < 1e-4, "left drag moved the orbit target");
    assert!((len(sub(pos(1), at(1))) - len(sub(pos(0), at(0)))).abs() < 1e-3, "orbiting changed the distance");
    assert_eq!(s[1]["light"], s[0]["light"], "left drag moved the light");
    // 2 → 3, right drag: the sun turns; the camera stays.
    assert!(dot(sun(2), sun(1)) < 0.999, "right drag did not turn the sun: {:?} → {:?}", sun(1), sun(2));
    assert_eq!(s[2]["camera"], s[1]["camera"], "right drag moved the camera");
    // 3 → 4, W held: camera and target move forward together.
    let fwd = sub(at(2), pos(2));
    let moved = sub(at(3), at(2));
    assert!(dot(moved, fwd) / len(fwd) > 0.05, "W did not fly forward: moved {moved:?}");
    assert!(len(sub(sub(pos(3), pos(2)), moved)) < 1e-3, "W changed the view direction");
    // 4 → 5, wheel up: dolly towards the target.
    assert!(len(sub(pos(4), at(4))) < 0.95 * len(sub(pos(3), at(3))), "the wheel did not dolly in");
    // 5 → 6, N: the next built-in scene; 6 → 7, T: the next technique.
    assert_eq!((s[4]["scene"].as_str(), s[5]["scene"].as_str()), (Some("colonnade"), Some("forest")));
    // ... with forest's own camera (the rest of the wheel turn does not move it).
    let forest = crepuscular_scene::builtin::builtin("forest").unwrap().camera.position;
    let p = pos(5);
    assert!(
        (p[0] - forest.x as f64).abs() + (p[1] - forest.y as f64).abs() + (p[2] - forest.z as f64).abs() < 1e-4,
        "the new scene's camera moved: {p:?} vs {forest}"
    );
    assert_ne!(s[6]["technique"], s[5]["technique"], "T did not switch the technique");
    assert_eq!(s[6]["stats"]["technique"], s[6]["technique"], "the frame after T was not rendered with it");
    // The screenshots show it: each gesture changed the image.
    let img = |n: u32| image::open(d.join(format!("shot-{n}.png"))).unwrap().to_rgb8();
    for n in 1..7 {
        assert_ne!(img(n).as_raw(), img(n + 1).as_raw(), "shot {n} and {} are the same image", n + 1);
    }
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
