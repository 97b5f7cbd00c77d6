//! `crepuscular view`: an interactive window (winit + egui) that renders a scene every frame
//! with a technique on the GPU — the same host renderer and technique runners as `render`
//! ([`crate::render`]) — with an orbit/fly camera, a movable light, the medium and every
//! setting of the technique editable live, the per-pass timings, debug views, an error view
//! against `reference` and screenshots.
//!
//! Per frame: the host renderer draws the shadow map, depth and surface; the technique writes
//! its in-scattering; the library's composite ([`crepuscular::Composite`]) adds
//! T(s)·L_surface + L_scatt and tone-maps exactly as `render` does, into an `Rgba8Unorm`
//! texture that egui draws behind its panels. The technique's pipelines are built
//! once and rebuilt only when its settings change; the scene is re-rendered only when
//! something changed (camera, light, medium, settings, size) unless "continuous" is on.

use crate::metrics;
use crate::output;
use crate::render::{self, DebugView};
use anyhow::{Context, Result, anyhow, bail};
use crepuscular::frame::{FrameDesc, surface_transmittance};
use crepuscular::gpu::GpuContext;
use crepuscular::stats::{PassTime, TechniqueStats};
use crepuscular::techniques::presets::Preset;
use crepuscular::techniques::reference::{self, ReferenceSettings};
use crepuscular::tonemap::{ToneMap, composite};
use crepuscular::{CpuFrame, Image, Light, Phase};
use crepuscular::{Scattering, TechniqueSettings};
use crepuscular_scene::{GpuHost, HostTextures, Scene, host};
use glam::{Quat, Vec3};
use std::collections::VecDeque;
use std::path::PathBuf;
use std::sync::Arc;
use std::time::{Duration, Instant};
use winit::application::ApplicationHandler;
use winit::event::WindowEvent;
use winit::event_loop::{ActiveEventLoop, ControlFlow, EventLoop};
use winit::window::{Window, WindowId};

mod controls;
mod frame;
mod panels;
use controls::Controls;
use panels::*;

/// Default window size.
pub const DEFAULT_SIZE: (u32, u32) = (960, 540);

/// Seconds of history in the timing graph.
const HISTORY_S: f64 = 5.0;

/// Options of `crepuscular view`.
#[derive(Clone, Debug)]
pub struct ViewOptions {
    /// Built-in scene name or scene file.
    pub scene: String,
    /// Technique name (a GPU technique).
    pub technique: String,
    /// A preset applied before `overrides` (over the scene's `[render.<technique>]` table).
    pub preset: Option<Preset>,
    /// `key=value` settings of the technique (TOML values).
    pub overrides: Vec<String>,
    /// Window inner size, physical pixels.
    pub size: (u32, u32),
    /// Render scale: the scene is rendered at window size × scale (None: 1 on a hardware
    /// adapter, 0.5 on a software one).
    pub scale: Option<f32>,
    /// Shadow-map size override.
    pub shadow_map_size: Option<u32>,
    /// Render this many frames, save the scene image to `output` and exit.
    pub screenshot_after: Option<u32>,
    /// Screenshot path (F12 / P write `<stem>-<n>.png` beside it).
    pub output: PathBuf,
    /// Start with the temporal stage on (a checkbox in the tools panel).
    pub temporal: bool,
}

// The doc comment of every field of every technique's settings struct, collected by build.rs
// from the library's sources: (technique, field, doc).
include!(concat!(env!("OUT_DIR"), "/setting_docs.rs"));

/// Known values of string-valued settings, for a combo box.
const ENUM_VALUES: &[(&str, &[&str])] = &[
    ("spot_steps", &["fixed", "exact-cone", "appendix-b-constant", "appendix-b-smoothstep"]),
    ("local_steps", &["equiangular", "uniform"]),
    ("weighting", &["gaussian", "shepard", "threshold"]),
    ("precision", &["unorm8", "float16"]),
    ("rectification", &["auto", "projective", "epipolar"]),
    ("reference_ray", &["bisectrix", "optimal"]),
];

/// The tooltip of a technique's setting: the doc comment of its field in the library.
pub fn setting_doc(technique: &str, key: &str) -> Option<&'static str> {
    GENERATED_SETTING_DOCS.iter().find(|(t, k, _)| *t == technique && *k == key).map(|e| e.2)
}

/// Fails with one line when there is no display to open a window on.
pub fn check_display() -> Result<()> {
    if cfg!(all(unix, not(target_os = "macos"))) {
        let set = |v: &str| std::env::var_os(v).is_some_and(|s| !s.is_empty());
        if !set("DISPLAY") {
            if set("WAYLAND_DISPLAY") {
                bail!(
                    "view: no X11 display (DISPLAY is not set; this build talks X11 only — run it under XWayland or xvfb-run)"
                );
            }
            bail!("view: no display (DISPLAY is not set); on a headless machine run it under `xvfb-run -a`");
        }
    }
    Ok(())
}

/// The `key=value` overrides that select `preset` for `technique` (empty for an unknown one).
pub fn preset_overrides(preset: Preset, technique: &str) -> Vec<String> {
    let Some(settings) = preset.settings(technique) else { return Vec::new() };
    match serde_json::to_value(&settings) {
        Ok(serde_json::Value::Object(m)) => json_overrides(&m),
        _ => Vec::new(),
    }
}

/// `key=value` overrides (TOML values) for the fields of a serialised settings object; nulls
/// (unset options) and the `technique` tag are left out.
pub fn json_overrides(fields: &serde_json::Map<String, serde_json::Value>) -> Vec<String> {
    fields
        .iter()
        .filter(|(k, _)| *k != "technique")
        .filter_map(|(k, v)| Some(format!("{k}={}", toml_literal(v)?)))
        .collect()
}

fn toml_literal(v: &serde_json::Value) -> Option<String> {
    use serde_json::Value as J;
    Some(match v {
        J::Null => return None,
        J::Bool(b) => b.to_string(),
        J::Number(n) => n.to_string(),
        J::String(s) => toml::Value::String(s.clone()).to_string(),
        other => toml::Value::try_from(other).ok()?.to_string(),
    })
}

/// Parses a technique with an optional preset and overrides, as the viewer and `render
/// --preset` do: the scene's table, then the preset, then the overrides.
pub fn parse_technique(
    name: &str,
    scene: &Scene,
    preset: Option<Preset>,
    overrides: &[String],
) -> Result<TechniqueSettings> {
    let mut all = preset.map(|p| preset_overrides(p, name)).unwrap_or_default();
    all.extend_from_slice(overrides);
    render::parse_technique(name, scene, &all)
}

/// A technique from a preset and `key=value` overrides over it, without a scene's table.
pub fn parse_preset_technique(name: &str, preset: Preset, overrides: &[String]) -> Result<TechniqueSettings> {
    let mut all = preset_overrides(preset, name);
    all.extend_from_slice(overrides);
    render::parse_technique_table(name, toml::Table::new(), &format!("the {} preset of {name}", preset.name()), &all)
}

/// Runs the viewer until the window is closed (or `screenshot_after` frames were rendered).
pub fn run(opts: ViewOptions) -> Result<()> {
    let mut scene = render::load_scene(&opts.scene)?;
    if let Some(s) = opts.shadow_map_size {
        if s == 0 || s > 16384 {
            bail!("--shadow-map-size {s}: must be in 1..=16384");
        }
        scene.render.shadow.size = s;
    }
    let (w, h) = opts.size;
    if w == 0 || h == 0 || w > 8192 || h > 8192 {
        bail!("--size {w}x{h}: width and height must be in 1..=8192");
    }
    if let Some(s) = opts.scale
        && !(s.is_finite() && (0.05..=2.0).contains(&s))
    {
        bail!("--scale {s}: must be in 0.05..=2");
    }
    if opts.screenshot_after == Some(0) {
        bail!("--screenshot-after 0: must be ≥ 1");
    }
    let technique = parse_technique(&opts.technique, &scene, opts.preset, &opts.overrides)?;
    if !crepuscular::techniques::find(technique.name()).is_some_and(|t| t.gpu) {
        bail!(
            "view: `{}` runs on the CPU only; pick a GPU technique (the viewer's error view compares against it)",
            technique.name()
        );
    }
    check_display()?;
    let event_loop = EventLoop::new().map_err(|e| anyhow!("view: cannot connect to the display: {e}"))?;
    event_loop.set_control_flow(ControlFlow::Wait);
    let mut app = App { opts, scene: Some(scene), technique: Some(technique), viewer: None, error: None };
    event_loop.run_app(&mut app).map_err(|e| anyhow!("view: event loop: {e}"))?;
    match app.error {
        Some(e) => Err(e),
        None => Ok(()),
    }
}

struct App {
    opts: ViewOptions,
    scene: Option<Scene>,
    technique: Option<TechniqueSettings>,
    viewer: Option<Viewer>,
    error: Option<anyhow::Error>,
}

impl ApplicationHandler for App {
    fn resumed(&mut self, event_loop: &ActiveEventLoop) {
        if self.viewer.is_some() || self.error.is_some() {
            return;
        }
        let (Some(scene), Some(technique)) = (self.scene.take(), self.technique.take()) else { return };
        match Viewer::new(event_loop, &self.opts, scene, technique) {
            Ok(v) => {
                v.window.request_redraw();
                self.viewer = Some(v);
            }
            Err(e) => {
                self.error = Some(e);
                event_loop.exit();
            }
        }
    }

    fn window_event(&mut self, event_loop: &ActiveEventLoop, _id: WindowId, event: WindowEvent) {
        let Some(v) = self.viewer.as_mut() else { return };
        let response = v.egui_state.on_window_event(&v.window, &event);
        match event {
            WindowEvent::CloseRequested => event_loop.exit(),
            WindowEvent::Resized(size) => {
                v.resize(size.width, size.height);
                v.window.request_redraw();
            }
            WindowEvent::RedrawRequested => match v.redraw() {
                Ok(Flow::Continue) => {}
                Ok(Flow::Exit) => event_loop.exit(),
                Err(e) => {
                    self.error = Some(e);
                    event_loop.exit();
                }
            },
            _ => {
                if response.repaint {
                    v.window.request_redraw();
                }
            }
        }
    }

    fn about_to_wait(&mut self, _event_loop: &ActiveEventLoop) {
        if let Some(v) = &self.viewer
            && v.wants_redraw()
        {
            v.window.request_redraw();
        }
    }
}

enum Flow {
    Continue,
    Exit,
}

/// One rendered frame's timings.
struct FrameTiming {
    at: Instant,
    passes: Vec<PassTime>,
    wall_ms: f64,
}

/// The textures of the current render size.
struct Targets {
    width: u32,
    height: u32,
    inscatter: wgpu::Texture,
    /// The temporal stage's output (what the composite reads while the stage is on).
    resolved: wgpu::Texture,
    display: wgpu::Texture,
}

/// An image shown in a window of its own (debug view, error map).
struct Shown {
    title: String,
    caption: String,
    texture: egui::TextureHandle,
    open: bool,
}

struct Viewer {
    window: Arc<Window>,
    surface: wgpu::Surface<'static>,
    config: wgpu::SurfaceConfiguration,
    gpu: GpuContext,
    egui_ctx: egui::Context,
    egui_state: egui_winit::State,
    renderer: egui_wgpu::Renderer,
    host: GpuHost,
    composite: crepuscular::Composite,
    targets: Option<Targets>,
    display_id: Option<egui::TextureId>,
    /// The scene as loaded; camera, light and medium below override it.
    scene: Scene,
    controls: Controls,
    medium: crepuscular::Medium,
    exposure: f32,
    scale: f32,
    technique: TechniqueSettings,
    runner: Option<Scattering>,
    /// The temporal stage (docs/MODEL.md §7), while it is on: the technique then runs with its
    /// `jitter` on and its `frame_index` advanced every frame, and the view renders
    /// continuously so the history accumulates.
    temporal: Option<crepuscular::Temporal>,
    /// How many times a technique's pipelines were built (a settings change does not rebuild
    /// them; a technique switch or a new scene does), and how long the last build took.
    runner_builds: u32,
    runner_build_ms: f64,
    /// `--shadow-map-size`, kept for scenes opened in the window.
    shadow_map_size: Option<u32>,
    /// The scene-file field of the scene panel.
    scene_path: String,
    /// The settings as edited (serde_json object of the technique's fields).
    fields: serde_json::Map<String, serde_json::Value>,
    /// TOML text of the fields that are unset options or not scalars.
    text_fields: std::collections::BTreeMap<String, String>,
    settings_error: Option<String>,
    render_error: Option<String>,
    preset: Option<Preset>,
    continuous: bool,
    dirty: bool,
    last_host: Option<(HostTextures, FrameDesc)>,
    last_stats: Option<TechniqueStats>,
    history: VecDeque<FrameTiming>,
    frames_rendered: u32,
    screenshot_after: Option<u32>,
    output: PathBuf,
    screenshots: u32,
    status: String,
    shown: Vec<Shown>,
    pending: Vec<Action>,
    reference_steps: u32,
    keys_down: bool,
    last_frame: Instant,
}

/// Work the UI asks for, done after the scene is rendered.
enum Action {
    Screenshot,
    Debug(DebugView),
    ErrorView,
    HistoryWeight,
}

impl Viewer {
    fn new(
        event_loop: &ActiveEventLoop,
        opts: &ViewOptions,
        scene: Scene,
        technique: TechniqueSettings,
    ) -> Result<Self> {
        let (w, h) = opts.size;
        let attrs = Window::default_attributes()
            .with_title(format!("crepuscular — {} — {}", scene.name, technique.name()))
            .with_inner_size(winit::dpi::PhysicalSize::new(w, h));
        let window = Arc::new(event_loop.create_window(attrs).map_err(|e| anyhow!("view: cannot open a window: {e}"))?);
        let mut desc = wgpu::InstanceDescriptor::new_without_display_handle();
        desc.backends = wgpu::Backends::from_env().unwrap_or(wgpu::Backends::PRIMARY | wgpu::Backends::GL);
        desc.display = Some(Box::new(event_loop.owned_display_handle()));
        let instance = wgpu::Instance::new(desc);
        let surface = instance.create_surface(window.clone()).map_err(|e| {
            anyhow!("view: no GPU adapter can present to this window (creating the surface failed: {e})")
        })?;
        let adapter = pollster::block_on(instance.request_adapter(&wgpu::RequestAdapterOptions {
            power_preference: wgpu::PowerPreference::HighPerformance,
            force_fallback_adapter: false,
            compatible_surface: Some(&surface),
        }))
        .map_err(|e| anyhow!("view: no GPU adapter that can present to a window ({e}); the viewer needs one"))?;
        let adapter_for_caps = adapter.clone();
        let gpu = GpuContext::from_adapter(adapter).context("view")?;
        let caps = surface.get_capabilities(&adapter_for_caps);
        let format = caps
            .formats
            .iter()
            .copied()
            .find(|f| matches!(f, wgpu::TextureFormat::Bgra8Unorm | wgpu::TextureFormat::Rgba8Unorm))
            .or_else(|| caps.formats.first().copied())
            .ok_or_else(|| anyhow!("view: the adapter cannot present to this window (no surface formats)"))?;
        let size = window.inner_size();
        let present_mode = if caps.present_modes.contains(&wgpu::PresentMode::Fifo) {
            wgpu::PresentMode::Fifo
        } else {
            caps.present_modes.first().copied().unwrap_or(wgpu::PresentMode::Fifo)
        };
        // COPY_SRC where offered, for `CREPUSCULAR_VIEW_UI_SHOT` (a capture of the whole window).
        let usage = wgpu::TextureUsages::RENDER_ATTACHMENT | (caps.usages & wgpu::TextureUsages::COPY_SRC);
        let config = wgpu::SurfaceConfiguration {
            usage,
            format,
            width: size.width.max(1),
            height: size.height.max(1),
            present_mode,
            desired_maximum_frame_latency: 2,
            alpha_mode: caps.alpha_modes.first().copied().unwrap_or(wgpu::CompositeAlphaMode::Auto),
            view_formats: vec![],
        };
        gpu.scoped("configuring the window surface", || surface.configure(&gpu.device, &config))?;
        let egui_ctx = egui::Context::default();
        let max_side = gpu.device.limits().max_texture_dimension_2d as usize;
        let egui_state = egui_winit::State::new(
            egui_ctx.clone(),
            egui::ViewportId::ROOT,
            &window,
            Some(window.scale_factor() as f32),
            None,
            Some(max_side),
        );
        let renderer = egui_wgpu::Renderer::new(&gpu.device, format, egui_wgpu::RendererOptions::default());
        let host = GpuHost::for_scene(&gpu, &scene)?;
        let composite = crepuscular::Composite::new(&gpu.device)?;
        let built = Instant::now();
        let runner = render::scattering(&gpu, &technique)?;
        let runner_build_ms = built.elapsed().as_secs_f64() * 1e3;
        let scale = opts.scale.unwrap_or(if gpu.software { 0.5 } else { 1.0 });
        let fields = settings_fields(&technique);
        let temporal = if opts.temporal {
            Some(crepuscular::Temporal::new(&gpu.device, crepuscular::TemporalSettings::default())?)
        } else {
            None
        };
        eprintln!("view: `{}` with {} on {}", scene.name, technique.name(), gpu.describe());
        Ok(Self {
            controls: Controls::of(&scene),
            medium: scene.medium.clone(),
            exposure: scene.render.exposure,
            text_fields: text_fields(&fields),
            fields,
            window,
            surface,
            config,
            gpu,
            egui_ctx,
            egui_state,
            renderer,
            host,
            composite,
            targets: None,
            display_id: None,
            scene,
            scale,
            technique,
            runner,
            temporal,
            runner_builds: 1,
            runner_build_ms,
            shadow_map_size: opts.shadow_map_size,
            scene_path: String::new(),
            settings_error: None,
            render_error: None,
            preset: opts.preset,
            continuous: false,
            dirty: true,
            last_host: None,
            last_stats: None,
            history: VecDeque::new(),
            frames_rendered: 0,
            screenshot_after: opts.screenshot_after,
            output: opts.output.clone(),
            screenshots: 0,
            status: String::new(),
            shown: Vec::new(),
            pending: Vec::new(),
            reference_steps: 256,
            keys_down: false,
            last_frame: Instant::now(),
        })
    }

    fn wants_redraw(&self) -> bool {
        self.dirty
            || self.continuous
            || self.temporal.is_some()
            || self.screenshot_after.is_some()
            || self.keys_down
            || !self.pending.is_empty()
    }

    fn resize(&mut self, w: u32, h: u32) {
        if w == 0 || h == 0 {
            return;
        }
        self.config.width = w;
        self.config.height = h;
        self.surface.configure(&self.gpu.device, &self.config);
        self.dirty = true;
    }

    /// The render size: window × scale.
    fn render_size(&self) -> (u32, u32) {
        let s = |v: u32| ((v as f32 * self.scale).round() as u32).clamp(1, 8192);
        (s(self.config.width), s(self.config.height))
    }

    /// The scene as currently edited, at the render size.
    fn current_scene(&self) -> Scene {
        let mut scene = self.scene.clone();
        scene.camera.position = self.controls.orbit.position();
        scene.camera.look_at = self.controls.orbit.target;
        scene.lights = self.controls.lights.clone();
        scene.medium = self.medium.clone();
        scene.render.exposure = self.exposure;
        let (w, h) = self.render_size();
        scene.render.width = w;
        scene.render.height = h;
        scene
    }

    fn act(&mut self, action: Action) -> Result<()> {
        match action {
            Action::Screenshot => {
                let stem = self.output.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or("view".into());
                self.screenshots += 1;
                let path = self.output.with_file_name(format!("{stem}-{}.png", self.screenshots));
                self.save_screenshot(&path)?;
                output::write_atomic(&path.with_extension("json"), self.view_state_json()?.as_bytes())?;
                self.status = format!("wrote {} and its .json", path.display());
                eprintln!("{}", self.status);
            }
            Action::HistoryWeight => {
                let t = self.temporal.as_ref().context("the temporal stage is off")?;
                let tex = t.weights().context("nothing rendered with the temporal stage yet")?;
                let (w, h) = (tex.width(), tex.height());
                let weights = self.gpu.read_texture_f32(tex, 0)?;
                // 0 (history rejected) black, the largest weight white.
                let top = t.settings().history_weight.max(1e-6);
                let rgb: Vec<u8> =
                    weights.iter().flat_map(|&x| [((x / top).clamp(0.0, 1.0) * 255.0).round() as u8; 3]).collect();
                self.show_image("temporal: history weight".into(), format!("{w}×{h}; black: rejected"), w, h, &rgb);
            }
            Action::Debug(view) => {
                let (_, fin, _) = self.read_frame()?;
                let scene = self.current_scene();
                let img = render::debug_view(&scene, Some(&self.gpu), &self.technique, view, &fin)?;
                let rgb = ToneMap::new(self.exposure).to_rgb8(&img);
                let caption = format!("{}×{}", img.width, img.height);
                self.show_image(
                    format!("{}: {}", self.technique.name(), view.name()),
                    caption,
                    img.width,
                    img.height,
                    &rgb,
                );
            }
            Action::ErrorView => {
                let started = Instant::now();
                let (inscatter, fin, depth) = self.read_frame()?;
                let (tex, desc) = self.last_host.as_ref().context("nothing rendered yet")?;
                let shadow_maps = host::read_shadow_maps(&self.gpu, tex, desc)?;
                let surface = self.gpu.read_image(&tex.surface)?;
                let frame = CpuFrame { desc, depth: &depth, shadow_maps: &shadow_maps, surface: Some(&surface) };
                let settings = ReferenceSettings { steps: self.reference_steps, ..Default::default() };
                let (ref_in, _) = reference::render(&frame, &settings, &|_, _| {})?;
                let tr = surface_transmittance(desc, &depth);
                let ref_fin = composite(&surface, &ref_in, &tr);
                let tone = ToneMap::new(self.exposure);
                let m = metrics::compare(&ref_fin, &fin, &tone)?;
                let mi = metrics::compare(&ref_in, &inscatter, &tone)?;
                let (w, h, rgb) = metrics::flip_heatmap(&ref_fin, &fin, &tone)?;
                let caption = format!(
                    "vs reference ({} steps, {:.1} s): final PSNR {:.2} dB, FLIP {:.4}; in-scattering PSNR {:.2} dB",
                    self.reference_steps,
                    started.elapsed().as_secs_f64(),
                    m.psnr_db,
                    m.flip_mean,
                    mi.psnr_db
                );
                self.show_image(format!("FLIP error: {}", self.technique.name()), caption, w, h, &rgb);
            }
        }
        Ok(())
    }

    /// Opens another scene (a built-in name or a scene file) in the window: new geometry for
    /// the host renderer, the scene's camera, light, medium and exposure, and the current
    /// technique with the scene's own `[render.<technique>]` settings and the current preset,
    /// as `crepuscular view SCENE --technique T --preset P` would start. On error nothing
    /// changes.
    fn open_scene(&mut self, spec: &str) -> Result<()> {
        let (scene, technique) = load_for_view(spec, self.shadow_map_size, self.technique.name(), self.preset)?;
        let host = GpuHost::for_scene(&self.gpu, &scene)?;
        self.host = host;
        self.controls = Controls::of(&scene);
        self.medium = scene.medium.clone();
        self.exposure = scene.render.exposure;
        self.scene = scene;
        self.last_host = None;
        self.last_stats = None;
        self.set_technique(Ok(technique), true);
        eprintln!("view: opened `{}`", self.scene.name);
        Ok(())
    }

    /// Re-parses the technique from the edited fields; errors go to the panel.
    fn apply_fields(&mut self) {
        let mut overrides = json_overrides(&self.fields);
        for (k, text) in &self.text_fields {
            if !text.trim().is_empty() {
                overrides.push(format!("{k}={text}"));
            }
        }
        let mut scene = self.scene.clone();
        scene.render.techniques.remove(self.technique.name());
        self.set_technique(render::parse_technique(self.technique.name(), &scene, &overrides), false);
    }

    fn set_technique(&mut self, parsed: Result<TechniqueSettings>, refresh: bool) {
        match parsed {
            Ok(t) => {
                let switched = t.name() != self.technique.name();
                // Same technique: the runner keeps its pipelines (Scattering::update); another
                // technique: a new runner on the next frame.
                if !self.runner.as_mut().is_some_and(|r| r.update(&t).unwrap_or(false)) {
                    self.runner = None;
                }
                self.technique = t;
                self.settings_error = None;
                self.dirty = true;
                if switched || refresh {
                    self.fields = settings_fields(&self.technique);
                    self.text_fields = text_fields(&self.fields);
                    self.window.set_title(&format!("crepuscular — {} — {}", self.scene.name, self.technique.name()));
                }
            }
            Err(e) => self.settings_error = Some(format!("{e:#}").replace('\n', " ")),
        }
    }
}

/// A scene to open in the window and the technique `name` on it: the scene's own
/// `[render.<name>]` settings under `preset`, and `shadow_map_size` (`--shadow-map-size`)
/// when given. Errors name the file, key and value.
fn load_for_view(
    spec: &str,
    shadow_map_size: Option<u32>,
    name: &str,
    preset: Option<Preset>,
) -> Result<(Scene, TechniqueSettings)> {
    let mut scene = render::load_scene(spec)?;
    if let Some(s) = shadow_map_size {
        scene.render.shadow.size = s;
    }
    let technique = parse_technique(name, &scene, preset, &[])?;
    Ok((scene, technique))
}

/// The phase function of kind `kind` (a scene file's `phase.kind`) with the scene file's
/// defaults, keeping the asymmetry of `old` when both have one; None for an unknown kind.
fn phase_of_kind(kind: &str, old: &Phase) -> Option<Phase> {
    let mut p = serde_json::from_value::<Phase>(serde_json::json!({ "kind": kind })).ok()?;
    if let (
        Phase::HenyeyGreenstein { g } | Phase::HoffmanPreetham { g, .. },
        Phase::HenyeyGreenstein { g: old } | Phase::HoffmanPreetham { g: old, .. },
    ) = (&mut p, old)
    {
        *g = *old;
    }
    Some(p)
}

/// The technique's settings as a JSON object (without the `technique` tag).
fn settings_fields(t: &TechniqueSettings) -> serde_json::Map<String, serde_json::Value> {
    match serde_json::to_value(t) {
        Ok(serde_json::Value::Object(mut m)) => {
            m.remove("technique");
            m
        }
        _ => serde_json::Map::new(),
    }
}

/// TOML text for the fields that are not scalars (unset options, arrays).
fn text_fields(fields: &serde_json::Map<String, serde_json::Value>) -> std::collections::BTreeMap<String, String> {
    fields
        .iter()
        .filter(|(_, v)| v.is_null() || v.is_array() || v.is_object())
        .map(|(k, v)| (k.clone(), toml_literal(v).unwrap_or_default()))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_setting_of_every_technique_round_trips_through_overrides() {
        let scene = crepuscular_scene::builtin::builtin("colonnade").unwrap();
        for t in crepuscular::techniques::TECHNIQUES {
            for p in Preset::ALL {
                let choice = parse_technique(t.name, &scene, Some(p), &[]).unwrap();
                let fields = settings_fields(&choice);
                let mut overrides = json_overrides(&fields);
                overrides.extend(
                    text_fields(&fields).into_iter().filter(|(_, v)| !v.is_empty()).map(|(k, v)| format!("{k}={v}")),
                );
                let back = render::parse_technique(t.name, &scene, &overrides).unwrap();
                assert_eq!(serde_json::to_value(&back).unwrap(), serde_json::to_value(&choice).unwrap(), "{}", t.name);
            }
        }
    }

    #[test]
    fn bad_values_are_errors_not_panics() {
        let scene = crepuscular_scene::builtin::builtin("colonnade").unwrap();
        assert!(render::parse_technique("brute-force", &scene, &["steps=0".into()]).is_err());
        assert!(render::parse_technique("epipolar", &scene, &["weighting=\"nope\"".into()]).is_err());
    }

    #[test]
    fn every_setting_of_every_technique_has_its_doc_comment_as_tooltip() {
        let scene = crepuscular_scene::builtin::builtin("colonnade").unwrap();
        for t in crepuscular::techniques::TECHNIQUES {
            let choice = parse_technique(t.name, &scene, None, &[]).unwrap();
            for key in settings_fields(&choice).keys() {
                let doc = setting_doc(t.name, key).unwrap_or_else(|| panic!("{}.{key} has no tooltip", t.name));
                assert!(doc.len() > 20 && !doc.contains("///"), "{}.{key}: {doc:?}", t.name);
            }
        }
        // The text is the field's documentation, paragraphs kept.
        let factor = setting_doc("subsampled", "factor").unwrap();
        assert!(factor.starts_with("Subsampling factor f: the grid is"), "{factor}");
        assert!(factor.contains("\n\nRay-marching cost falls as 1/f²"), "{factor}");
        // The shared march settings (flattened) carry their one doc, under every technique.
        let steps = setting_doc("brute-force", "steps").unwrap();
        assert!(steps.starts_with("Ray-marching steps N per view ray (eq. 1)"), "{steps}");
        assert_eq!(setting_doc("epipolar", "steps"), Some(steps));
        let spot = setting_doc("minmax", "spot_steps").unwrap();
        assert!(spot.contains("Wyman & Ramsey 2008"), "{spot}");
        assert_eq!(setting_doc("brute-force", "spot_steps"), Some(spot));
        assert!(setting_doc("minmax", "steps").is_none());
        assert!(setting_doc("brute-force", "no-such-key").is_none());
    }

    #[test]
    fn every_phase_kind_can_be_picked_and_keeps_g() {
        let hg = Phase::HenyeyGreenstein { g: -0.3 };
        for kind in ["isotropic", "henyey-greenstein", "rayleigh", "hoffman-preetham"] {
            let p = phase_of_kind(kind, &hg).unwrap_or_else(|| panic!("{kind}"));
            assert_eq!(serde_json::to_value(p).unwrap()["kind"], kind);
            if let Phase::HenyeyGreenstein { g } | Phase::HoffmanPreetham { g, .. } = p {
                assert_eq!(g, -0.3, "{kind} lost g");
            }
        }
        // From a kind without g: the file format's defaults.
        assert_eq!(phase_of_kind("henyey-greenstein", &Phase::Rayleigh), Some(Phase::HenyeyGreenstein { g: 0.7 }));
        assert!(phase_of_kind("mie", &hg).is_none());
    }

    #[test]
    fn opening_a_scene_keeps_the_technique_and_reports_bad_files_by_name() {
        let (scene, t) = load_for_view("forest", Some(512), "epipolar", Some(Preset::Fast)).unwrap();
        assert_eq!((scene.name.as_str(), t.name(), scene.render.shadow.size), ("forest", "epipolar", 512));
        let fast = parse_technique("epipolar", &scene, Some(Preset::Fast), &[]).unwrap();
        assert_eq!(serde_json::to_value(&t).unwrap(), serde_json::to_value(&fast).unwrap());
        let d = std::env::temp_dir().join(format!("crepuscular-view-open-{}", std::process::id()));
        std::fs::create_dir_all(&d).unwrap();
        let bad = d.join("bad.toml");
        std::fs::write(&bad, "[medium]\nscattering = -1.0\n").unwrap();
        let e = format!("{:#}", load_for_view(bad.to_str().unwrap(), None, "brute-force", None).unwrap_err());
        assert!(e.contains("bad.toml") && e.contains("scattering"), "{e}");
        let e = format!("{:#}", load_for_view("no-such-scene", None, "brute-force", None).unwrap_err());
        assert!(e.contains("no-such-scene"), "{e}");
    }
}
