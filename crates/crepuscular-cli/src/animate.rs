//! `crepuscular animate`: the camera and the light move along a built-in, looping path; every
//! frame is rendered with a technique and the tone-mapped frames become an animated GIF. With
//! `--flicker`, `reference` is rendered on the same host frames and the temporal stability of
//! the technique's error is measured ([`FlickerMeter`]); `crepuscular bench --flicker-frames`
//! uses the same machinery.
//!
//! The path is a function of t (one loop per unit of t, so frame i of N sits at t = i/N and the
//! GIF loops without a jump): the camera orbits its `look_at` point about the vertical axis and
//! dollies towards it, the light sweeps (directional: travel direction; spot: aim; point:
//! position). t = 0 is the scene exactly as `render` draws it.

use crate::metrics::Quality;
use crate::render::{self, frame_desc, load_scene, parse_technique};
use anyhow::{Context, Result, bail};
use crepuscular::frame::{FrameDesc, surface_transmittance};
use crepuscular::gpu::GpuContext;
use crepuscular::stats::TechniqueStats;
use crepuscular::temporal::{CpuTemporal, Temporal, TemporalSettings};
use crepuscular::tonemap::{ToneMap, composite};
use crepuscular::{Camera, CpuFrame, Image, Light, ShadowMap};
use crepuscular::{Scattering, TechniqueSettings};
use crepuscular_scene::{Geometry, GpuHost, HostTextures, Scene, builtin, host, host_cpu};
use glam::{Quat, Vec3};
use serde::Serialize;
use std::io::Write;
use std::path::{Path, PathBuf};

/// Frames of an animation when `--frames` is not given: one loop of the path.
pub const DEFAULT_FRAMES: u32 = 24;
/// Most frames `animate` renders.
pub const MAX_FRAMES: u32 = 3600;
/// Frame size when `--size` is not given (animations are previews: small and quick).
pub const DEFAULT_SIZE: (u32, u32) = (320, 180);
/// Largest width or height of an animation frame, pixels.
pub const MAX_SIDE: u32 = 4096;
/// Frames per second of the GIF when `--fps` is not given.
pub const DEFAULT_FPS: u32 = 12;
/// Steps per pixel of the reference `--flicker` renders when `--reference-steps` is not given.
pub const DEFAULT_REFERENCE_STEPS: u32 = 256;
/// GIF colour quantisation speed (NeuQuant sampling factor, 1 = best and slowest … 30).
const GIF_SPEED: i32 = 10;

/// A deterministic, looping motion of the camera and the light, a function of t with period 1
/// (φ = 2πt). Every term vanishes at t = 0, where the scene is exactly as defined.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct MotionPath {
    /// Camera orbit about the vertical axis through `look_at`: yaw = A·sin φ, A in degrees.
    pub orbit_degrees: f32,
    /// Camera dolly towards `look_at`: the eye–target distance is scaled by
    /// 1 − D·(1 − cos φ)/2, so D (in [0, 1)) is the largest fraction removed, at t = ½.
    pub dolly: f32,
    /// Light sweep about the vertical axis: A·sin φ, A in degrees. Directional light: its
    /// travel direction; spot: its aim (the position stays); point light: unused.
    pub light_yaw_degrees: f32,
    /// Light tilt about the horizontal axis perpendicular to its direction: A·sin 2φ, A in
    /// degrees (directional and spot lights).
    pub light_pitch_degrees: f32,
    /// Point light displacement, metres: (x·sin φ, y·sin 2φ, z·(1 − cos φ)/2).
    pub point_offset: [f32; 3],
}

impl MotionPath {
    /// The path of a built-in scene (by the name it was loaded with, options such as
    /// `:shadow_filter=bilinear` aside: [`crate::render::scene_base`]), else
    /// [`MotionPath::generic`].
    pub fn for_scene(name_or_path: &str, scene: &Scene) -> Self {
        let name_or_path = crate::render::scene_base(name_or_path);
        let p = |orbit_degrees, dolly, light_yaw_degrees, light_pitch_degrees, point_offset| MotionPath {
            orbit_degrees,
            dolly,
            light_yaw_degrees,
            light_pitch_degrees,
            point_offset,
        };
        if builtin::builtin(name_or_path).is_none() {
            return Self::generic(scene);
        }
        match name_or_path {
            // The sun slides along the colonnade: shafts sweep between the columns.
            "colonnade" => p(6.0, 0.10, 5.0, 1.5, [0.0; 3]),
            // Through the canopy: the shaft pattern changes everywhere at once.
            "forest" => p(5.0, 0.10, 6.0, 2.0, [0.0; 3]),
            // The spot's aim sweeps: the stained-glass slab walks across the floor.
            "stained-glass" => p(8.0, 0.08, 2.5, 2.0, [0.0; 3]),
            // The light wanders inside the lantern (bars at ±1.6 m): every beam swings.
            "cage" => p(12.0, 0.08, 0.0, 0.0, [0.5, 0.35, 0.5]),
            // A grazing sun over the ridge: ±1° of elevation moves the notch's shafts a lot.
            "terrain" => p(4.0, 0.06, 5.0, 1.0, [0.0; 3]),
            _ => Self::generic(scene),
        }
    }

    /// The path of any scene: an 8° orbit and 5 % dolly, the light swept by 6° (tilted by 2°), a
    /// point light moved by 5 % of its distance to the camera's `look_at` (0.05–1 m) per axis.
    pub fn generic(scene: &Scene) -> Self {
        // From the first point light (every point light moves by the same offsets).
        let offset = scene
            .lights
            .iter()
            .find_map(|l| match &l.light {
                Light::Point { position, .. } => {
                    Some((0.05 * position.distance(scene.camera.look_at)).clamp(0.05, 1.0))
                }
                _ => None,
            })
            .unwrap_or(0.0);
        MotionPath {
            orbit_degrees: 8.0,
            dolly: 0.05,
            light_yaw_degrees: 6.0,
            light_pitch_degrees: 2.0,
            point_offset: [offset; 3],
        }
    }

    /// This path with the lights held still (only the camera moves).
    pub fn still_lights(self) -> Self {
        MotionPath { light_yaw_degrees: 0.0, light_pitch_degrees: 0.0, point_offset: [0.0; 3], ..self }
    }

    /// The camera and one light at `t` (period 1), from the scene's own (every light of a
    /// scene moves by the same rule).
    /// Whole t (the start of a loop) gives the scene's own camera and light, bit for bit.
    pub fn pose(&self, camera: &Camera, light: &Light, t: f64) -> (Camera, Light) {
        if t.fract() == 0.0 {
            return (camera.clone(), light.clone());
        }
        let phi = std::f64::consts::TAU * t;
        let (s1, c1, s2) = (phi.sin() as f32, phi.cos() as f32, (2.0 * phi).sin() as f32);
        let mut cam = camera.clone();
        let v = camera.position - camera.look_at;
        let yaw = Quat::from_rotation_y(self.orbit_degrees.to_radians() * s1);
        let scale = 1.0 - self.dolly * (1.0 - c1) * 0.5;
        cam.position = camera.look_at + yaw * v * scale;
        let sweep = |d: Vec3| -> Vec3 {
            let d = Quat::from_rotation_y(self.light_yaw_degrees.to_radians() * s1) * d;
            let axis = d.cross(Vec3::Y);
            let d = if axis.length() > 1e-4 {
                Quat::from_axis_angle(axis.normalize(), self.light_pitch_degrees.to_radians() * s2) * d
            } else {
                d
            };
            d.normalize()
        };
        let mut l = light.clone();
        match &mut l {
            Light::Directional { direction, .. } | Light::Spot { direction, .. } => *direction = sweep(*direction),
            Light::Point { position, .. } => {
                let [x, y, z] = self.point_offset;
                *position += Vec3::new(x * s1, y * s2, z * (1.0 - c1) * 0.5);
            }
        }
        (cam, l)
    }
}

/// t of frame `i` of `frames`. With `spread` (what `animate` does) the frames cover exactly one
/// loop, t = i/frames, so the GIF loops without a jump. Without it (what `bench` does) frames are
/// 1/[`DEFAULT_FRAMES`] of the loop apart whatever their count, t = i/24, so the motion between
/// frames — and with it the flicker measure — does not depend on how many frames are measured,
/// and equals that of a default `animate` run.
pub fn frame_time(i: u32, frames: u32, spread: bool) -> f64 {
    if spread { i as f64 / frames.max(1) as f64 } else { i as f64 / DEFAULT_FRAMES as f64 }
}

/// The host frame at one point of the path: depth, surface, shadow map (read back to the CPU
/// only when a CPU technique needs it).
pub struct HostFrame {
    /// Path parameter.
    pub t: f64,
    /// The frame description (posed camera and light).
    pub desc: FrameDesc,
    /// Camera depth, [0, 1].
    pub depth: Vec<f32>,
    /// Surface radiance.
    pub surface: Image,
    /// Transmittance to the visible surface, per pixel (for compositing).
    pub transmittance: Vec<[f32; 3]>,
    /// The frame's motion vectors, as an engine's prepass writes them
    /// ([`crepuscular_scene::raster::motion_vectors`]; zero on the first frame), when the
    /// renderer makes them ([`PathRenderer::motion_vectors`]).
    pub motion: Option<Vec<[f32; 2]>>,
    /// The same on the GPU (`Rgba32Float`, x and y in R and G), when the frame came from it.
    motion_texture: Option<wgpu::Texture>,
    shadow_maps: Option<Vec<ShadowMap>>,
    textures: Option<HostTextures>,
}

impl HostFrame {
    /// The CPU shadow maps, one per light (read back from the GPU on first use).
    fn shadow_maps(&mut self, gpu: Option<&GpuContext>) -> Result<&[ShadowMap]> {
        if self.shadow_maps.is_none() {
            let (Some(g), Some(t)) = (gpu, &self.textures) else { bail!("no shadow map (internal error)") };
            self.shadow_maps = Some(host::read_shadow_maps(g, t, &self.desc)?);
        }
        self.shadow_maps.as_deref().context("no shadow map")
    }

    /// The final image from this frame's surface and an in-scattering image.
    pub fn final_radiance(&self, inscatter: &Image) -> Image {
        composite(&self.surface, inscatter, &self.transmittance)
    }
}

/// Renders host frames of one scene along its path (GPU pipelines built once).
pub struct PathRenderer<'g> {
    gpu: Option<&'g GpuContext>,
    host: Option<GpuHost>,
    scene: Scene,
    camera: Camera,
    lights: Vec<crepuscular_scene::SceneLight>,
    /// The path.
    pub path: MotionPath,
    /// Lights turned by this angle (degrees) about the vertical axis through the camera's
    /// `look_at`, on top of the path: a light jump ([`LIGHT_JUMP_DEGREES`]).
    pub light_turn_degrees: f32,
    /// Make each frame's motion vectors ([`HostFrame::motion`]), as an engine's prepass does,
    /// for the temporal stage. Costs one CPU rasterization of the frame. Default false.
    pub motion_vectors: bool,
    /// The scene's own triangles (without the occluder).
    base: Geometry,
    /// A box that moves across a shaft ([`PathRenderer::add_occluder`]).
    occluder: Option<Occluder>,
    /// The previous frame's world → clip matrix and vertex positions (for motion vectors).
    previous: Option<(glam::Mat4, Vec<[f32; 3]>)>,
}

/// A box that `animate --occluder-jump` adds to the scene and moves sideways in one frame (an
/// occluder crossing a shaft): the temporal stage's ghosting behind a moving object. Its own
/// surface moves with the motion vectors; the shaft it casts moves where no surface does.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Occluder {
    /// Centre before the jump, world space (metres).
    pub centre: Vec3,
    /// Half the side of the cube, metres.
    pub half_size: f32,
    /// Where the jump takes the centre: `centre + jump` (metres).
    pub jump: Vec3,
}

/// Where [`Occluder::for_scene`] may put the box: fractions of the way from the camera to its
/// `look_at` point.
const OCCLUDER_PLACES: [f32; 5] = [0.5, 0.4, 0.6, 0.3, 0.7];

impl Occluder {
    /// The box for `scene` (at t = 0 of its path): on the camera's line of sight to its
    /// `look_at` point, at the place of [`OCCLUDER_PLACES`] where the scene's lights (with their
    /// shadows, without the box) shine brightest, so the box casts a shaft into the view; its
    /// side a tenth of its distance to the eye, and the jump 1.5 sides to the camera's right,
    /// so the old and new shafts do not overlap. Errors on a scene whose frame is invalid.
    pub fn for_scene(scene: &Scene) -> Result<Self> {
        let desc = frame_desc(scene)?;
        let maps: Vec<ShadowMap> = desc
            .lights
            .iter()
            .map(|l| crepuscular_scene::raster::render_shadow_map(&scene.geometry, &l.shadow))
            .collect();
        let cam = &scene.camera;
        let lit = |p: Vec3| -> f64 {
            desc.lights
                .iter()
                .zip(&maps)
                .map(|(fl, m)| {
                    let (l, _) = crepuscular::integrand::lit_incident(fl, &desc.medium, m, p);
                    luminance(&l.extend(0.0).to_array())
                })
                .sum()
        };
        let mut best = (f64::NEG_INFINITY, OCCLUDER_PLACES[0]);
        for f in OCCLUDER_PLACES {
            let v = lit(cam.position + (cam.look_at - cam.position) * f);
            if v > best.0 {
                best = (v, f);
            }
        }
        let centre = cam.position + (cam.look_at - cam.position) * best.1;
        let half_size = 0.05 * centre.distance(cam.position);
        let forward = (cam.look_at - cam.position).normalize();
        let right = forward.cross(cam.up).normalize();
        Ok(Occluder { centre, half_size, jump: right * 3.0 * half_size })
    }

    /// The box's triangles (12, flat normals, albedo 0.5), before or after the jump.
    pub fn geometry(&self, jumped: bool) -> Geometry {
        let at = self.centre + if jumped { self.jump } else { Vec3::ZERO };
        crepuscular_scene::mesh::cuboid(
            &crepuscular_scene::mesh::Transform::at_scaled(at, Vec3::splat(2.0 * self.half_size)),
            Vec3::splat(0.5),
        )
    }
}

/// How far `animate --light-jump` turns the lights, degrees about the vertical axis through
/// the camera's `look_at` (a sun's travel, a spot's position and aim, a point light's position).
pub const LIGHT_JUMP_DEGREES: f32 = 20.0;

/// `l` turned by `degrees` about the vertical axis through `pivot`.
fn turn_light(l: &Light, degrees: f32, pivot: Vec3) -> Light {
    let q = Quat::from_rotation_y(degrees.to_radians());
    let mut l = l.clone();
    match &mut l {
        Light::Directional { direction, .. } => *direction = q * *direction,
        Light::Spot { position, direction, .. } => {
            *position = pivot + q * (*position - pivot);
            *direction = q * *direction;
        }
        Light::Point { position, .. } => *position = pivot + q * (*position - pivot),
    }
    l
}

impl<'g> PathRenderer<'g> {
    /// `scene` at its render size, moving along `path`.
    pub fn new(scene: Scene, path: MotionPath, gpu: Option<&'g GpuContext>) -> Result<Self> {
        let host = match gpu {
            Some(g) => {
                g.check_texture_size("image size", scene.render.width, scene.render.height)?;
                Some(GpuHost::for_scene(g, &scene)?)
            }
            None => None,
        };
        Ok(PathRenderer {
            gpu,
            host,
            camera: scene.camera.clone(),
            lights: scene.lights.clone(),
            base: scene.geometry.clone(),
            scene,
            path,
            light_turn_degrees: 0.0,
            motion_vectors: false,
            occluder: None,
            previous: None,
        })
    }

    /// Adds `occluder` to the scene from the next frame on (before its jump).
    pub fn add_occluder(&mut self, occluder: Occluder) {
        self.place_occluder(&occluder, false);
        self.occluder = Some(occluder);
    }

    /// Moves the occluder to its place after the jump from the next frame on (nothing without
    /// one).
    pub fn jump_occluder(&mut self) {
        if let Some(o) = self.occluder.clone() {
            self.place_occluder(&o, true);
        }
    }

    /// The scene's own triangles and `occluder`'s, before or after its jump, here and on the
    /// GPU host.
    fn place_occluder(&mut self, occluder: &Occluder, jumped: bool) {
        let mut g = self.base.clone();
        g.append(&occluder.geometry(jumped));
        if let (Some(gpu), Some(h)) = (self.gpu, &mut self.host) {
            h.set_geometry(gpu, &g);
        }
        self.scene.geometry = g;
    }

    /// The scene (at t = 0).
    pub fn scene(&self) -> &Scene {
        &self.scene
    }

    /// The host frame at `t`.
    pub fn frame(&mut self, t: f64) -> Result<HostFrame> {
        for (posed, own) in self.scene.lights.iter_mut().zip(&self.lights) {
            posed.light = self.path.pose(&self.camera, &own.light, t).1;
            if self.light_turn_degrees != 0.0 {
                posed.light = turn_light(&posed.light, self.light_turn_degrees, self.camera.look_at);
            }
        }
        self.scene.camera = self.path.pose(&self.camera, &self.lights[0].light, t).0;
        let desc = frame_desc(&self.scene)?;
        let (depth, surface, shadow_map, textures) = match (self.gpu, &self.host) {
            (Some(g), Some(h)) => {
                let tex = h.render(g, &desc)?;
                let depth = g.read_texture_f32(&tex.depth, 0)?;
                let surface = g.read_image(&tex.surface)?;
                (depth, surface, None, Some(tex))
            }
            _ => {
                let h = host_cpu::render(&self.scene.geometry, &self.scene.shading(), &desc);
                (h.depth, h.surface, Some(h.shadow_maps), None)
            }
        };
        let transmittance = surface_transmittance(&desc, &depth);
        let (motion, motion_texture) = if self.motion_vectors {
            let g = &self.scene.geometry;
            let vp = desc.camera.view_proj();
            let positions: Vec<[f32; 3]> = g.vertices.iter().map(|v| v.position).collect();
            let buffer = crepuscular_scene::raster::rasterize_with(g, vp, desc.width, desc.height, desc.camera.depth);
            let (prev_vp, prev) = self.previous.take().unwrap_or((vp, positions.clone()));
            let mv = crepuscular_scene::raster::motion_vectors(&buffer, g, &prev, prev_vp);
            self.previous = Some((vp, positions));
            let texture = self.gpu.map(|gpu| {
                let img = Image {
                    width: desc.width,
                    height: desc.height,
                    pixels: mv.iter().map(|m| [m[0], m[1], 0.0, 0.0]).collect(),
                };
                gpu.upload_image("motion vectors", &img)
            });
            (Some(mv), texture)
        } else {
            (None, None)
        };
        Ok(HostFrame {
            t,
            desc,
            depth,
            surface,
            transmittance,
            motion,
            motion_texture,
            shadow_maps: shadow_map,
            textures,
        })
    }
}

/// A technique rendered frame after frame: the settings of frame i are the scene's and the
/// overrides', with `frame_index` advanced by i where the technique marches
/// ([`TechniqueSettings::ray_march`]: temporal jitter). The GPU pipelines are built once.
pub struct AnimatedTechnique {
    name: String,
    frame_index: Option<u32>,
    gpu: Option<(serde_json::Value, Scattering, wgpu::Texture)>,
    /// Settings of frame 0.
    pub first: TechniqueSettings,
}

impl AnimatedTechnique {
    /// Parses the technique's settings (scene table + `key=value` overrides); errors name them.
    pub fn new(name: &str, scene: &Scene, overrides: &[String]) -> Result<Self> {
        let first = parse_technique(name, scene, overrides)?;
        Ok(AnimatedTechnique {
            name: name.into(),
            frame_index: first.ray_march().map(|m| m.frame_index),
            gpu: None,
            first,
        })
    }

    /// The technique's name.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// The GPU texture the last frame's in-scattering was rendered into (when it ran on the GPU).
    pub(crate) fn gpu_output(&self) -> Option<&wgpu::Texture> {
        self.gpu.as_ref().map(|(_, _, out)| out)
    }

    /// Whether frames advance the technique's `frame_index` setting.
    pub fn has_frame_index(&self) -> bool {
        self.frame_index.is_some()
    }

    /// Settings of frame `i`.
    pub fn settings(&self, i: u32) -> Result<TechniqueSettings> {
        let mut s = self.first.clone();
        if let (Some(base), Some(m)) = (self.frame_index, s.ray_march_mut()) {
            m.frame_index = base.wrapping_add(i);
        }
        Ok(s)
    }

    /// Renders frame `i` (the in-scattering) on `frame`: on the GPU when there is one and the
    /// technique runs there (over the GPU's textures), else on the CPU (over the GPU's shadow
    /// map and depth when the frame came from the GPU).
    pub fn render(
        &mut self,
        gpu: Option<&GpuContext>,
        frame: &mut HostFrame,
        i: u32,
        progress: &(dyn Fn(u64, u64) + Sync),
    ) -> Result<(Image, TechniqueStats)> {
        let choice = self.settings(i)?;
        let (img, stats) = match (gpu, &frame.textures) {
            (Some(g), Some(tex)) if crepuscular::techniques::find(&self.name).is_some_and(|t| t.gpu) => {
                let key = serde_json::to_value(&choice)?;
                let (w, h) = (frame.desc.width, frame.desc.height);
                let rebuild = match &mut self.gpu {
                    Some((k, _, out)) if out.width() != w || out.height() != h => {
                        *k = serde_json::Value::Null;
                        true
                    }
                    Some((k, _, _)) if *k == key => false,
                    Some((k, runner, _)) => {
                        let done = runner.update(&choice)?;
                        if done {
                            *k = key.clone();
                        }
                        !done
                    }
                    None => true,
                };
                if rebuild {
                    let runner = render::scattering(g, &choice)?.context("no GPU implementation")?;
                    self.gpu = Some((key, runner, g.create_output_texture(w, h)));
                }
                let (_, runner, out) = self.gpu.as_mut().context("no GPU runner")?;
                let out_view = out.create_view(&Default::default());
                let views = tex.views();
                let gf = views.frame(&frame.desc);
                let stats = render::render_gpu(runner, None, &gf, &out_view)?;
                (g.read_image(out)?, stats)
            }
            _ => {
                frame.shadow_maps(gpu)?;
                let sm = frame.shadow_maps.as_deref().context("no shadow map")?;
                let cf =
                    CpuFrame { desc: &frame.desc, depth: &frame.depth, shadow_maps: sm, surface: Some(&frame.surface) };
                render::render_cpu(&choice, &cf, None, progress)?
            }
        };
        if !img.all_finite() {
            bail!("{}: the technique produced non-finite values (NaN/Inf) — a bug, please report it", self.name);
        }
        Ok((img, stats))
    }
}

/// The temporal stability of a technique's error along a path.
///
/// With e_t = Y(technique_t) − Y(reference_t) per pixel, Y the linear Rec. 709 luminance
/// (0.2126 R + 0.7152 G + 0.0722 B) of the **in-scattering** (the final images differ by
/// exactly the same amount, since both add the same T·L_surface), flicker is the mean over
/// pixels and consecutive frame pairs of |e_{t+1} − e_t|. An error that stays put as the view
/// moves (a bias that moves with the scene) counts little; error that changes from frame to
/// frame — jitter noise, banding that crawls, shafts that pop in and out — counts fully.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Flicker {
    /// Mean |e_{t+1} − e_t| over pixels and frame pairs, in linear luminance (radiance units).
    pub mean_abs_change: f64,
    /// Mean Y of the reference over every pixel of every frame.
    pub mean_reference: f64,
    /// `mean_abs_change / mean_reference`: dimensionless, comparable across scenes (0 when both
    /// are 0). This is the number `bench` reports (as a percentage).
    pub relative: f64,
    /// For scale: the reference's own mean |Y(reference_{t+1}) − Y(reference_t)| — how much the
    /// picture itself changes between the frames (the motion).
    pub reference_change: f64,
    /// Frames measured (pairs = frames − 1).
    pub frames: u32,
}

/// Accumulates [`Flicker`] one frame at a time (only the previous error image is kept).
#[derive(Debug, Default)]
pub struct FlickerMeter {
    prev: Option<(Vec<f64>, Vec<f64>)>,
    size: (u32, u32),
    sum_reference_change: f64,
    sum_change: f64,
    changes: u64,
    sum_reference: f64,
    reference_pixels: u64,
    frames: u32,
}

fn luminance(p: &[f32; 4]) -> f64 {
    0.2126 * p[0] as f64 + 0.7152 * p[1] as f64 + 0.0722 * p[2] as f64
}

impl FlickerMeter {
    /// A meter with no frames.
    pub fn new() -> Self {
        Self::default()
    }

    /// Adds the next frame: the technique's and the reference's in-scattering of the same host
    /// frame. Errors if the sizes differ from each other or from the previous frames'.
    pub fn push(&mut self, technique: &Image, reference: &Image) -> Result<()> {
        let size = (technique.width, technique.height);
        if size != (reference.width, reference.height) {
            bail!(
                "flicker: technique frame is {}x{} but reference frame is {}x{}",
                size.0,
                size.1,
                reference.width,
                reference.height
            );
        }
        let n = size.0 as usize * size.1 as usize;
        if technique.pixels.len() != n || reference.pixels.len() != n || n == 0 {
            bail!("flicker: frame {} claims {}x{} but holds a different number of pixels", self.frames, size.0, size.1);
        }
        if self.frames > 0 && size != self.size {
            bail!(
                "flicker: frame {} is {}x{}, earlier frames are {}x{}",
                self.frames,
                size.0,
                size.1,
                self.size.0,
                self.size.1
            );
        }
        let y_ref: Vec<f64> = reference.pixels.iter().map(luminance).collect();
        let err: Vec<f64> = technique.pixels.iter().zip(&y_ref).map(|(t, r)| luminance(t) - r).collect();
        if let Some((prev_err, prev_ref)) = &self.prev {
            self.sum_change += err.iter().zip(prev_err).map(|(a, b)| (a - b).abs()).sum::<f64>();
            self.sum_reference_change += y_ref.iter().zip(prev_ref).map(|(a, b)| (a - b).abs()).sum::<f64>();
            self.changes += n as u64;
        }
        self.sum_reference += y_ref.iter().sum::<f64>();
        self.reference_pixels += n as u64;
        self.prev = Some((err, y_ref));
        self.size = size;
        self.frames += 1;
        Ok(())
    }

    /// The measure so far; errors with fewer than two frames. Non-finite pixels give NaN.
    pub fn finish(&self) -> Result<Flicker> {
        if self.frames < 2 {
            bail!("flicker needs at least 2 frames, got {}", self.frames);
        }
        let mean_abs_change = self.sum_change / self.changes as f64;
        let mean_reference = self.sum_reference / self.reference_pixels as f64;
        let relative = if mean_abs_change == 0.0 { 0.0 } else { mean_abs_change / mean_reference };
        let reference_change = self.sum_reference_change / self.changes as f64;
        Ok(Flicker { mean_abs_change, mean_reference, relative, reference_change, frames: self.frames })
    }
}

/// [`Flicker`] of a technique's frames against the reference's frames of the same path.
pub fn flicker(technique: &[Image], reference: &[Image]) -> Result<Flicker> {
    if technique.len() != reference.len() {
        bail!("flicker: {} technique frames but {} reference frames", technique.len(), reference.len());
    }
    let mut m = FlickerMeter::new();
    for (t, r) in technique.iter().zip(reference) {
        m.push(t, r)?;
    }
    m.finish()
}

/// What `crepuscular animate` does.
#[derive(Clone, Debug)]
pub struct AnimateOptions {
    /// Built-in scene name or scene file.
    pub scene: String,
    /// Technique name.
    pub technique: String,
    /// `key=value` technique settings.
    pub overrides: Vec<String>,
    /// Frames, 1..=[`MAX_FRAMES`].
    pub frames: u32,
    /// Frame size, each side 1..=[`MAX_SIDE`].
    pub size: (u32, u32),
    /// Shadow-map size override.
    pub shadow_map_size: Option<u32>,
    /// GIF frame rate, 1..=100.
    pub fps: u32,
    /// Also render `reference` and measure [`Flicker`].
    pub flicker: bool,
    /// Steps per pixel of that reference (even, ≥ 2).
    pub reference_steps: u32,
    /// Run the temporal stage after the technique on every frame ([`crepuscular::Temporal`] on
    /// the GPU, its CPU mirror on the CPU), with the technique's `jitter` on where it has one
    /// (unless set otherwise). With `flicker`, each frame's quality is measured with and without
    /// it ([`TemporalReport`]).
    pub temporal: Option<TemporalSettings>,
    /// Hold the lights still: only the camera moves ([`MotionPath::still_lights`]).
    pub still_lights: bool,
    /// Render only the first this many frames of the `frames`-frame path (a slow move over a
    /// few frames; the GIF then does not loop back). None: all.
    pub stop_after: Option<u32>,
    /// Turn every light by [`LIGHT_JUMP_DEGREES`] from this frame on (a light jump); with
    /// `--temporal --flicker` the report gives the frames the stage takes to recover.
    pub light_jump: Option<u32>,
    /// Add a box on the camera's line of sight ([`Occluder::for_scene`]) and move it sideways
    /// by 1.5 of its sides at this frame (an occluder crossing a shaft); with `--temporal
    /// --flicker` the report gives the frames the stage takes to recover. Not with
    /// `light_jump`.
    pub occluder_jump: Option<u32>,
    /// Write each frame's images into this directory (created if missing): the technique's
    /// in-scattering (`NNNN-technique.exr`, linear, and `.png`, the final image tone-mapped),
    /// with `temporal` the stage's output (`NNNN-temporal.exr`/`.png`) and its history weight
    /// per pixel (`NNNN-weight.png`), with `flicker` the reference (`NNNN-reference.exr`/`.png`)
    /// and the error maps against it (`NNNN-error-technique.png`, `NNNN-error-temporal.png`; the
    /// ramp's top at [`DUMP_ERROR_FULL_SCALE`] of the reference's peak).
    /// Cost: two or three image writes per frame (a few ms at 320×180).
    pub dump_frames: Option<PathBuf>,
    /// The GIF.
    pub output: PathBuf,
}

impl AnimateOptions {
    /// Frames rendered: `frames`, or `stop_after` when it is smaller.
    pub fn rendered(&self) -> u32 {
        self.stop_after.map_or(self.frames, |s| s.min(self.frames))
    }

    /// Checks every value before any work; errors name the option and value.
    pub fn validate(&self) -> Result<()> {
        if !(1..=MAX_FRAMES).contains(&self.frames) {
            bail!("--frames {}: must be in 1..={MAX_FRAMES}", self.frames);
        }
        let (w, h) = self.size;
        if w == 0 || h == 0 || w > MAX_SIDE || h > MAX_SIDE {
            bail!("--size {w}x{h}: animation frames must be 1..={MAX_SIDE} pixels per side");
        }
        if !(1..=100).contains(&self.fps) {
            bail!("--fps {}: must be in 1..=100", self.fps);
        }
        if let Some(s) = self.shadow_map_size
            && (s == 0 || s > 16384)
        {
            bail!("--shadow-map-size {s}: must be in 1..=16384");
        }
        if self.flicker {
            if self.frames < 2 {
                bail!("--flicker needs --frames ≥ 2 (it measures change between frames), got {}", self.frames);
            }
            if self.reference_steps < 2 || self.reference_steps % 2 != 0 || self.reference_steps > 1 << 20 {
                bail!("--reference-steps {}: must be even and in 2..=1048576", self.reference_steps);
            }
        }
        if let Some(t) = &self.temporal {
            t.validate().map_err(|e| anyhow::anyhow!("--temporal: {e}"))?;
        }
        if self.stop_after == Some(0) {
            bail!("--stop-after 0: must render at least one frame");
        }
        if let Some(k) = self.light_jump
            && (k == 0 || k >= self.rendered())
        {
            bail!("--light-jump {k}: must be a frame after the first and before the last ({})", self.rendered());
        }
        if let Some(k) = self.occluder_jump
            && (k == 0 || k >= self.rendered())
        {
            bail!("--occluder-jump {k}: must be a frame after the first and before the last ({})", self.rendered());
        }
        if self.light_jump.is_some() && self.occluder_jump.is_some() {
            bail!("--light-jump and --occluder-jump: give one at a time (each recovery is measured alone)");
        }
        if let Some(d) = &self.dump_frames
            && d.exists()
            && !d.is_dir()
        {
            bail!("--dump-frames {}: exists and is not a directory", d.display());
        }
        let parent = match self.output.parent() {
            Some(p) if !p.as_os_str().is_empty() => p,
            _ => Path::new("."),
        };
        if !parent.is_dir() {
            bail!("{}: the directory {} does not exist", self.output.display(), parent.display());
        }
        if self.output.file_name().is_none() {
            bail!("{}: not a file path", self.output.display());
        }
        Ok(())
    }
}

/// Everything [`run`] checks before it renders: the options, the scene and the technique
/// settings (so that a bad value fails before a GPU is opened).
pub fn check(opts: &AnimateOptions) -> Result<()> {
    opts.validate()?;
    let mut scene = load_scene(&opts.scene)?;
    (scene.render.width, scene.render.height) = opts.size;
    AnimatedTechnique::new(&opts.technique, &scene, &opts.overrides)?;
    Ok(())
}

/// What an animation run produced.
#[derive(Clone, Debug, Serialize)]
pub struct AnimateReport {
    /// Scene name.
    pub scene: String,
    /// Technique and frame 0's settings.
    pub settings: TechniqueSettings,
    /// Whether frames advanced `frame_index`.
    pub frame_index_advanced: bool,
    /// The path.
    pub path: MotionPath,
    /// Frames written.
    pub frames: u32,
    /// The technique's time per frame, ms, in frame order.
    pub technique_ms: Vec<f64>,
    /// Flicker vs reference (with `--flicker`; of the temporal stage's output with
    /// `--temporal`).
    pub flicker: Option<Flicker>,
    /// What the temporal stage did (with `--temporal`).
    pub temporal: Option<TemporalReport>,
    /// Bytes of the GIF.
    pub bytes: u64,
}

/// One frame's quality against its reference, with and without the temporal stage.
#[derive(Clone, Copy, Debug, Serialize)]
pub struct FrameQuality {
    /// PSNR of the technique's own in-scattering (dB).
    #[serde(with = "crate::metrics::psnr_serde")]
    pub psnr_db_without: f64,
    /// FLIP mean of its tone-mapped final image.
    pub flip_without: f64,
    /// PSNR after the temporal stage (dB).
    #[serde(with = "crate::metrics::psnr_serde")]
    pub psnr_db: f64,
    /// FLIP mean after the temporal stage.
    pub flip: f64,
    /// Mean history weight over the frame's pixels (0 where the history was rejected).
    pub mean_history_weight: f64,
    /// From a jump's frame on: PSNR of the technique's own in-scattering over the jump's
    /// region ([`JumpRegion`]), dB.
    pub region_psnr_db_without: Option<f64>,
    /// The same after the temporal stage (JSON `null` for identical pixels, as for `psnr_db`).
    pub region_psnr_db: Option<f64>,
}

/// Where a jump (of the lights or of the occluder) changed the picture: the pixels whose
/// reference in-scattering luminance changed between the frame before the jump and the jump's
/// frame by more than [`REGION_CHANGE`] of the larger of the two and by more than 2 % of the
/// jump frame's mean (so the slow camera move's own change stays out). The old and the new
/// shaft: where a ghost would be. Its PSNR uses the whole reference's peak, so it reads on the
/// same scale as the frame's.
#[derive(Clone, Debug, Serialize)]
pub struct JumpRegion {
    /// Pixels in the region.
    pub pixels: u32,
    /// Their fraction of the frame.
    pub fraction: f64,
    /// Frames from the jump until the stage's region PSNR is within 1 dB of its steady state
    /// (the mean of the last 4 frames rendered; at least 8 must follow the jump); None when
    /// never.
    pub recovery_frames: Option<u32>,
}

/// A pixel's change that counts it into a [`JumpRegion`]: this fraction of its larger value.
pub const REGION_CHANGE: f64 = 0.1;

/// The [`JumpRegion`] mask of `before` → `after` (reference in-scattering of the frames either
/// side of a jump).
pub fn jump_region(before: &Image, after: &Image) -> Vec<bool> {
    let mean = after.pixels.iter().map(luminance).sum::<f64>() / after.pixels.len().max(1) as f64;
    before
        .pixels
        .iter()
        .zip(&after.pixels)
        .map(|(b, a)| {
            let (yb, ya) = (luminance(b), luminance(a));
            let d = (ya - yb).abs();
            d > REGION_CHANGE * yb.max(ya) && d > 0.02 * mean
        })
        .collect()
}

/// What `animate --temporal` measured.
#[derive(Clone, Debug, Serialize)]
pub struct TemporalReport {
    /// The stage's settings.
    pub settings: TemporalSettings,
    /// Whether `jitter=true` was added to the technique's settings.
    pub jitter_added: bool,
    /// "gpu" or "cpu": where the stage ran.
    pub backend: String,
    /// The stage's time per frame, ms (wall clock around its submit and wait on the GPU).
    pub stage_ms: Vec<f64>,
    /// Per frame, with `--flicker`.
    pub frames: Vec<FrameQuality>,
    /// Flicker of the technique without the stage (with `--flicker`).
    pub flicker_without: Option<Flicker>,
    /// The frame the lights jumped at (`--light-jump`).
    pub light_jump: Option<u32>,
    /// The frame the occluder jumped at (`--occluder-jump`), and the occluder.
    pub occluder_jump: Option<(u32, Occluder)>,
    /// Ghosting after the jump (with `--flicker`): frames from the jump until the stage's PSNR
    /// is within 1 dB of its new steady state (the mean of the last 4 frames rendered, which
    /// must be at least 8 frames after the jump); 0 when the jump frame itself is; None when
    /// it is not within the frames rendered or too few follow the jump.
    pub recovery_frames: Option<u32>,
    /// The same over the pixels the jump changed (with `--flicker`).
    pub region: Option<JumpRegion>,
}

/// Frames from `jump` until `psnr` is within 1 dB of its mean over the last 4 frames (at least
/// 8 frames must follow the jump). See [`TemporalReport::recovery_frames`].
pub fn recovery_frames(psnr: &[f64], jump: usize) -> Option<u32> {
    if psnr.len() < jump + 8 {
        return None;
    }
    let steady = psnr[psnr.len() - 4..].iter().sum::<f64>() / 4.0;
    psnr.iter().skip(jump).position(|&p| p >= steady - 1.0).map(|r| r as u32)
}

/// `overrides` with `jitter=true` added where the technique has a `jitter` setting and the
/// overrides do not set it (what the temporal stage is fed); and whether it was added.
pub(crate) fn with_jitter(name: &str, scene: &Scene, overrides: &[String]) -> Result<(Vec<String>, bool)> {
    let first = parse_technique(name, scene, overrides)?;
    let has_jitter = first.ray_march().is_some();
    let set_by_user = overrides.iter().any(|o| o.split_once('=').is_some_and(|(k, _)| k.trim() == "jitter"));
    let add = has_jitter && !set_by_user;
    let mut o = overrides.to_vec();
    if add {
        o.push("jitter=true".into());
    }
    Ok((o, add))
}

/// The temporal stage after one technique along a path (`animate --temporal`, bench's temporal
/// column): the library's [`Temporal`] where the technique runs on the GPU, its CPU mirror
/// elsewhere.
pub(crate) enum Stage {
    Gpu(Box<Temporal>),
    Cpu(CpuTemporal),
}

impl Stage {
    /// The stage for `technique`: on the GPU when there is one and the technique runs there.
    pub(crate) fn new(settings: TemporalSettings, gpu: Option<&GpuContext>, technique: &str) -> Result<Self> {
        let on_gpu = crepuscular::techniques::find(technique).is_some_and(|t| t.gpu);
        Ok(match gpu {
            Some(g) if on_gpu => Stage::Gpu(Box::new(Temporal::new(&g.device, settings)?)),
            _ => Stage::Cpu(CpuTemporal::new(settings)?),
        })
    }

    /// "gpu" or "cpu".
    pub(crate) fn backend(&self) -> &'static str {
        if matches!(self, Stage::Gpu(_)) { "gpu" } else { "cpu" }
    }

    /// Resolves one frame: `img` is the technique's in-scattering on `frame`, which on the GPU
    /// is still in `gpu_output` (read there, with the host's depth, not uploaded again).
    /// Returns the output and the history weight per pixel (row-major; 0 where the history was
    /// rejected).
    pub(crate) fn resolve(
        &mut self,
        gpu: Option<&GpuContext>,
        frame: &HostFrame,
        gpu_output: Option<&wgpu::Texture>,
        img: &Image,
    ) -> Result<(Image, Vec<f32>)> {
        match (self, gpu, gpu_output, &frame.textures) {
            (Stage::Gpu(t), Some(g), Some(current), Some(host)) => {
                let (w, h) = (frame.desc.width, frame.desc.height);
                let out = g.create_output_texture(w, h);
                let view = |t: &wgpu::Texture| t.create_view(&Default::default());
                let mut enc = g.device.create_command_encoder(&Default::default());
                let motion = frame.motion_texture.as_ref().map(view);
                t.encode(&mut enc, &frame.desc, &host.depth_view(), &view(current), &view(&out), motion.as_ref())?;
                g.queue.submit([enc.finish()]);
                let img = g.read_image(&out)?;
                let w = g.read_texture_f32(t.weights().context("temporal weights")?, 0)?;
                Ok((img, w))
            }
            (Stage::Cpu(t), ..) => {
                let img = t.resolve(&frame.desc, &frame.depth, img, frame.motion.as_deref())?;
                Ok((img, t.weights().to_vec()))
            }
            (Stage::Gpu(_), ..) => {
                bail!("the GPU temporal stage needs the frame and the technique on the GPU (internal error)")
            }
        }
    }
}

/// The error, as a fraction of the reference's peak, at the top of the ramp of
/// `--dump-frames`' error maps: 5 % (an image whose every pixel were that far off would read
/// 26 dB), so that the errors of frames between 30 and 50 dB show.
pub const DUMP_ERROR_FULL_SCALE: f64 = 0.05;

/// One frame's images for `--dump-frames DIR` ([`AnimateOptions::dump_frames`]), named
/// `NNNN-WHAT.EXT` with NNNN the frame's index (four digits), each written atomically.
struct FrameDump<'a> {
    dir: &'a Path,
    index: u32,
    tone: ToneMap,
}

impl FrameDump<'_> {
    fn path(&self, what: &str, ext: &str) -> PathBuf {
        self.dir.join(format!("{:04}-{what}.{ext}", self.index))
    }

    /// `NNNN-WHAT.exr`: the linear in-scattering as it is (alpha included: minus the scattering
    /// distance where the technique wrote one); `NNNN-WHAT.png`: the final image (the frame's
    /// surface and this in-scattering), tone-mapped as the GIF's frames.
    fn images(&self, frame: &HostFrame, what: &str, inscatter: &Image) -> Result<()> {
        crate::output::write_exr(&self.path(what, "exr"), inscatter)?;
        let (w, h) = (inscatter.width, inscatter.height);
        let rgb = self.tone.to_rgb8(&frame.final_radiance(inscatter));
        crate::output::write_png_rgb8(&self.path(what, "png"), w, h, &rgb)
    }

    /// `NNNN-weight.png`: the temporal stage's history weight per pixel on the magma ramp
    /// (black: 0, the history rejected or the current frame shown as it is; pale yellow: 1).
    fn weights(&self, frame: &HostFrame, weights: &[f32]) -> Result<()> {
        let rgb: Vec<u8> = weights.iter().flat_map(|&w| crate::metrics::magma_ramp(w.clamp(0.0, 1.0))).collect();
        crate::output::write_png_rgb8(&self.path("weight", "png"), frame.desc.width, frame.desc.height, &rgb)
    }

    /// `NNNN-error-WHAT.png`: the absolute error of the in-scattering against the frame's
    /// reference ([`crate::metrics::abs_error_heatmap`]: luminance of the per-channel error on
    /// the magma ramp, its top at [`DUMP_ERROR_FULL_SCALE`] of the reference's peak).
    fn error(&self, what: &str, reference: &Image, inscatter: &Image) -> Result<()> {
        let rgb = crate::metrics::abs_error_heatmap(reference, inscatter, DUMP_ERROR_FULL_SCALE)?;
        let (w, h) = (inscatter.width, inscatter.height);
        crate::output::write_png_rgb8(&self.path(&format!("error-{what}"), "png"), w, h, &rgb)
    }
}

/// A writer that remembers the first error (the GIF encoder writes its trailer on drop, where
/// errors would otherwise be lost).
struct Tracked<W: Write> {
    inner: W,
    error: Option<String>,
    bytes: u64,
}

impl<W: Write> Write for Tracked<W> {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        match self.inner.write(buf) {
            Ok(n) => {
                self.bytes += n as u64;
                Ok(n)
            }
            Err(e) => {
                self.error.get_or_insert_with(|| e.to_string());
                Err(e)
            }
        }
    }
    fn flush(&mut self) -> std::io::Result<()> {
        self.inner.flush().inspect_err(|e| {
            self.error.get_or_insert_with(|| e.to_string());
        })
    }
}

/// Renders the animation and writes the GIF atomically (nothing is left at `output` on error).
/// `progress(frames_done, frames_total, what)` is called as frames finish; `rows` receives the
/// reference's row progress.
pub fn run(
    opts: &AnimateOptions,
    gpu: Option<&GpuContext>,
    progress: &dyn Fn(u32, u32, &str),
    rows: &(dyn Fn(u64, u64) + Sync),
) -> Result<AnimateReport> {
    opts.validate()?;
    let mut scene = load_scene(&opts.scene)?;
    (scene.render.width, scene.render.height) = opts.size;
    if let Some(s) = opts.shadow_map_size {
        scene.render.shadow.size = s;
    }
    let (overrides, jitter_added) = match opts.temporal {
        Some(_) => with_jitter(&opts.technique, &scene, &opts.overrides)?,
        None => (opts.overrides.clone(), false),
    };
    let mut technique = AnimatedTechnique::new(&opts.technique, &scene, &overrides)?;
    let mut stage = match opts.temporal {
        Some(s) => Some(Stage::new(s, gpu, &opts.technique)?),
        None => None,
    };
    let mut meter_without = FlickerMeter::new();
    let mut stage_ms = Vec::new();
    let mut qualities = Vec::new();
    let mut reference = if opts.flicker {
        let r = format!("steps={}", opts.reference_steps);
        // Seed fixed: the reference's own noise changes only as the rays move.
        Some(AnimatedTechnique::new("reference", &scene, &[r, "seed=1".into()])?)
    } else {
        None
    };
    let mut path = MotionPath::for_scene(&opts.scene, &scene);
    if opts.still_lights {
        path = path.still_lights();
    }
    let tone = ToneMap::new(scene.render.exposure);
    let scene_name = scene.name.clone();
    let mut renderer = PathRenderer::new(scene, path.clone(), gpu)?;
    // The stage reads the frame's motion vectors, as it would an engine's.
    renderer.motion_vectors = stage.is_some();
    let occluder = match opts.occluder_jump {
        Some(_) => Some(Occluder::for_scene(renderer.scene())?),
        None => None,
    };
    if let Some(o) = &occluder {
        renderer.add_occluder(o.clone());
    }
    let jump = opts.light_jump.or(opts.occluder_jump);
    if let Some(d) = &opts.dump_frames {
        std::fs::create_dir_all(d).with_context(|| format!("--dump-frames {}: cannot create it", d.display()))?;
    }
    let mut previous_reference: Option<Image> = None;
    let mut region: Option<Vec<bool>> = None;
    let (w, h) = opts.size;
    let delay = image::Delay::from_numer_denom_ms(1000, opts.fps);
    let mut meter = FlickerMeter::new();
    let mut technique_ms = Vec::new();
    let mut bytes = 0;
    crate::output::write_atomic_with(&opts.output, |file| {
        let mut sink = Tracked { inner: std::io::BufWriter::new(file), error: None, bytes: 0 };
        {
            let mut enc = image::codecs::gif::GifEncoder::new_with_speed(&mut sink, GIF_SPEED);
            enc.set_repeat(image::codecs::gif::Repeat::Infinite).context("GIF")?;
            let rendered = opts.rendered();
            for i in 0..rendered {
                let t = frame_time(i, opts.frames, true);
                progress(i, rendered, &format!("frame {}/{}: {}", i + 1, rendered, technique.name()));
                if opts.light_jump == Some(i) {
                    renderer.light_turn_degrees = LIGHT_JUMP_DEGREES;
                }
                if opts.occluder_jump == Some(i) {
                    renderer.jump_occluder();
                }
                let mut frame = renderer.frame(t)?;
                let (raw, stats) = technique.render(gpu, &mut frame, i, rows)?;
                technique_ms.push(stats.total_ms());
                let (img, weights) = match &mut stage {
                    Some(st) => {
                        let start = std::time::Instant::now();
                        let r = st.resolve(gpu, &frame, technique.gpu_output(), &raw)?;
                        stage_ms.push(start.elapsed().as_secs_f64() * 1e3);
                        r
                    }
                    None => (raw.clone(), Vec::new()),
                };
                let weight = weights.iter().map(|&x| x as f64).sum::<f64>() / weights.len().max(1) as f64;
                let dump = opts.dump_frames.as_deref().map(|dir| FrameDump { dir, index: i, tone });
                if let Some(d) = &dump {
                    d.images(&frame, "technique", &raw)?;
                    if stage.is_some() {
                        d.images(&frame, "temporal", &img)?;
                        d.weights(&frame, &weights)?;
                    }
                }
                if let Some(r) = &mut reference {
                    progress(i, rendered, &format!("frame {}/{}: reference", i + 1, rendered));
                    let (ri, _) = r.render(gpu, &mut frame, 0, rows)?;
                    if let Some(d) = &dump {
                        d.images(&frame, "reference", &ri)?;
                        d.error("technique", &ri, &raw)?;
                        if stage.is_some() {
                            d.error("temporal", &ri, &img)?;
                        }
                    }
                    meter.push(&img, &ri)?;
                    if jump == Some(i)
                        && let Some(before) = &previous_reference
                    {
                        let m = jump_region(before, &ri);
                        region = m.iter().any(|&b| b).then_some(m);
                    }
                    let region_psnr = |img: &Image| -> Result<Option<f64>> {
                        match &region {
                            Some(m) => Ok(Some(crate::metrics::region_psnr(&ri, img, m)?)),
                            None => Ok(None),
                        }
                    };
                    let (region_psnr_db_without, region_psnr_db) = (region_psnr(&raw)?, region_psnr(&img)?);
                    // The frame before the jump's reference, to find the jump's region.
                    if jump == Some(i + 1) {
                        previous_reference = Some(ri.clone());
                    }
                    if stage.is_some() {
                        meter_without.push(&raw, &ri)?;
                        let q = Quality {
                            final_radiance: frame.final_radiance(&ri),
                            inscatter: ri,
                            transmittance: frame.transmittance.clone(),
                            tone,
                        };
                        let (psnr_db_without, flip_without) = q.measure(&raw, &frame.surface)?;
                        let (psnr_db, flip) = q.measure(&img, &frame.surface)?;
                        qualities.push(FrameQuality {
                            psnr_db_without,
                            flip_without,
                            psnr_db,
                            flip,
                            mean_history_weight: weight,
                            region_psnr_db_without,
                            region_psnr_db,
                        });
                    }
                }
                let rgb = tone.to_rgb8(&frame.final_radiance(&img));
                let rgba: Vec<u8> = rgb.chunks_exact(3).flat_map(|p| [p[0], p[1], p[2], 255]).collect();
                let buf = image::RgbaImage::from_raw(w, h, rgba).context("frame buffer size")?;
                enc.encode_frame(image::Frame::from_parts(buf, 0, 0, delay))
                    .with_context(|| format!("cannot encode GIF frame {i}"))?;
            }
            progress(rendered, rendered, "done");
        }
        if let Some(e) = &sink.error {
            bail!("{e}");
        }
        sink.flush()?;
        bytes = sink.bytes;
        Ok(())
    })?;
    let flicker = if opts.flicker { Some(meter.finish()?) } else { None };
    let psnr: Vec<f64> = qualities.iter().map(|q| q.psnr_db).collect();
    let region_report = match (&region, jump) {
        (Some(m), Some(k)) => {
            let after: Vec<f64> = qualities.iter().skip(k as usize).filter_map(|q| q.region_psnr_db).collect();
            let pixels = m.iter().filter(|&&b| b).count() as u32;
            Some(JumpRegion {
                pixels,
                fraction: pixels as f64 / m.len().max(1) as f64,
                recovery_frames: recovery_frames(&after, 0),
            })
        }
        _ => None,
    };
    let temporal = match (opts.temporal, &stage) {
        (Some(settings), Some(st)) => Some(TemporalReport {
            settings,
            jitter_added,
            backend: st.backend().into(),
            stage_ms,
            frames: qualities,
            flicker_without: if opts.flicker { Some(meter_without.finish()?) } else { None },
            light_jump: opts.light_jump,
            occluder_jump: opts.occluder_jump.zip(occluder),
            recovery_frames: jump
                .and_then(|k| if psnr.len() > k as usize { recovery_frames(&psnr, k as usize) } else { None }),
            region: region_report,
        }),
        _ => None,
    };
    Ok(AnimateReport {
        temporal,
        scene: scene_name,
        frame_index_advanced: technique.has_frame_index(),
        settings: technique.first,
        path,
        frames: opts.rendered(),
        technique_ms,
        flicker,
        bytes,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The light's direction (directional, spot) or position (point).
    fn light_vector(l: &Light) -> Vec3 {
        match l {
            Light::Directional { direction, .. } | Light::Spot { direction, .. } => *direction,
            Light::Point { position, .. } => *position,
        }
    }

    #[test]
    fn the_path_starts_and_ends_at_the_scene_and_moves_in_between() {
        for name in ["colonnade", "forest", "stained-glass", "cage", "terrain"] {
            let s = builtin::builtin(name).unwrap();
            let p = MotionPath::for_scene(name, &s);
            assert_ne!(p, MotionPath::generic(&s), "{name} has its own path");
            let (c, l) = p.pose(&s.camera, &s.lights[0].light, 0.0);
            assert_eq!((c, l), (s.camera.clone(), s.lights[0].light.clone()), "{name}: t = 0 is the scene");
            let (c, l) = p.pose(&s.camera, &s.lights[0].light, 0.999999);
            assert!(c.position.distance(s.camera.position) < 1e-3, "{name}: t → 1 loops back");
            assert!(light_vector(&l).distance(light_vector(&s.lights[0].light)) < 1e-3, "{name}");
            let (c, l) = p.pose(&s.camera, &s.lights[0].light, 0.25);
            assert!(c.position.distance(s.camera.position) > 0.1, "{name}: the camera does not move");
            assert_eq!(c.look_at, s.camera.look_at);
            assert!(
                light_vector(&l).distance(light_vector(&s.lights[0].light)) > 0.02,
                "{name}: the light does not move"
            );
        }
        // A scene from a file (any name that is not built in) gets the generic path.
        let s = builtin::builtin("cage").unwrap();
        assert_eq!(MotionPath::for_scene("my-cage.toml", &s), MotionPath::generic(&s));
        // Options after a built-in name keep its path (they once fell back to the generic one,
        // so `animate colonnade:shadow_filter=bilinear` moved unlike `animate colonnade`).
        let s = builtin::builtin("colonnade").unwrap();
        let own = MotionPath::for_scene("colonnade", &s);
        for name in
            ["colonnade:shadow_filter=bilinear", "colonnade:lights=1", "colonnade:lights=1:shadow_filter=nearest"]
        {
            assert_eq!(MotionPath::for_scene(name, &s), own, "{name}");
        }
        assert_eq!(crate::render::scene_base("my:scene.toml"), "my:scene.toml");
    }

    #[test]
    fn frame_times_loop_or_step_by_a_24th() {
        assert_eq!(frame_time(0, 8, true), 0.0);
        assert_eq!(frame_time(4, 8, true), 0.5);
        assert_eq!(frame_time(3, 4, false), 3.0 / 24.0);
    }
}
