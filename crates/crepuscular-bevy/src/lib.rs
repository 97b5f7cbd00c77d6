//! A Bevy plugin for [crepuscular](crepuscular): light shafts in fog (single scattering) by any
//! of the library's techniques — epipolar sampling, prefiltered shadow maps, 1D min-max
//! mipmaps, brute-force and interleaved ray marching — inside Bevy's own frame.
//!
//! ```no_run
//! use bevy::prelude::*;
//! use crepuscular_bevy::{Crepuscular, CrepuscularLight, CrepuscularPlugin};
//!
//! fn setup(mut commands: Commands) {
//!     // The camera chooses the technique and the medium…
//!     commands.spawn((Camera3d::default(), Crepuscular::default()));
//!     // …and each light that scatters carries the marker (its shadows must be on).
//!     commands.spawn((DirectionalLight { shadow_maps_enabled: true, ..default() }, CrepuscularLight::default()));
//! }
//! App::new().add_plugins((DefaultPlugins, CrepuscularPlugin)).add_systems(Startup, setup).run();
//! ```
//!
//! What the plugin does each frame, per camera with [`Crepuscular`] (docs/BEVY.md):
//! 1. copies the shadow maps Bevy rendered for the marked lights (the chosen cascade of a
//!    directional light, a spot's map, a point light's six cube faces) into one `R32Float`
//!    array, the form the library reads (`shadow_copy.wgsl`);
//! 2. describes the frame to the library with Bevy's own matrices: the camera's reversed-Z
//!    infinite projection (jittered if TAA jitters it) and each shadow view's projection;
//! 3. records the technique ([`crepuscular::Scattering::encode`]) into Bevy's command encoder,
//!    reading Bevy's depth buffer after the main opaque pass;
//! 4. with [`CrepuscularTemporal`] on the camera, moves the technique's samples every frame
//!    and blends the frames with the library's temporal stage ([`crepuscular::Temporal`]),
//!    reprojected through Bevy's previous and current matrices and, where the camera has
//!    `MotionVectorPrepass`, Bevy's motion vectors;
//! 5. composites L = T(s)·L_surface + L_scatt into Bevy's HDR view target with the library's
//!    [`crepuscular::Composite`], before Bevy's tone mapping.
//!
//! Nothing is submitted or waited for by the plugin: Bevy submits its encoder as usual.

use std::collections::HashMap;
use std::sync::{Arc, Mutex};

use bevy::camera::visibility::RenderLayers;
use bevy::core_pipeline::core_3d::prepare_core_3d_depth_textures;
use bevy::core_pipeline::prepass::ViewPrepassTextures;
use bevy::core_pipeline::schedule::{Core3d, Core3dSystems};
use bevy::ecs::query::QueryItem;
use bevy::pbr::{
    ExtractedDirectionalLight, ExtractedPointLight, GlobalClusterableObjectMeta, PointAndSpotLightViewEntities,
    ViewShadowBindings,
};
use bevy::prelude::*;
use bevy::render::camera::ExtractedCamera;
use bevy::render::extract_component::{ExtractComponent, ExtractComponentPlugin};
use bevy::render::renderer::{RenderContext, RenderDevice, RenderQueue, ViewQuery};
use bevy::render::sync_component::SyncComponent;
use bevy::render::view::{ExtractedView, Msaa, ViewDepthTexture, ViewTarget};
use bevy::render::{Render, RenderApp, RenderSystems};
use crepuscular::{
    Composite, CompositeInputs, CompositeTarget, DepthConvention, FrameCamera, FrameDesc, GpuFrame, Medium, Phase,
    Scattering, StatsMode, TechniqueSettings, Temporal, TemporalSettings,
};

mod convert;
pub mod demo;
mod shadow_copy;

pub use convert::to_glam;
use shadow_copy::ShadowCopy;

/// Adds light shafts to every 3D camera that has a [`Crepuscular`] component, from every light
/// that has a [`CrepuscularLight`] component (and shadow maps enabled).
pub struct CrepuscularPlugin;

/// The camera's effect: which technique and settings, and the medium the camera looks through.
/// Put it on a `Camera3d` entity (with `Msaa::Off`: the library reads a single-sample depth
/// buffer). Changing it at run time switches technique or settings in place; pipelines are
/// rebuilt only where the technique changes (`Scattering::update`).
#[derive(Component, Clone, Debug)]
pub struct Crepuscular {
    /// The technique and its settings, as the library names them (every technique and every
    /// preset: `TechniqueSettings::named("epipolar")`, `Preset::Fast.settings("prefiltered")`).
    /// Default: epipolar at its balanced settings (K = 32 initial samples per line, 64 steps).
    pub technique: TechniqueSettings,
    /// Scattering coefficient σs per RGB channel, m⁻¹ (world units⁻¹). Must be finite and ≥ 0.
    /// Default 0.02 m⁻¹ (grey). Cost: none (the medium is homogeneous; docs/MODEL.md §1).
    pub scattering: Vec3,
    /// Absorption coefficient σa per RGB channel, m⁻¹. Must be finite and ≥ 0. Default 0.005.
    pub absorption: Vec3,
    /// The phase function (docs/MODEL.md §1). Default Henyey–Greenstein g = 0.7.
    pub phase: Phase,
    /// Where the rays of pixels with no geometry (the sky) and the medium end, world units:
    /// Bevy's projection has no far plane. Default 200. Cost: none; precision of the techniques
    /// that sample along rays falls as it grows. Set it to your fog's extent: beside Bevy's
    /// `FogVolume` (a box), its half side, or the sky gathers more path than Bevy's fog does.
    pub far: f32,
    /// Which of a directional light's shadow cascades the effect reads (docs/BEVY.md
    /// "Cascades"). Default [`CascadeChoice::Farthest`].
    pub cascade: CascadeChoice,
    /// Format of the in-scattering texture: `Rgba16Float` (default; half the memory and
    /// bandwidth, within one half-float ulp of `Rgba32Float`, README "Rgba16Float output") or
    /// `Rgba32Float`.
    pub output_format: wgpu::TextureFormat,
}

impl Default for Crepuscular {
    fn default() -> Self {
        Self {
            technique: TechniqueSettings::named("epipolar").expect("epipolar is a built-in technique"),
            scattering: Vec3::splat(0.02),
            absorption: Vec3::splat(0.005),
            phase: Phase::HenyeyGreenstein { g: 0.7 },
            far: 200.0,
            cascade: CascadeChoice::Farthest,
            output_format: wgpu::TextureFormat::Rgba16Float,
        }
    }
}

impl Crepuscular {
    /// The library's medium of this camera.
    pub fn medium(&self) -> Medium {
        Medium { scattering: to_glam(self.scattering), absorption: to_glam(self.absorption), phase: self.phase }
    }
}

/// Temporal accumulation after the camera's technique (docs/BEVY.md "Temporal accumulation";
/// the library's stage, docs/MODEL.md §7): put it on a camera that has [`Crepuscular`]. Each
/// frame the technique's samples move (`jitter` on, `frame_index` advanced, where the technique
/// marches: brute-force, interleaved, subsampled, epipolar; [`TechniqueSettings::jittered`]),
/// and the stage blends the frame with the previous ones, reprojected through Bevy's previous
/// and current camera matrices and its depth, rejecting the history where another surface
/// was seen, clipping it to the frame's neighbourhood, and dropping it when a light jumps.
/// Where the camera also has Bevy's `MotionVectorPrepass`, the stage follows moving objects by
/// Bevy's motion vectors ([`Self::motion_vectors`]). Without this component the effect shows
/// each frame as the technique renders it.
///
/// Where it pays, measured (docs/RESULTS.md "Temporal accumulation"): after a jittered march
/// (brute-force, epipolar) it gains up to 14 dB after 8 frames of a slow move; after an exact
/// technique (minmax) it loses up to 11 dB, and after interleaved and subsampled it raises
/// the flicker. Cost: one compute pass per frame (16 ms at 320×180 on the software adapter,
/// docs/RESULTS.md), 68 bytes of history per pixel.
#[derive(Component, Clone, Debug)]
pub struct CrepuscularTemporal {
    /// The stage's settings (the library's [`TemporalSettings`], each documented there with its
    /// default and cost). Changing them keeps the history.
    pub settings: TemporalSettings,
    /// Hand the stage Bevy's motion vectors where the camera has `MotionVectorPrepass` (UV now
    /// minus UV a frame ago, y down: the library's convention), so the history follows moving
    /// objects; without them, or with this false, every pixel is reprojected through the camera
    /// alone (exact for a static scene). Default true (it matters only where the prepass
    /// exists). Cost: one more texture read per pixel.
    pub motion_vectors: bool,
    /// Bumped by [`Self::cut`]; the render side drops the history when it changes.
    cuts: u32,
}

impl Default for CrepuscularTemporal {
    fn default() -> Self {
        Self { settings: TemporalSettings::default(), motion_vectors: true, cuts: 0 }
    }
}

impl CrepuscularTemporal {
    /// The stage with these settings (Bevy's motion vectors read where the camera has them).
    pub fn new(settings: TemporalSettings) -> Self {
        Self { settings, ..Default::default() }
    }

    /// Drops the history on the next frame rendered: call it on a camera cut or a teleport,
    /// where the previous frames show another place (the stage also drops it by itself on a new
    /// size, another medium or light set, a light jump, or a technique switch).
    pub fn cut(&mut self) {
        self.cuts = self.cuts.wrapping_add(1);
    }
}

/// Which cascade of a directional light's cascaded shadow map the effect reads. The library
/// reads one map per light; Bevy's cascades each cover a slice of the view frustum. The
/// farthest cascade covers the farthest slice at the coarsest texels; view samples outside the
/// chosen cascade's box are unshadowed. For shafts over the whole view give the scattering sun
/// one cascade (`CascadeShadowConfigBuilder { num_cascades: 1, maximum_distance: far, .. }`),
/// as the plugin's examples do.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum CascadeChoice {
    /// The last cascade (the largest box). Default.
    #[default]
    Farthest,
    /// Cascade `i` (0 is the nearest); clamped to the light's cascade count.
    Index(usize),
}

/// Marks a light (`DirectionalLight`, `SpotLight` or `PointLight`, with `shadow_maps_enabled`)
/// as scattering in the fog of cameras with [`Crepuscular`]. At most 16 lights reach the
/// effect per view (the library's limit).
#[derive(Component, Clone, Debug)]
pub struct CrepuscularLight {
    /// Scale of this light's in-scattering (1 scatters as the light shines, 0 opts out).
    /// Finite, ≥ 0. Default 1.
    pub scattering: f32,
    /// Volume shadow bias, world units along the light's depth axis (the library's
    /// `FrameLight::shadow_bias`; Bevy's own depth and normal biases already apply to the
    /// map). Default 0.02.
    pub shadow_bias: f32,
    /// How the volume reads this light's shadow map (the library's
    /// `FrameLight::shadow_filter`, docs/MODEL.md §1 "Visibility"): `Nearest`, one texel's
    /// test, or `Bilinear`, the 2×2 percentage-closer filter — what Bevy's own lookups into the
    /// same map return through their comparison sampler, so shaft edges step less; four
    /// texture reads per sample instead of one. Read by the marching techniques and `minmax`'s
    /// walk (exactly, docs/MODEL.md §8); `prefiltered` keeps its own filtered visibility outside
    /// its epipole disc. Default `Bilinear`.
    pub shadow_filter: crepuscular::ShadowFilter,
    /// A spot light's projected texture ("gobo", stained glass): a Bevy image, mapped over the
    /// spot's square shadow frustum, its RGB multiplying the light (linear; an sRGB image is
    /// decoded). Read into the effect once it is loaded and whenever the handle changes; any
    /// format Bevy can convert to RGBA (`Image::try_into_dynamic`). Ignored on other lights.
    /// Default None. Cost: one bilinear lookup per light sample.
    pub texture: Option<Handle<Image>>,
}

impl Default for CrepuscularLight {
    fn default() -> Self {
        Self { scattering: 1.0, shadow_bias: 0.02, shadow_filter: crepuscular::ShadowFilter::Bilinear, texture: None }
    }
}

/// A spot light's gobo as the library reads it (linear RGB texels), made by the plugin from
/// [`CrepuscularLight::texture`] once the image is loaded.
#[derive(Component, Clone, Debug)]
pub struct CrepuscularGobo {
    /// The image it was read from.
    pub image: AssetId<Image>,
    /// Its linear texels.
    pub texture: Arc<crepuscular::RgbTexture>,
}

impl SyncComponent for Crepuscular {
    type Target = Self;
}
impl ExtractComponent for Crepuscular {
    type QueryData = &'static Crepuscular;
    type QueryFilter = ();
    type Out = Self;
    fn extract_component(item: QueryItem<'_, '_, Self::QueryData>) -> Option<Self> {
        Some(item.clone())
    }
}
impl SyncComponent for CrepuscularTemporal {
    type Target = Self;
}
impl ExtractComponent for CrepuscularTemporal {
    type QueryData = &'static CrepuscularTemporal;
    type QueryFilter = ();
    type Out = Self;
    fn extract_component(item: QueryItem<'_, '_, Self::QueryData>) -> Option<Self> {
        Some(item.clone())
    }
}
impl SyncComponent for CrepuscularLight {
    type Target = Self;
}
impl ExtractComponent for CrepuscularLight {
    type QueryData = &'static CrepuscularLight;
    type QueryFilter = ();
    type Out = Self;
    fn extract_component(item: QueryItem<'_, '_, Self::QueryData>) -> Option<Self> {
        Some(item.clone())
    }
}
impl SyncComponent for CrepuscularGobo {
    type Target = Self;
}
impl ExtractComponent for CrepuscularGobo {
    type QueryData = &'static CrepuscularGobo;
    type QueryFilter = ();
    type Out = Self;
    fn extract_component(item: QueryItem<'_, '_, Self::QueryData>) -> Option<Self> {
        Some(item.clone())
    }
}

/// The camera's HDR main textures take `COPY_DST`: if the composite ever fails after Bevy's
/// main texture flipped, the plugin copies Bevy's picture across instead of leaving it black.
fn main_texture_copy_dst(mut cameras: Query<&mut bevy::camera::CameraMainTextureUsages, With<Crepuscular>>) {
    for mut usages in &mut cameras {
        if !usages.0.contains(wgpu::TextureUsages::COPY_DST) {
            usages.0 |= wgpu::TextureUsages::COPY_DST;
        }
    }
}

/// Reads each marked light's gobo image into a [`CrepuscularGobo`] when it is loaded, when the
/// handle changes, or when the image is edited in place (`Assets::get_mut`, a hot reload: its
/// `AssetEvent::Modified`); an image that cannot be read is logged once per version, naming the
/// light and format.
fn read_gobos(
    mut commands: Commands,
    lights: Query<(Entity, &CrepuscularLight, Option<&CrepuscularGobo>)>,
    images: Res<Assets<Image>>,
    mut events: MessageReader<AssetEvent<Image>>,
    mut failed: Local<HashMap<Entity, AssetId<Image>>>,
) {
    let modified: Vec<AssetId<Image>> = events
        .read()
        .filter_map(|e| match e {
            AssetEvent::Modified { id } => Some(*id),
            _ => None,
        })
        .collect();
    for (entity, light, gobo) in &lights {
        match (&light.texture, gobo) {
            (None, Some(_)) => {
                commands.entity(entity).remove::<CrepuscularGobo>();
            }
            (Some(handle), g) if g.is_none_or(|g| g.image != handle.id()) || modified.contains(&handle.id()) => {
                let Some(image) = images.get(handle) else { continue };
                if modified.contains(&handle.id()) {
                    failed.remove(&entity);
                }
                if failed.get(&entity) == Some(&handle.id()) {
                    continue;
                }
                match gobo_texels(image) {
                    Ok(texture) => {
                        failed.remove(&entity);
                        commands
                            .entity(entity)
                            .insert(CrepuscularGobo { image: handle.id(), texture: Arc::new(texture) });
                    }
                    Err(e) => {
                        error!("crepuscular: light {entity}: CrepuscularLight::texture: {e}");
                        failed.insert(entity, handle.id());
                    }
                }
            }
            _ => {}
        }
    }
}

/// A Bevy image as linear RGB texels (sRGB formats decoded).
pub fn gobo_texels(image: &Image) -> Result<crepuscular::RgbTexture, String> {
    let format = image.texture_descriptor.format;
    let dynamic = image.clone().try_into_dynamic().map_err(|e| format!("an image of format {format:?}: {e}"))?;
    let rgba = dynamic.to_rgba32f();
    let decode = |c: f32| if c <= 0.04045 { c / 12.92 } else { ((c + 0.055) / 1.055).powf(2.4) };
    let srgb = format.is_srgb();
    let texels = rgba
        .pixels()
        .map(|p| {
            let [r, g, b, a] = p.0;
            if srgb { [decode(r), decode(g), decode(b), a] } else { [r, g, b, a] }
        })
        .collect::<Vec<_>>();
    if texels.iter().any(|t| t.iter().any(|v| !v.is_finite() || *v < 0.0)) {
        return Err(format!("an image of format {format:?} with negative or non-finite texels"));
    }
    Ok(crepuscular::RgbTexture { width: rgba.width(), height: rgba.height(), texels })
}

/// A copy of one frame's inputs and output, for tests and tools that check the plugin against
/// the library: insert a `CrepuscularCapture` resource into the app, run frames, then
/// [`CrepuscularCapture::take`] the newest captured frame. Costs three texture copies per frame
/// while the resource exists.
#[derive(Resource, Clone, Default)]
pub struct CrepuscularCapture(Arc<Mutex<Option<CapturedFrame>>>);

impl CrepuscularCapture {
    /// The newest frame captured, if one was.
    pub fn take(&self) -> Option<CapturedFrame> {
        self.0.lock().ok()?.take()
    }
}

/// The effect's statistics per camera, for tools and overlays: insert a `CrepuscularStats`
/// resource into the app and read [`CrepuscularStats::get`] with the camera's entity. While it
/// exists every camera's technique runs with `StatsMode::Deferred`: its GPU timestamps (on an
/// adapter with timestamp queries; none on a software one, where `timing` says `unmeasured`)
/// and counters (samples, nodes per ray, …) are recorded into Bevy's encoder and read back a
/// frame or more later, never stalling the frame; without it the effect records none
/// (`StatsMode::Off`). What arrives is the newest frame whose readbacks have finished.
#[derive(Resource, Clone, Default)]
pub struct CrepuscularStats(Arc<Mutex<HashMap<Entity, crepuscular::stats::TechniqueStats>>>);

impl CrepuscularStats {
    /// The newest statistics of camera `camera` (its main-world entity), once they arrived.
    pub fn get(&self, camera: Entity) -> Option<crepuscular::stats::TechniqueStats> {
        self.0.lock().ok()?.get(&camera).cloned()
    }
}

/// One frame as the plugin handed it to the library.
pub struct CapturedFrame {
    /// The frame description (camera, lights with their projections and layers, medium, size).
    pub desc: FrameDesc,
    /// The technique settings used.
    pub technique: TechniqueSettings,
    /// Bevy's depth buffer after the main pass (`Depth32Float`).
    pub depth: wgpu::Texture,
    /// The shadow array the library read (`R32Float`, the lights' layers).
    pub shadow_maps: wgpu::Texture,
    /// The in-scattering the plugin computed (in `Crepuscular::output_format`).
    pub inscatter: wgpu::Texture,
    /// With [`CrepuscularTemporal`]: the stage's output (what was composited) and what it
    /// read.
    pub temporal: Option<CapturedTemporal>,
}

/// The temporal stage's part of a [`CapturedFrame`].
pub struct CapturedTemporal {
    /// The stage's settings this frame.
    pub settings: TemporalSettings,
    /// Whether the stage dropped its history before this frame (a cut, a technique switch,
    /// the first frame).
    pub reset: bool,
    /// The resolved in-scattering (in `Crepuscular::output_format`).
    pub resolved: wgpu::Texture,
    /// Whether the stage read Bevy's motion vectors (their texture has no `COPY_SRC`, so it
    /// is not copied).
    pub motion_vectors: bool,
}

impl Plugin for CrepuscularPlugin {
    fn build(&self, app: &mut App) {
        app.add_plugins((
            ExtractComponentPlugin::<Crepuscular>::default(),
            ExtractComponentPlugin::<CrepuscularTemporal>::default(),
            ExtractComponentPlugin::<CrepuscularLight>::default(),
            ExtractComponentPlugin::<CrepuscularGobo>::default(),
        ))
        .add_systems(PostUpdate, (read_gobos, main_texture_copy_dst));
        let Some(render_app) = app.get_sub_app_mut(RenderApp) else {
            return;
        };
        render_app
            .init_resource::<ViewStates>()
            .add_systems(bevy::render::ExtractSchedule, (extract_capture, extract_stats))
            .add_systems(
                Render,
                (
                    depth_texture_binding.in_set(RenderSystems::Prepare).before(prepare_core_3d_depth_textures),
                    forget_views.in_set(RenderSystems::Prepare),
                    publish_stats.in_set(RenderSystems::Cleanup),
                ),
            )
            .add_systems(Core3d, scatter.after(Core3dSystems::MainPass).before(Core3dSystems::EarlyPostProcess));
    }
}

fn extract_capture(mut commands: Commands, capture: bevy::render::Extract<Option<Res<CrepuscularCapture>>>) {
    match capture.as_ref() {
        Some(c) => commands.insert_resource((**c).clone()),
        None => commands.remove_resource::<CrepuscularCapture>(),
    }
}

fn extract_stats(mut commands: Commands, stats: bevy::render::Extract<Option<Res<CrepuscularStats>>>) {
    match stats.as_ref() {
        Some(c) => commands.insert_resource((**c).clone()),
        None => commands.remove_resource::<CrepuscularStats>(),
    }
}

/// After Bevy submitted the frame (`RenderSystems::Cleanup` follows the render graph's
/// submit): each view's `Scattering::end_frame` starts the readback of what it recorded, and
/// the newest statistics that arrived go to [`CrepuscularStats`].
fn publish_stats(states: Res<ViewStates>, stats: Option<Res<CrepuscularStats>>) {
    let Ok(mut states) = states.0.lock() else { return };
    for state in states.values_mut() {
        state.scattering.end_frame();
        // Only measured frames: right after the resource appears, the newest stats may still
        // be those of a frame encoded with statistics off (no counters, `timing` "off").
        if let (Some(stats), Some(main)) = (&stats, state.main)
            && let Some(s) = state.scattering.stats()
            && s.timing != "off"
            && let Ok(mut map) = stats.0.lock()
        {
            map.insert(main, s.clone());
        }
    }
}

/// The library samples Bevy's depth buffer: it needs `TEXTURE_BINDING` (Bevy's own volumetric
/// fog asks for the same), and a capture copies it (`COPY_SRC`).
fn depth_texture_binding(
    mut cameras: Query<&mut Camera3d, With<Crepuscular>>,
    capture: Option<Res<CrepuscularCapture>>,
) {
    let mut usage = wgpu::TextureUsages::TEXTURE_BINDING;
    if capture.is_some() {
        usage |= wgpu::TextureUsages::COPY_SRC;
    }
    for mut camera in &mut cameras {
        camera.depth_texture_usages.0 |= usage.bits();
    }
}

/// Drops the state of cameras that no longer have [`Crepuscular`] (or no longer exist): their
/// pipelines and textures are freed.
fn forget_views(states: Res<ViewStates>, views: Query<Entity, With<Crepuscular>>) {
    if let Ok(mut states) = states.0.lock() {
        states.retain(|e, _| views.contains(*e));
    }
}

/// Per view: the technique, the composite, the shadow copy and the textures they own, built
/// on the first frame and kept (rebuilt only on resize or a format change; a settings change
/// goes through `Scattering::update`).
#[derive(Resource, Default)]
struct ViewStates(Mutex<HashMap<Entity, ViewState>>);

struct ViewState {
    scattering: Scattering,
    /// The stage, where the camera has [`CrepuscularTemporal`].
    temporal: Option<TemporalState>,
    composite: Composite,
    shadow_copy: ShadowCopy,
    inscatter: Option<wgpu::Texture>,
    /// The gobos of the last frame and their array.
    gobos: Vec<Arc<crepuscular::RgbTexture>>,
    gobo_array: Option<wgpu::TextureView>,
    /// The settings the technique last encoded with (jittered under the stage).
    technique: TechniqueSettings,
    /// The settings the camera asked for (a change drops the stage's history).
    asked: TechniqueSettings,
    /// The camera's main-world entity ([`CrepuscularStats`] is keyed by it).
    main: Option<Entity>,
    /// The last error, logged once until it changes.
    last_error: Option<String>,
}

/// The temporal stage of one view and its output.
struct TemporalState {
    stage: Temporal,
    resolved: Option<wgpu::Texture>,
    /// Frames encoded since the stage was made or last reset (the jitter's `frame_index`).
    frame: u32,
    /// The component's cut count last seen.
    cuts: u32,
}

#[allow(clippy::too_many_arguments, clippy::type_complexity)]
fn scatter(
    view: ViewQuery<(
        Entity,
        &ExtractedView,
        &ExtractedCamera,
        &ViewTarget,
        &ViewDepthTexture,
        &Crepuscular,
        Option<&ViewShadowBindings>,
        Option<&Msaa>,
        Option<&RenderLayers>,
        &bevy::render::sync_world::MainEntity,
        Option<&CrepuscularTemporal>,
        Option<&ViewPrepassTextures>,
    )>,
    directional: Query<(Entity, &ExtractedDirectionalLight, Option<&RenderLayers>, Option<&CrepuscularLight>)>,
    points: Query<(
        Entity,
        &ExtractedPointLight,
        &PointAndSpotLightViewEntities,
        Option<&CrepuscularLight>,
        Option<&CrepuscularGobo>,
    )>,
    shadow_views: Query<&ExtractedView>,
    cluster_meta: Option<Res<GlobalClusterableObjectMeta>>,
    capture: Option<Res<CrepuscularCapture>>,
    stats: Option<Res<CrepuscularStats>>,
    states: Res<ViewStates>,
    device: Res<RenderDevice>,
    queue: Res<RenderQueue>,
    mut ctx: RenderContext,
) {
    let (entity, extracted, camera, target, depth, settings, shadows, msaa, layers, main, temporal, prepass) =
        view.into_inner();
    let device_w = device.wgpu_device();
    let queue_w: &wgpu::Queue = &queue.0;
    let Some(size) = camera.physical_viewport_size else { return };
    let (width, height) = (size.x, size.y);
    if width == 0 || height == 0 {
        return;
    }
    let Ok(mut states) = states.0.lock() else { return };
    let state = match states.get_mut(&entity) {
        Some(s) => s,
        None => match new_state(device_w, queue_w, settings) {
            Ok(s) => states.entry(entity).or_insert(s),
            Err(e) => {
                error!("crepuscular: {e}");
                return;
            }
        },
    };
    let result = (|| -> Result<(), String> {
        if msaa.is_some_and(|m| *m != Msaa::Off) {
            return Err("the camera must have Msaa::Off (the effect reads a single-sample depth buffer)".into());
        }
        let Some(shadows) = shadows else { return Err("the view has no shadow bindings yet".into()) };
        // The stage: made when the component appears, dropped with it; its history dropped on
        // a cut or when the camera asks for other technique settings.
        match (temporal, &mut state.temporal) {
            (None, t) => *t = None,
            (Some(c), None) => {
                let stage = Temporal::new(device_w, c.settings).map_err(|e| e.to_string())?;
                state.temporal = Some(TemporalState { stage, resolved: None, frame: 0, cuts: c.cuts });
            }
            (Some(c), Some(t)) => {
                if t.stage.settings() != c.settings {
                    t.stage.set_settings(c.settings).map_err(|e| e.to_string())?;
                }
                if t.cuts != c.cuts || state.asked != settings.technique {
                    // The jitter's sequence restarts with the history (its first frames are
                    // then the best spread).
                    t.stage.reset();
                    t.cuts = c.cuts;
                    t.frame = 0;
                }
            }
        }
        state.asked = settings.technique.clone();
        // Under the stage the samples move every frame (no pipeline change).
        let wanted = match &state.temporal {
            Some(t) => settings.technique.jittered(t.frame),
            None => settings.technique.clone(),
        };
        // Settings of the same technique change in place (pipelines kept); another technique
        // or output format builds its pipelines once, here.
        let same_technique =
            state.technique == wanted || state.scattering.update(&wanted).map_err(|e| e.to_string())?;
        if !same_technique || state.scattering.output_format() != settings.output_format {
            state.scattering = new_scattering(device_w, queue_w, &wanted, settings.output_format)?;
            state.inscatter = None;
        }
        state.technique = wanted;
        state.main = Some(main.id());
        // Statistics only while a CrepuscularStats resource asks for them.
        let mode = if stats.is_some() { StatsMode::Deferred } else { StatsMode::Off };
        if state.scattering.stats_mode() != mode {
            state.scattering.set_stats_mode(mode).map_err(|e| e.to_string())?;
        }
        // The lights and where their maps are (docs/BEVY.md "Shadow maps").
        let lights = convert::LightsInView {
            view: entity,
            view_layers: layers.cloned().unwrap_or_default(),
            cascade: settings.cascade,
            exposure: camera.exposure,
            directional_size: shadows.directional_light_depth_texture.width(),
            point_size: shadows.point_light_depth_texture.width(),
        };
        let directional: Vec<_> = directional.iter().collect();
        let points: Vec<_> = points.iter().collect();
        let (frame_lights, jobs, gobos) =
            lights.collect(&directional, &points, &shadow_views, cluster_meta.as_deref())?;
        if frame_lights.is_empty() {
            return Err("no light with CrepuscularLight and shadow maps enabled reaches this camera".into());
        }
        let world_from_view = extracted.world_from_view.to_matrix();
        let frame_camera = FrameCamera::new(
            to_glam_mat(world_from_view.inverse()),
            to_glam_mat(extracted.clip_from_view),
            DepthConvention::Reversed,
            Some(settings.far),
        )
        .map_err(|e| e.to_string())?;
        let desc = FrameDesc { camera: frame_camera, lights: frame_lights, medium: settings.medium(), width, height };
        let encoder = ctx.command_encoder();
        let shadow_array = state.shadow_copy.encode(device_w, encoder, shadows, &jobs)?;
        let inscatter = match &state.inscatter {
            Some(t) if (t.width(), t.height()) == (width, height) => t.clone(),
            _ => {
                let t = crepuscular::gpu::storage_texture(
                    device_w,
                    "crepuscular inscatter",
                    settings.output_format,
                    width,
                    height,
                );
                state.inscatter = Some(t.clone());
                t
            }
        };
        let inscatter_view = inscatter.create_view(&Default::default());
        let depth_view = depth
            .texture
            .create_view(&wgpu::TextureViewDescriptor { aspect: wgpu::TextureAspect::DepthOnly, ..Default::default() });
        let shadow_view = shadow_array.create_view(&wgpu::TextureViewDescriptor {
            dimension: Some(wgpu::TextureViewDimension::D2Array),
            ..Default::default()
        });
        // The gobos, one layer each, uploaded when the set changes.
        let same = state.gobos.len() == gobos.len() && state.gobos.iter().zip(&gobos).all(|(a, b)| Arc::ptr_eq(a, b));
        if !same {
            let refs: Vec<&crepuscular::RgbTexture> = gobos.iter().map(|g| g.as_ref()).collect();
            state.gobo_array = (!gobos.is_empty()).then(|| {
                crepuscular::GpuContext::from_device(device_w, queue_w).upload_spot_textures(&refs).create_view(
                    &wgpu::TextureViewDescriptor {
                        dimension: Some(wgpu::TextureViewDimension::D2Array),
                        ..Default::default()
                    },
                )
            });
            state.gobos = gobos;
        }
        let frame = GpuFrame {
            desc: &desc,
            depth: &depth_view,
            shadow_maps: &shadow_view,
            spot_textures: state.gobo_array.as_ref(),
            rectified_shadow_maps: &[],
        };
        state.scattering.encode(encoder, &frame, &inscatter_view).map_err(|e| e.to_string())?;
        // The stage: this frame blended with the history into `resolved`, which is composited.
        let mut captured_temporal = None;
        let composited = match &mut state.temporal {
            None => inscatter_view.clone(),
            Some(t) => {
                let resolved = match &t.resolved {
                    Some(r) if (r.width(), r.height(), r.format()) == (width, height, settings.output_format) => {
                        r.clone()
                    }
                    _ => {
                        let r = crepuscular::gpu::storage_texture(
                            device_w,
                            "crepuscular resolved",
                            settings.output_format,
                            width,
                            height,
                        );
                        t.resolved = Some(r.clone());
                        r
                    }
                };
                let motion = temporal
                    .filter(|c| c.motion_vectors)
                    .and_then(|_| prepass.and_then(|p| p.motion_vectors.as_ref()))
                    .map(|m| &m.texture.texture);
                let motion_view = motion.map(|m| m.create_view(&Default::default()));
                let resolved_view = resolved.create_view(&Default::default());
                let reset = !t.stage.has_history();
                t.stage
                    .encode(encoder, &desc, &depth_view, &inscatter_view, &resolved_view, motion_view.as_deref())
                    .map_err(|e| e.to_string())?;
                t.frame = t.frame.wrapping_add(1);
                if capture.is_some() {
                    captured_temporal = Some(CapturedTemporal {
                        settings: t.stage.settings(),
                        reset,
                        resolved: copy_of(device_w, encoder, &resolved, "crepuscular capture resolved"),
                        motion_vectors: motion.is_some(),
                    });
                }
                resolved_view
            }
        };
        // L = T(s)·L_surface + L_scatt into Bevy's HDR target, before its tone mapping.
        let post = target.post_process_write();
        let inputs = CompositeInputs { desc: &desc, depth: &depth_view, inscatter: &composited, surface: post.source };
        if let Err(e) = state.composite.encode(encoder, &inputs, CompositeTarget::Into(post.destination), None) {
            // The main texture has already flipped to `destination`: keep Bevy's picture in it.
            encoder.copy_texture_to_texture(
                post.source_texture.as_image_copy(),
                post.destination_texture.as_image_copy(),
                post.source_texture.size(),
            );
            return Err(e.to_string());
        }
        if let Some(capture) = &capture {
            let mut frame =
                capture_frame(device_w, encoder, &desc, &state.technique, &depth.texture, &shadow_array, &inscatter);
            frame.temporal = captured_temporal;
            if let Ok(mut slot) = capture.0.lock() {
                *slot = Some(frame);
            }
        }
        Ok(())
    })();
    match result {
        Ok(()) => state.last_error = None,
        Err(e) => {
            if state.last_error.as_deref() != Some(e.as_str()) {
                error!("crepuscular (camera {entity}): {e}");
                state.last_error = Some(e);
            }
        }
    }
}

fn new_scattering(
    device: &wgpu::Device,
    queue: &wgpu::Queue,
    technique: &TechniqueSettings,
    format: wgpu::TextureFormat,
) -> Result<Scattering, String> {
    Scattering::new(device, queue, technique.clone())
        .and_then(|s| s.with_stats(StatsMode::Off))
        .and_then(|s| s.with_output_format(format))
        .map_err(|e| e.to_string())
}

fn new_state(device: &wgpu::Device, queue: &wgpu::Queue, settings: &Crepuscular) -> Result<ViewState, String> {
    Ok(ViewState {
        scattering: new_scattering(device, queue, &settings.technique, settings.output_format)?,
        temporal: None,
        asked: settings.technique.clone(),
        composite: Composite::new(device).map_err(|e| e.to_string())?,
        shadow_copy: ShadowCopy::new(device),
        inscatter: None,
        gobos: Vec::new(),
        gobo_array: None,
        technique: settings.technique.clone(),
        main: None,
        last_error: None,
    })
}

fn copy_of(
    device: &wgpu::Device,
    encoder: &mut wgpu::CommandEncoder,
    src: &wgpu::Texture,
    label: &str,
) -> wgpu::Texture {
    let t = device.create_texture(&wgpu::TextureDescriptor {
        label: Some(label),
        size: src.size(),
        mip_level_count: 1,
        sample_count: 1,
        dimension: wgpu::TextureDimension::D2,
        format: src.format(),
        usage: wgpu::TextureUsages::COPY_DST | wgpu::TextureUsages::COPY_SRC | wgpu::TextureUsages::TEXTURE_BINDING,
        view_formats: &[],
    });
    encoder.copy_texture_to_texture(src.as_image_copy(), t.as_image_copy(), src.size());
    t
}

fn capture_frame(
    device: &wgpu::Device,
    encoder: &mut wgpu::CommandEncoder,
    desc: &FrameDesc,
    technique: &TechniqueSettings,
    depth: &wgpu::Texture,
    shadow_maps: &wgpu::Texture,
    inscatter: &wgpu::Texture,
) -> CapturedFrame {
    CapturedFrame {
        desc: desc.clone(),
        technique: technique.clone(),
        depth: copy_of(device, encoder, depth, "crepuscular capture depth"),
        shadow_maps: copy_of(device, encoder, shadow_maps, "crepuscular capture shadow maps"),
        inscatter: copy_of(device, encoder, inscatter, "crepuscular capture inscatter"),
        temporal: None,
    }
}

pub(crate) fn to_glam_mat(m: Mat4) -> glam::Mat4 {
    glam::Mat4::from_cols_array(&m.to_cols_array())
}
