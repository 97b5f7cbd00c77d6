//! The plugin's demo scene — a colonnade in fog, lit by a low sun through its pillars (and
//! optionally a spot and a point lamp) — and a headless app that renders it into an image: what
//! the `shafts` and `versus` examples and the plugin's test run (docs/BEVY.md).

use std::sync::{Arc, Mutex};

use bevy::camera::{Hdr, RenderTarget};
use bevy::light::{CascadeShadowConfigBuilder, DirectionalLightShadowMap, FogVolume, VolumetricFog, VolumetricLight};
use bevy::prelude::*;
use bevy::render::RenderApp;
use bevy::render::pipelined_rendering::PipelinedRenderingPlugin;
use bevy::render::render_resource::PipelineCache;
use bevy::render::render_resource::TextureFormat;
use bevy::render::view::screenshot::{Screenshot, ScreenshotCaptured};
use bevy::window::{ExitCondition, WindowPlugin};

use crate::{Crepuscular, CrepuscularLight, CrepuscularPlugin, CrepuscularTemporal};

/// Which volumetric effect the demo camera renders.
#[derive(Clone, Debug)]
pub enum Effect {
    /// No fog at all (the scene alone: the baseline of the timings).
    None,
    /// The plugin, with this camera component.
    Crepuscular(Crepuscular),
    /// Bevy's own `VolumetricFog` at this many steps, over the same medium (docs/BEVY.md
    /// "Bevy's fog, matched").
    BevyFog {
        /// `VolumetricFog::step_count`.
        steps: u32,
    },
}

/// What the demo renders.
#[derive(Clone, Debug)]
pub struct DemoOptions {
    /// Image width, pixels. Default 320.
    pub width: u32,
    /// Image height, pixels. Default 180.
    pub height: u32,
    /// The effect. Default: the plugin at its defaults.
    pub effect: Effect,
    /// Adds a spot lamp and a point lamp (both scattering) to the sun. Default false.
    pub lamps: bool,
    /// Side of Bevy's directional (and spot) shadow maps, texels. Default 1024.
    pub shadow_map_size: usize,
    /// How the plugin's lights read those maps ([`CrepuscularLight::shadow_filter`]). Default
    /// `Bilinear` (what Bevy's own lookups return); `Nearest` costs one read per march sample
    /// instead of four.
    pub shadow_filter: crepuscular::ShadowFilter,
    /// Installs Bevy's `LogPlugin` (a process-wide logger: tests that build several apps in one
    /// process turn it off). Default true.
    pub log: bool,
    /// With the plugin: the temporal stage on the camera ([`CrepuscularTemporal`]), with
    /// Bevy's `MotionVectorPrepass` beside it for its motion vectors. Default None (off).
    pub temporal: Option<CrepuscularTemporal>,
}

impl Default for DemoOptions {
    fn default() -> Self {
        Self {
            width: 320,
            height: 180,
            effect: Effect::Crepuscular(Crepuscular::default()),
            lamps: false,
            shadow_map_size: 1024,
            shadow_filter: crepuscular::ShadowFilter::Bilinear,
            log: true,
            temporal: None,
        }
    }
}

/// The sun's illuminance, lux (Bevy's full daylight is 10 000–100 000).
pub const SUN_LUX: f32 = 10_000.0;

/// The demo's image target, for screenshots.
#[derive(Resource, Clone)]
pub struct DemoTarget(pub Handle<Image>);

/// A headless app (no window, no pipelined rendering: each `update` renders one whole frame)
/// with the demo scene. Call `app.finish(); app.cleanup();` once, then `update` per frame (as
/// [`render_frames`] does).
pub fn headless_app(opts: &DemoOptions) -> App {
    let mut app = App::new();
    let mut plugins = DefaultPlugins
        .set(WindowPlugin { primary_window: None, exit_condition: ExitCondition::DontExit, ..default() })
        .disable::<bevy::winit::WinitPlugin>()
        .disable::<PipelinedRenderingPlugin>();
    if !opts.log {
        plugins = plugins.disable::<bevy::log::LogPlugin>();
    }
    app.add_plugins(plugins);
    add_scene(&mut app, opts, None);
    app
}

/// The demo in a window of the options' size (run it with `app.run()`): T switches the camera
/// to the next GPU technique (at the same preset), A turns the temporal stage on and off,
/// Escape quits.
pub fn windowed_app(opts: &DemoOptions) -> App {
    let mut app = App::new();
    app.add_plugins(DefaultPlugins.set(WindowPlugin {
        primary_window: Some(Window {
            title: "crepuscular-bevy: T switches technique, A temporal accumulation".into(),
            resolution: bevy::window::WindowResolution::new(opts.width, opts.height),
            ..default()
        }),
        ..default()
    }));
    add_scene(&mut app, opts, Some(()));
    app.add_systems(Update, keys);
    app
}

fn add_scene(app: &mut App, opts: &DemoOptions, window: Option<()>) {
    app.insert_resource(DirectionalLightShadowMap { size: opts.shadow_map_size }).add_plugins(CrepuscularPlugin);
    let opts = opts.clone();
    app.add_systems(
        Startup,
        move |mut commands: Commands,
              mut meshes: ResMut<Assets<Mesh>>,
              mut materials: ResMut<Assets<StandardMaterial>>,
              mut images: ResMut<Assets<Image>>| {
            let target = match window {
                Some(()) => RenderTarget::Window(bevy::window::WindowRef::Primary),
                None => {
                    let image = Image::new_target_texture(opts.width, opts.height, TextureFormat::Rgba8UnormSrgb, None);
                    let handle = images.add(image);
                    commands.insert_resource(DemoTarget(handle.clone()));
                    RenderTarget::Image(handle.into())
                }
            };
            let gobo = images.add(stained_glass());
            spawn_colonnade(&mut commands, &mut meshes, &mut materials, &opts, target, gobo);
        },
    );
}

/// T: the next GPU technique (same preset); A: the temporal stage on or off; Escape: quit.
fn keys(
    mut commands: Commands,
    keys: Res<ButtonInput<KeyCode>>,
    mut cameras: Query<(Entity, &mut Crepuscular, Has<CrepuscularTemporal>)>,
    mut exit: MessageWriter<AppExit>,
) {
    if keys.just_pressed(KeyCode::Escape) {
        exit.write(AppExit::Success);
    }
    if keys.just_pressed(KeyCode::KeyA) {
        for (entity, _, on) in &cameras {
            if on {
                commands.entity(entity).remove::<CrepuscularTemporal>();
            } else {
                commands
                    .entity(entity)
                    .insert((CrepuscularTemporal::default(), bevy::core_pipeline::prepass::MotionVectorPrepass));
            }
            info!("crepuscular: temporal stage {}", if on { "off" } else { "on" });
        }
    }
    if keys.just_pressed(KeyCode::KeyT) {
        for (_, mut c, _) in &mut cameras {
            c.technique = next_technique(&c.technique);
            info!("crepuscular: technique {}", c.technique.name());
        }
    }
}

/// The GPU technique after `t` in the library's list (wrapping), at its default settings.
pub fn next_technique(t: &crepuscular::TechniqueSettings) -> crepuscular::TechniqueSettings {
    let gpu: Vec<_> = crepuscular::techniques::TECHNIQUES
        .iter()
        .filter_map(|i| crepuscular::TechniqueSettings::named(i.name).ok())
        .filter(|s| s.has_gpu())
        .collect();
    let at = gpu.iter().position(|s| s.name() == t.name()).unwrap_or(gpu.len() - 1);
    gpu[(at + 1) % gpu.len()].clone()
}

/// Side of the square ground plane (y = 0, centred on the origin), world units.
pub const GROUND: f32 = 80.0;

/// The colonnade's boxes (centre, size), world units: nine pillars 0.7 wide and 7 high every 2
/// units along x at z = 0, the beam on them, and a low wall behind. With [`GROUND`] they are
/// the whole scene, so a test can check that a depth buffer or shadow map, unprojected with the
/// matrices the plugin hands the library, lands on them ([`surface_distance`]).
pub const BOXES: [([f32; 3], [f32; 3]); 11] = [
    ([-8.0, 3.5, 0.0], [0.7, 7.0, 0.7]),
    ([-6.0, 3.5, 0.0], [0.7, 7.0, 0.7]),
    ([-4.0, 3.5, 0.0], [0.7, 7.0, 0.7]),
    ([-2.0, 3.5, 0.0], [0.7, 7.0, 0.7]),
    ([0.0, 3.5, 0.0], [0.7, 7.0, 0.7]),
    ([2.0, 3.5, 0.0], [0.7, 7.0, 0.7]),
    ([4.0, 3.5, 0.0], [0.7, 7.0, 0.7]),
    ([6.0, 3.5, 0.0], [0.7, 7.0, 0.7]),
    ([8.0, 3.5, 0.0], [0.7, 7.0, 0.7]),
    ([0.0, 7.4, 0.0], [18.0, 0.8, 1.4]),
    ([0.0, 1.5, -12.0], [30.0, 3.0, 0.5]),
];

/// Distance from `p` to the nearest surface of the demo scene (the ground or a box's faces),
/// world units.
pub fn surface_distance(p: Vec3) -> f32 {
    let half = GROUND / 2.0;
    let ground = if p.x.abs() <= half && p.z.abs() <= half { p.y.abs() } else { f32::INFINITY };
    BOXES.iter().fold(ground, |best, (c, s)| {
        let q = (p - Vec3::from_array(*c)).abs() - Vec3::from_array(*s) / 2.0;
        // Signed distance to the box; its magnitude is the distance to the surface.
        let outside = q.max(Vec3::ZERO).length();
        let inside = q.max_element().min(0.0);
        best.min((outside + inside).abs())
    })
}

/// The far end of the medium (and of Bevy's fog volume), world units.
pub const FAR: f32 = 60.0;

/// The plugin's camera component for the demo scene: `technique` over the library's default
/// medium, ending at [`FAR`] as Bevy's fog box does ([`spawn_colonnade`] centres a box of side
/// 2·`FAR` on the camera), so that the two effects integrate the same medium along the same
/// rays. (The component's own default, 200, would march sky rays 3.3× as far as Bevy's.)
pub fn crepuscular(technique: crepuscular::TechniqueSettings) -> Crepuscular {
    Crepuscular { technique, far: FAR, ..Default::default() }
}

/// Spawns the colonnade, its lights and the camera (rendering into `target`).
pub fn spawn_colonnade(
    commands: &mut Commands,
    meshes: &mut Assets<Mesh>,
    materials: &mut Assets<StandardMaterial>,
    opts: &DemoOptions,
    target: RenderTarget,
    gobo: Handle<Image>,
) {
    let stone = materials.add(StandardMaterial {
        base_color: Color::srgb(0.72, 0.68, 0.6),
        perceptual_roughness: 0.9,
        ..default()
    });
    let ground = materials.add(StandardMaterial {
        base_color: Color::srgb(0.35, 0.33, 0.3),
        perceptual_roughness: 1.0,
        ..default()
    });
    commands.spawn((Mesh3d(meshes.add(Plane3d::default().mesh().size(GROUND, GROUND))), MeshMaterial3d(ground)));
    for (center, size) in BOXES {
        commands.spawn((
            Mesh3d(meshes.add(Cuboid::from_size(Vec3::from_array(size)))),
            MeshMaterial3d(stone.clone()),
            Transform::from_translation(Vec3::from_array(center)),
        ));
    }

    let mut sun = commands.spawn((
        DirectionalLight { illuminance: SUN_LUX, shadow_maps_enabled: true, ..default() },
        // One cascade over the whole medium: the library reads one map per light (docs/BEVY.md).
        CascadeShadowConfigBuilder { num_cascades: 1, minimum_distance: 0.1, maximum_distance: FAR, ..default() }
            .build(),
        Transform::from_xyz(0.0, 10.0, -10.0).looking_to(Vec3::new(0.35, -0.45, 1.0), Vec3::Y),
    ));
    match &opts.effect {
        Effect::Crepuscular(_) => {
            sun.insert(CrepuscularLight { shadow_filter: opts.shadow_filter, ..default() });
        }
        Effect::BevyFog { .. } => {
            sun.insert(VolumetricLight);
        }
        Effect::None => {}
    }
    if opts.lamps {
        let mut spot = commands.spawn((
            SpotLight {
                intensity: 2.0e7,
                range: FAR,
                outer_angle: 0.5,
                inner_angle: 0.35,
                shadow_maps_enabled: true,
                ..default()
            },
            Transform::from_xyz(-5.0, 7.0, 5.0).looking_at(Vec3::new(-3.0, 0.0, 1.0), Vec3::Y),
        ));
        match opts.effect {
            Effect::Crepuscular(_) => {
                spot.insert(CrepuscularLight { texture: Some(gobo), shadow_filter: opts.shadow_filter, ..default() });
            }
            Effect::BevyFog { .. } => {
                spot.insert(VolumetricLight);
            }
            Effect::None => {}
        }
        let mut point = commands.spawn((
            PointLight { intensity: 1.0e6, range: FAR, shadow_maps_enabled: true, ..default() },
            Transform::from_xyz(3.0, 3.0, -1.5),
        ));
        match opts.effect {
            Effect::Crepuscular(_) => {
                point.insert(CrepuscularLight { shadow_filter: opts.shadow_filter, ..default() });
            }
            Effect::BevyFog { .. } => {
                point.insert(VolumetricLight);
            }
            Effect::None => {}
        }
    }

    let mut camera = commands.spawn((
        Camera3d::default(),
        Hdr,
        Msaa::Off,
        target,
        Projection::Perspective(PerspectiveProjection { fov: 55f32.to_radians(), near: 0.1, ..default() }),
        Transform::from_xyz(-1.0, 2.2, 13.0).looking_at(Vec3::new(0.5, 3.2, 0.0), Vec3::Y),
    ));
    match &opts.effect {
        Effect::Crepuscular(c) => {
            camera.insert(c.clone());
            if let Some(t) = &opts.temporal {
                camera.insert((t.clone(), bevy::core_pipeline::prepass::MotionVectorPrepass));
            }
        }
        Effect::BevyFog { steps } => {
            camera.insert(VolumetricFog { step_count: *steps, ambient_intensity: 0.0, jitter: 0.0, ..default() });
        }
        Effect::None => {}
    }
    if let Effect::BevyFog { .. } = opts.effect {
        // Bevy's fog over the same medium as the plugin's default (docs/BEVY.md "Bevy's fog,
        // matched"): σs and σa as `scattering` and `absorption` at density 1, HG g as the
        // asymmetry, and the light scaled by exp(σt·R) to cancel the attenuation Bevy applies
        // to the light over the volume's bounding radius R (the library's sun arrives
        // unattenuated, docs/MODEL.md §2).
        let c = Crepuscular::default();
        let size = 2.0 * FAR;
        let radius = (Vec3::splat(0.5 * size)).length();
        let sigma_t = c.scattering.x + c.absorption.x;
        commands.spawn((
            FogVolume {
                density_factor: 1.0,
                scattering: c.scattering.x,
                absorption: c.absorption.x,
                scattering_asymmetry: match c.phase {
                    crepuscular::Phase::HenyeyGreenstein { g } => g,
                    _ => 0.0,
                },
                light_intensity: (sigma_t * radius).exp(),
                ..default()
            },
            Transform::from_xyz(-1.0, 2.2, 13.0).with_scale(Vec3::splat(size)),
        ));
    }
}

/// Parses a `--size` value `WIDTHxHEIGHT` (both at least 1); the error names the value.
pub fn parse_size(s: &str) -> Result<(u32, u32), String> {
    s.split_once('x')
        .and_then(|(w, h)| Some((w.parse::<u32>().ok()?, h.parse::<u32>().ok()?)))
        .filter(|&(w, h)| w > 0 && h > 0)
        .ok_or_else(|| format!("--size {s}: expected WIDTHxHEIGHT, e.g. 960x540"))
}

/// A 4×4 "stained glass" of saturated panes (sRGB), the demo spot's gobo.
pub fn stained_glass() -> Image {
    use bevy::asset::RenderAssetUsages;
    use bevy::render::render_resource::{Extent3d, TextureDimension};
    const PANES: [[u8; 4]; 4] = [[230, 40, 40, 255], [40, 200, 60, 255], [50, 80, 240, 255], [240, 210, 40, 255]];
    let mut data = Vec::new();
    for y in 0..4 {
        for x in 0..4 {
            data.extend_from_slice(&PANES[(x + y) % 4]);
        }
    }
    Image::new(
        Extent3d { width: 4, height: 4, depth_or_array_layers: 1 },
        TextureDimension::D2,
        data,
        TextureFormat::Rgba8UnormSrgb,
        RenderAssetUsages::MAIN_WORLD | RenderAssetUsages::RENDER_WORLD,
    )
}

/// Runs at least `frames` frames of a headless demo app, and on until Bevy has built every
/// pipeline it queued (Bevy compiles pipelines in the background and skips what is not ready:
/// until then the frame lacks meshes), then captures its image (sRGB 8-bit RGBA, after Bevy's
/// tone mapping). Errors when the pipelines are not ready within two minutes or no frame
/// arrives.
pub fn render_frames(app: &mut App, frames: u32) -> Result<Image, String> {
    settle(app, frames)?;
    capture(app)
}

/// Updates at least `frames` times and until no pipeline has been waiting for three frames.
/// Gives up when the pipelines are still not built after two minutes plus twenty times the
/// slowest frame (a slow effect's frames hold the CPU that a software adapter's pipeline
/// compiles need).
pub fn settle(app: &mut App, frames: u32) -> Result<(), String> {
    let start = std::time::Instant::now();
    let (mut n, mut ready) = (0u32, 0u32);
    let mut slowest = std::time::Duration::ZERO;
    while n < frames || ready < 3 {
        let t0 = std::time::Instant::now();
        app.update();
        slowest = slowest.max(t0.elapsed());
        n += 1;
        if let Some(exit) = app.should_exit() {
            return Err(format!("the app quit after {n} frames ({exit:?}; Bevy logged why)"));
        }
        let waiting = app.sub_app(RenderApp).world().resource::<PipelineCache>().waiting_pipelines().count();
        ready = if waiting == 0 { ready + 1 } else { 0 };
        let limit = std::time::Duration::from_secs(120) + slowest * 20;
        if start.elapsed() > limit {
            return Err(format!(
                "{waiting} of Bevy's pipelines were still compiling after {:.0} s ({n} frames)",
                start.elapsed().as_secs_f64()
            ));
        }
    }
    Ok(())
}

/// Captures the demo target's current image (a few frames of Bevy's screenshot readback, the
/// device waited for after each).
pub fn capture(app: &mut App) -> Result<Image, String> {
    let slot: Arc<Mutex<Option<Image>>> = Arc::default();
    let target = app.world().get_resource::<DemoTarget>().ok_or("the demo scene was not spawned")?.0.clone();
    let sink = slot.clone();
    app.world_mut().spawn(Screenshot::image(target)).observe(move |captured: On<ScreenshotCaptured>| {
        if let Ok(mut s) = sink.lock() {
            *s = Some(captured.image.clone());
        }
    });
    // Bevy maps the screenshot's buffer without waiting for it: wait for the device between
    // frames so that the readback lands (a fast GPU otherwise outruns it for many frames).
    let device = app.world().resource::<bevy::render::renderer::RenderDevice>().wgpu_device().clone();
    for _ in 0..30 {
        app.update();
        crepuscular::gpu::wait_idle(&device).map_err(|e| e.to_string())?;
        if let Some(img) = slot.lock().ok().and_then(|mut s| s.take()) {
            return Ok(img);
        }
    }
    Err("the screenshot did not arrive within 30 frames".into())
}

/// Writes an 8-bit image as PNG atomically (a temporary file beside `path`, then a rename).
pub fn save_png(img: &Image, path: &std::path::Path) -> Result<(), String> {
    let dynamic = img.clone().try_into_dynamic().map_err(|e| format!("{}: {e}", path.display()))?;
    let rgb = dynamic.to_rgb8();
    let tmp = path.with_extension("png.tmp");
    rgb.save_with_format(&tmp, image::ImageFormat::Png).map_err(|e| format!("{}: {e}", tmp.display()))?;
    std::fs::rename(&tmp, path).map_err(|e| format!("{}: {e}", path.display()))
}

/// The GPU time of the volumetric effect alone, from two timestamps that Bevy's own command
/// encoder writes each frame: one after Bevy's main pass (in `Core3dSystems::MainPass`, after
/// `main_transparent_pass_3d`), one first in `Core3dSystems::EarlyPostProcess`. Between them run
/// exactly the systems ordered after the main pass and before early post-processing: Bevy's
/// `volumetric_fog` and the plugin's render system (shadow-map copy, technique, composite), so
/// both effects are timed by the same bracket. Used by the `versus` example on hardware
/// adapters; a software adapter's timestamps mean nothing (time it by wall clock instead).
/// Needs `TIMESTAMP_QUERY` and `TIMESTAMP_QUERY_INSIDE_ENCODERS` (Bevy asks for every feature
/// the adapter has); without them [`EffectTimer::read`] answers `None`.
#[derive(Resource, Clone, Default)]
pub struct EffectTimer(Arc<Mutex<Option<TimerGpu>>>);

struct TimerGpu {
    set: wgpu::QuerySet,
    resolve: wgpu::Buffer,
    readback: wgpu::Buffer,
    /// Nanoseconds per timestamp tick (`Queue::get_timestamp_period`).
    period_ns: f64,
    /// Whether a frame has written both timestamps since the last read.
    written: bool,
}

impl EffectTimer {
    /// Adds the bracket's two render systems to a demo app (call before `app.finish()`).
    pub fn install(app: &mut App) -> Self {
        use bevy::core_pipeline::core_3d::main_transparent_pass_3d;
        use bevy::core_pipeline::schedule::{Core3d, Core3dSystems};
        let timer = EffectTimer::default();
        app.insert_resource(timer.clone());
        if let Some(render_app) = app.get_sub_app_mut(RenderApp) {
            render_app.insert_resource(timer.clone()).add_systems(
                Core3d,
                (
                    timer_begin.in_set(Core3dSystems::MainPass).after(main_transparent_pass_3d),
                    timer_end.in_set(Core3dSystems::EarlyPostProcess),
                ),
            );
        }
        timer
    }

    /// The effect's GPU time in the last frame, milliseconds (wait for the device first, as
    /// `versus` does after each `update`); `None` without timestamp queries or before a frame
    /// wrote both timestamps.
    pub fn read(&self, device: &wgpu::Device, queue: &wgpu::Queue) -> Result<Option<f64>, String> {
        let mut guard = self.0.lock().map_err(|e| e.to_string())?;
        let Some(gpu) = guard.as_mut().filter(|g| g.written) else { return Ok(None) };
        gpu.written = false;
        let ticks = crepuscular::GpuContext::from_device(device, queue)
            .read_mapped(&gpu.readback, "the effect's timestamps", |b| {
                let t: &[u64] = bytemuck::cast_slice(&b[..16]);
                t[1].wrapping_sub(t[0])
            })
            .map_err(|e| e.to_string())?;
        // A wrapped or reordered pair (a driver that resets its counter) is not a time.
        if ticks > u64::MAX / 2 {
            return Err("the end timestamp precedes the begin timestamp".into());
        }
        Ok(Some(ticks as f64 * gpu.period_ns / 1e6))
    }
}

fn timer_begin(
    timer: Res<EffectTimer>,
    device: Res<bevy::render::renderer::RenderDevice>,
    queue: Res<bevy::render::renderer::RenderQueue>,
    mut ctx: bevy::render::renderer::RenderContext,
) {
    let Ok(mut guard) = timer.0.lock() else { return };
    if guard.is_none() {
        let d = device.wgpu_device();
        let needed = wgpu::Features::TIMESTAMP_QUERY | wgpu::Features::TIMESTAMP_QUERY_INSIDE_ENCODERS;
        if !d.features().contains(needed) {
            return;
        }
        let buffer = |label, usage| {
            d.create_buffer(&wgpu::BufferDescriptor { label: Some(label), size: 16, usage, mapped_at_creation: false })
        };
        *guard = Some(TimerGpu {
            set: d.create_query_set(&wgpu::QuerySetDescriptor {
                label: Some("effect timer"),
                ty: wgpu::QueryType::Timestamp,
                count: 2,
            }),
            resolve: buffer("effect timer resolve", wgpu::BufferUsages::QUERY_RESOLVE | wgpu::BufferUsages::COPY_SRC),
            readback: buffer("effect timer readback", wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST),
            period_ns: queue.0.get_timestamp_period() as f64,
            written: false,
        });
    }
    if let Some(gpu) = guard.as_mut() {
        ctx.command_encoder().write_timestamp(&gpu.set, 0);
    }
}

fn timer_end(timer: Res<EffectTimer>, mut ctx: bevy::render::renderer::RenderContext) {
    let Ok(mut guard) = timer.0.lock() else { return };
    let Some(gpu) = guard.as_mut() else { return };
    let encoder = ctx.command_encoder();
    encoder.write_timestamp(&gpu.set, 1);
    encoder.resolve_query_set(&gpu.set, 0..2, &gpu.resolve, 0);
    encoder.copy_buffer_to_buffer(&gpu.resolve, 0, &gpu.readback, 0, 16);
    gpu.written = true;
}
