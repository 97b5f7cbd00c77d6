//! Temporal accumulation after any technique (docs/MODEL.md §7): each frame's in-scattering is
//! blended with the previous frames' reprojected through the camera's motion, so a technique
//! whose sample positions change from frame to frame (its `jitter` and `frame_index` settings)
//! converges towards the mean of those positions instead of showing one of them.
//!
//! [`Temporal`] is the GPU stage: it records one compute pass into the caller's encoder after
//! the technique's, reading the technique's output, the frame's depth and its own history, and
//! writing the resolved in-scattering to the caller's texture. [`CpuTemporal`] is its CPU
//! mirror ([`resolve_pixel`] is the shader, line for line), tested against it pixel by pixel.
//!
//! What the history is, is the caller's choice: each stage remembers the camera of the frame it
//! resolved last and reprojects through it; [`Temporal::reset`] forgets it (a camera cut, a
//! teleport). An engine that renders motion vectors passes them too ([`Temporal::encode`]'s
//! `motion`, [`CpuTemporal::resolve`]'s): the drawn pixels are then reprojected by them, so
//! the history follows moving objects as well as the camera (except the pixels reprojected by
//! their scattering distance, [`TemporalSettings::scattering_distance`], whose light belongs to
//! the medium, not to the objects). A new size, another set of lights (count, kinds, scattering scales), another
//! medium, or a light that jumps ([`TemporalSettings::light_jump_degrees`]) resets it by itself.

use crate::error::Error;
use crate::frame::{FrameDesc, MAX_LIGHTS};
use crate::image::Image;
use crate::techniques::pass::{self, BindCache, Bound, Pass};
use glam::{Mat4, Vec3, Vec4};
use serde::{Deserialize, Serialize};
use std::hash::{Hash, Hasher};

/// The pass shader (composed with common.wgsl).
pub const TEMPORAL_WGSL: &str = include_str!("temporal.wgsl");

/// The frame count a pixel's history saturates at (`MAX_FRAMES` in temporal.wgsl).
pub const MAX_FRAMES: f32 = 1024.0;

/// The weight of the past in the running moments of a pixel's frame-to-frame change that
/// [`TemporalSettings::adaptive_weight`] reads (`MOMENT_WEIGHT` in temporal.wgsl): about the
/// last 1/(1 − 0.8) = 5 frames. Shorter than the history's memory, so that the drift it
/// measures is the current one.
pub const MOMENT_WEIGHT: f32 = 0.8;

/// The frames a pixel's history must hold before its moments steer the weight
/// ([`TemporalSettings::adaptive_weight`]; `ADAPT_AFTER` in temporal.wgsl): more than 4.5, so
/// at least five frame-to-frame changes, this frame's included (a count is a bilinear mean of
/// counts: the half keeps rounding from deciding). Measured (docs/RESULTS.md): steering from
/// 2.5 frames (three changes), the moments lowered the weight of jittered inputs on many
/// pixels (colonnade, frame 3 of a slow move: 44.75 dB against 45.55).
pub const ADAPT_AFTER: f32 = 4.5;

/// The least noise [`adapted_weight`] assumes, as a fraction of the pixel's value (its
/// standard deviation; `NOISE_FLOOR` in temporal.wgsl): 1/256, a step of an 8-bit display. A
/// noise-free input whose value drifts by far less than that per frame (reprojection's own
/// rounding, a slow change of light) keeps its history; without the floor any drift at all,
/// however small, would set the weight to 0. Measured (docs/RESULTS.md): on a slow camera
/// move, minmax on terrain 57.75 dB without the floor, 57.62 with it; the mean weight of a
/// frame 0.20 → 0.45.
pub const NOISE_FLOOR: f32 = 1.0 / 256.0;

/// How the reprojected history is read between texels ([`TemporalSettings::history_filter`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum HistoryFilter {
    /// The 2×2 texels around the reprojected point, bilinear weights (each texel kept only
    /// where the previous frame saw the same surface). Soft: a sub-pixel motion blurs the
    /// history a little every frame.
    #[default]
    Bilinear,
    /// The 4×4 texels around it with Catmull-Rom weights (a cubic that interpolates the
    /// texels and keeps their slopes), where all 16 show the same surface; elsewhere bilinear.
    /// Keeps sharp patterns (a gobo's, a thin shaft's) sharp under motion; its overshoot is
    /// clamped at 0 and then by the neighbourhood clip. Cost: 16 history and distance reads
    /// per pixel instead of 4.
    CatmullRom,
}

/// The temporal stage's settings. Cost of the stage: one full-screen compute pass reading, per
/// pixel, 4 history texels and their 4 stored statistics (16 with the Catmull-Rom read), and
/// (where the history is clipped or young) 9 current texels and their depths; 68 bytes of
/// history per pixel (two RGBA32F images, two RGBA32F statistics — the distance the pixel was
/// reprojected from (its surface's, or its scattering distance) and the
/// moments [`TemporalSettings::adaptive_weight`] reads —, one R32F weight).
///
/// Feed it a jittered march whose lights read their shadow maps with
/// [`crate::ShadowFilter::Bilinear`] (the default): at the march's cost, brute-force with the stage then
/// reaches 40 dB after 8 frames of a slow move on every built-in scene (forest 41.1 dB against
/// 38.7 with nearest lookups; docs/RESULTS.md "The stage with the bilinear shadow filter").
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct TemporalSettings {
    /// The largest weight w of the history in out = c + w·(h − c), in [0, 1): the exponential
    /// average's factor once 1/(1 − w) frames are held (before that, w = n/(n + 1) with n the
    /// frames the pixel's history holds: the plain mean). Higher: less noise and banding, a
    /// slower answer to change (about 1/(1 − w) frames). Default 0.9 (Unreal's volumetric
    /// fog). No cost.
    pub history_weight: f32,
    /// Clip the reprojected history to the current frame's 3×3 neighbourhood (its mean ±
    /// `clip_sigma` standard deviations, inside its min and max; Salvi's variance clipping),
    /// so a history that no longer fits — a light moved, an occluder crossed a shaft — is
    /// pulled to what the frame shows instead of ghosting. Default true. Cost: 9 texture reads
    /// per pixel.
    pub clip: bool,
    /// Half-width of the clip box in standard deviations of the neighbourhood (≥ 0): smaller
    /// rejects more (less ghosting and lag, more of the current frame's noise kept). Default
    /// 0.5, measured (docs/RESULTS.md, "Temporal accumulation"): on a slow camera move over
    /// colonnade 0.35–0.5 gave the lowest FLIP and flicker at the same PSNR; 1.25 and 2 let
    /// the history lag (FLIP 0.029–0.031 instead of 0.020 after 8 frames).
    pub clip_sigma: f32,
    /// Disocclusion test: the history is rejected where the previous frame's view distance at
    /// the reprojected pixel differs from the point's distance to the previous eye by more than
    /// this fraction of it (the previous frame saw another surface there). Default 0.05.
    pub depth_tolerance: f32,
    /// A light jump, degrees: the whole history is dropped when a light's direction (a sun's
    /// travel, a spot's aim) or its position as seen from the eye turns by more than this
    /// between two frames. Slower motion of the lights (and any change of their colour or
    /// intensity) is left to the neighbourhood clip. Default 5°.
    pub light_jump_degrees: f32,
    /// How the history is read at the reprojected point, between texels: `"bilinear"` or
    /// `"catmull-rom"` ([`HistoryFilter`]). Default `"bilinear"`, measured (docs/RESULTS.md,
    /// "Temporal accumulation"): with the clip on, Catmull-Rom changed no scene's PSNR by more
    /// than 0.1 dB nor its FLIP by more than 0.0002 after 8 frames (the clip, not the read,
    /// bounds the history); without the clip it halves the reprojection error of fine surface
    /// detail. Cost: 16 reads of history and distance instead of 4.
    pub history_filter: HistoryFilter,
    /// Adapt each pixel's history weight to what its input does from frame to frame
    /// (docs/MODEL.md §7, step 5): the stage keeps, per pixel, running moments of the change
    /// d of the input's largest channel between consecutive frames (reprojected). Their
    /// variance is the input's noise (twice its variance), their mean its drift (the signal
    /// moving under the camera or lights). An exponential average of weight w leaves
    /// σ²·(1 − w)/(1 + w) of the noise's variance σ² and lags a drift δ per frame by
    /// δ·w/(1 − w); w is lowered to where the sum of the two squared errors is least
    /// ([`adapted_weight`]; never raised above `history_weight`). A technique without jitter
    /// (no noise) then follows the camera with little lag instead of trailing it by
    /// w/(1 − w) ≈ 9 frames of its drift; a jittered one keeps most of its averaging. Default
    /// true, measured (docs/RESULTS.md, "Temporal accumulation"). Cost: a few ALU operations
    /// per pixel (the moments are read with the history).
    pub adaptive_weight: bool,
    /// While a pixel's history holds fewer than this many frames (k, counting this one: 1 on
    /// the first frame, after a reset or a light jump, and where the history was rejected),
    /// its output leans on the current frame's 3×3 same-surface mean M: the first frame shows
    /// M, and frame k ≥ 2 shows T + m·(M − T), T the running mean (which is what the history
    /// keeps) and m the weight [`young_mean_weight`] gives M: large where the pixel's own
    /// frame-to-frame changes say T is still noisy, small where M differs from T by more than
    /// that noise (M blurs an edge of a clean input), and never above (N − k)/(N − 1). A
    /// jittered input's first frames are then a spatial average instead of one noisy sample
    /// (colonnade, brute-force: the frame of a light jump 35.3 → 43.9 dB), and a clean one's
    /// second frame is its own again (stained-glass and terrain recover from a light jump in 1
    /// frame, not 6). The first frame is a 3×3 blur whatever the input (an exact technique's:
    /// minmax on terrain 64.9 → 57.1 dB). 0 or 1: off (a new or rejected history shows the
    /// current frame). Default 8, measured (docs/RESULTS.md, "Temporal accumulation" and "A
    /// young history that weighs its own noise"). Cost: the neighbourhood's 9 reads on those
    /// frames (the clip reads them anyway) and a few ALU operations.
    pub young_frames: u32,
    /// Radius of the disc around each point or spot light seen in the frame (its position
    /// projected, nearer than the surface behind it) whose pixels show the current frame as it
    /// is: no history, no clip, no young mean (docs/MODEL.md §7, step 0). As a fraction of the
    /// image height, so that it covers the same part of the view at every resolution. A light
    /// seen directly puts a near-singular peak of in-scattering (like 1/h, h the distance by
    /// which the pixel's ray misses the light) around its own pixel; the peak moves with the
    /// light's projection, not with the surface behind it that the reprojection follows, so the
    /// history misplaces it by the parallax between the two, a relative error of about that
    /// parallax over the pixel's distance from the light — the same part of the view at every
    /// resolution — and the 3×3 neighbourhood there is too wide to clip it. In [0, 1]; 0
    /// disables. Default 0.09 (8 px at 90 rows, 16 at 180, 97 at 1080), measured
    /// (docs/RESULTS.md, "The lamp disc"): on a slow camera move, frame 8, at 320×180
    /// night-street 55.0 → 73.0 dB and its flicker 4.35 → 1.65 %, cage 58.6 → 69.8 dB; at
    /// 160×90 night-street 47.1 → 64.6 dB, cage 55.2 → 67.0 dB; the sun scenes have no such
    /// light. Cost: per pixel a loop over the frame's point and spot lights (at most 16
    /// distance tests); the discs' pixels lose the stage's averaging.
    pub light_disc_radius: f32,
    /// Reproject a pixel's history from where its in-scattering came from instead of from the
    /// surface it shows, where the input says so: where the input's alpha is negative it is
    /// minus the pixel's *scattering distance* (m); an alpha ≥ 0 (an opaque 1, as engines and
    /// the other techniques write) gives none. `brute-force` writes it where the point and spot
    /// lights that march their own interval (every one under the default `local_steps =
    /// "equiangular"`; under `"uniform"`, spots under a cone `spot_steps` policy) give at least
    /// half of a pixel's in-scattering (the luminance-weighted mean
    /// distance from the eye of their light along the ray, from its march's own samples:
    /// [`crate::march::scattering_distance`], 0 elsewhere); every other technique of the
    /// library writes 1 ([`crate::TechniqueSettings::writes_scattering_distance`]). The point at that distance on
    /// the pixel's ray is reprojected through the previous camera (not by motion vectors: the
    /// medium does not move with the objects), and a history texel is kept where its own stored
    /// distance matches that point's distance from the previous eye within `depth_tolerance`;
    /// the other pixels use their surface, as with this off (docs/MODEL.md §7, step 1). A
    /// spot's cone or a lamp's glow in front of a distant wall or the sky then moves with the
    /// medium it lies in, not with the wall. Turn it off when feeding the stage an
    /// in-scattering whose alpha may be negative for another reason. Default true, measured (docs/RESULTS.md,
    /// "Reprojection by the scattering distance": stained-glass +2.7 dB, cage's FLIP 0.0141 →
    /// 0.0103; atrium −0.36 dB; the sun scenes unchanged). No cost in the stage (the alpha is
    /// read with the colour); `brute-force` pays a luminance and a multiply-add per march step
    /// for it. A pixel that crosses the half-share threshold between frames changes anchor, and
    /// its history restarts there (its stored distance is of the other kind).
    pub scattering_distance: bool,
}

impl Default for TemporalSettings {
    fn default() -> Self {
        Self {
            history_weight: 0.9,
            clip: true,
            clip_sigma: 0.5,
            depth_tolerance: 0.05,
            light_jump_degrees: 5.0,
            history_filter: HistoryFilter::Bilinear,
            adaptive_weight: true,
            young_frames: 8,
            light_disc_radius: 0.09,
            scattering_distance: true,
        }
    }
}

impl TemporalSettings {
    /// An error naming the first setting outside its range.
    pub fn validate(&self) -> Result<(), Error> {
        let w = self.history_weight;
        if !(0.0..1.0).contains(&w) {
            return Err(Error::invalid("temporal.history_weight", w, "must be in [0, 1)"));
        }
        if !(self.clip_sigma >= 0.0 && self.clip_sigma.is_finite()) {
            return Err(Error::invalid("temporal.clip_sigma", self.clip_sigma, "must be finite and ≥ 0"));
        }
        if !(self.depth_tolerance >= 0.0 && self.depth_tolerance.is_finite()) {
            return Err(Error::invalid("temporal.depth_tolerance", self.depth_tolerance, "must be finite and ≥ 0"));
        }
        if self.young_frames > MAX_FRAMES as u32 {
            return Err(Error::invalid("temporal.young_frames", self.young_frames, "must be at most 1024"));
        }
        let r = self.light_disc_radius;
        if !(r.is_finite() && (0.0..=1.0).contains(&r)) {
            return Err(Error::invalid("temporal.light_disc_radius", r, "must be in [0, 1] (of the image height)"));
        }
        if !(self.light_jump_degrees >= 0.0 && self.light_jump_degrees <= 180.0) {
            return Err(Error::invalid("temporal.light_jump_degrees", self.light_jump_degrees, "must be in [0, 180]"));
        }
        Ok(())
    }
}

/// What the history needs of the previous frame.
#[derive(Clone, Debug, PartialEq)]
struct Previous {
    view_proj: Mat4,
    camera_pos: Vec3,
    key: u64,
    /// Each light's unit directions that a jump is measured on (its direction of travel or
    /// aim, and its position as seen from the eye).
    poses: Vec<[Vec3; 2]>,
    size: (u32, u32),
}

/// A light's direction (travel or aim; zero for a point light) and the unit vector from the
/// eye to it (zero for a directional light).
fn pose(l: &crate::Light, eye: Vec3) -> [Vec3; 2] {
    match l {
        crate::Light::Directional { direction, .. } => [direction.normalize_or_zero(), Vec3::ZERO],
        crate::Light::Spot { position, direction, .. } => {
            [direction.normalize_or_zero(), (*position - eye).normalize_or_zero()]
        }
        crate::Light::Point { position, .. } => [Vec3::ZERO, (*position - eye).normalize_or_zero()],
    }
}

impl Previous {
    fn of(desc: &FrameDesc) -> Self {
        let eye = desc.camera.position;
        Self {
            view_proj: desc.camera.view_proj(),
            camera_pos: eye,
            key: light_key(desc),
            poses: desc.lights.iter().map(|l| pose(&l.light, eye)).collect(),
            size: (desc.width, desc.height),
        }
    }

    /// Whether a history of this previous frame may serve `desc`: the same size, the same
    /// lights (count, kinds, scattering scales) and medium, and no light turned by more than
    /// `jump_degrees`.
    fn serves(&self, desc: &FrameDesc, jump_degrees: f32) -> bool {
        if self.size != (desc.width, desc.height) || self.key != light_key(desc) {
            return false;
        }
        let cos_jump = jump_degrees.to_radians().cos();
        let eye = desc.camera.position;
        desc.lights.iter().zip(&self.poses).all(|(l, before)| {
            let now = pose(&l.light, eye);
            (0..2).all(|i| before[i] == Vec3::ZERO || now[i] == Vec3::ZERO || before[i].dot(now[i]) >= cos_jump)
        })
    }
}

/// A hash of what may not change at all under a history: the number of lights, their kinds
/// and scattering scales, and the medium. (A light's pose is compared by angle,
/// [`TemporalSettings::light_jump_degrees`]; its colour and intensity are left to the clip.)
fn light_key(desc: &FrameDesc) -> u64 {
    let mut h = std::collections::hash_map::DefaultHasher::new();
    for l in &desc.lights {
        l.light.kind_code().hash(&mut h);
        l.scattering.to_bits().hash(&mut h);
    }
    format!("{:?}", desc.medium).hash(&mut h);
    h.finish()
}

/// The pass uniforms (`struct Temporal` in temporal.wgsl).
#[repr(C)]
#[derive(Clone, Copy, Debug, bytemuck::Pod, bytemuck::Zeroable)]
pub struct TemporalUniforms {
    /// The previous frame's view-projection.
    pub prev_view_proj: [[f32; 4]; 4],
    /// The previous frame's eye (xyz).
    pub prev_camera_pos: [f32; 4],
    /// [`TemporalSettings::history_weight`].
    pub history_weight: f32,
    /// [`TemporalSettings::clip_sigma`].
    pub clip_sigma: f32,
    /// [`TemporalSettings::depth_tolerance`].
    pub depth_tolerance: f32,
    /// 1 when the history serves this frame.
    pub valid: u32,
    /// 1 to clip ([`TemporalSettings::clip`]).
    pub clip: u32,
    /// 1 for the Catmull-Rom history read ([`TemporalSettings::history_filter`]).
    pub catmull_rom: u32,
    /// 1 when the frame's motion vectors are bound (drawn pixels reprojected by them).
    pub motion: u32,
    /// 1 to adapt the weight to the pixel's noise and drift
    /// ([`TemporalSettings::adaptive_weight`]).
    pub adaptive: u32,
    /// [`TemporalSettings::young_frames`], as a float.
    pub young_frames: f32,
    /// How many of `lamps` are set.
    pub lamp_count: u32,
    /// [`TemporalSettings::light_disc_radius`] in pixels (times the image height; 0: no discs).
    pub lamp_radius: f32,
    /// 1 to reproject by the input's scattering distance where its alpha is negative (minus
    /// that distance; [`TemporalSettings::scattering_distance`]).
    pub scattering: u32,
    /// The point and spot lights in front of the eye ([`lamp_discs`]): (x, y) their projection
    /// in pixels (the image's top-left corner at 0, pixel centres at +0.5), z their distance from
    /// the eye, w unused.
    pub lamps: [[f32; 4]; MAX_LIGHTS],
}

/// The point and spot lights of `desc` in front of the eye, for
/// [`TemporalSettings::light_disc_radius`]: each light's position projected into the image,
/// in pixels (pixel centres at +0.5), and its distance from the eye; (the array, how many are
/// set). A light whose projection lies off the image is kept (its disc may reach in).
pub fn lamp_discs(desc: &FrameDesc) -> ([[f32; 4]; MAX_LIGHTS], u32) {
    let mut lamps = [[0.0f32; 4]; MAX_LIGHTS];
    let mut n = 0usize;
    let view_proj = desc.camera.view_proj();
    let eye = desc.camera.position;
    for l in &desc.lights {
        let (crate::Light::Point { position, .. } | crate::Light::Spot { position, .. }) = &l.light else { continue };
        let clip = view_proj * position.extend(1.0);
        if clip.w <= 0.0 || n == MAX_LIGHTS {
            continue;
        }
        let ndc = clip.truncate().truncate() / clip.w;
        let (x, y) = ((ndc.x * 0.5 + 0.5) * desc.width as f32, (0.5 - ndc.y * 0.5) * desc.height as f32);
        if x.is_finite() && y.is_finite() {
            lamps[n] = [x, y, (*position - eye).length(), 0.0];
            n += 1;
        }
    }
    (lamps, n as u32)
}

/// Whether pixel (x, y), whose view distance is `dist` (negative: nothing drawn), lies within
/// `lamp_radius` of a light in `lamps` that is nearer than its surface
/// ([`TemporalSettings::light_disc_radius`]). Mirrors `in_lamp_disc` in temporal.wgsl.
pub fn in_lamp_disc(u: &TemporalUniforms, x: u32, y: u32, dist: f32) -> bool {
    let q = glam::Vec2::new(x as f32 + 0.5, y as f32 + 0.5);
    u.lamps[..u.lamp_count as usize]
        .iter()
        .any(|l| (q - glam::Vec2::new(l[0], l[1])).length() < u.lamp_radius && (dist < 0.0 || l[2] < dist))
}

fn uniforms(s: &TemporalSettings, prev: Option<&Previous>, motion: bool, desc: &FrameDesc) -> TemporalUniforms {
    let (lamps, lamp_count) = if s.light_disc_radius > 0.0 { lamp_discs(desc) } else { ([[0.0; 4]; MAX_LIGHTS], 0) };
    TemporalUniforms {
        prev_view_proj: prev.map_or(Mat4::IDENTITY, |p| p.view_proj).to_cols_array_2d(),
        prev_camera_pos: prev.map_or(Vec4::ZERO, |p| p.camera_pos.extend(1.0)).to_array(),
        history_weight: s.history_weight,
        clip_sigma: s.clip_sigma,
        depth_tolerance: s.depth_tolerance,
        valid: prev.is_some() as u32,
        clip: s.clip as u32,
        catmull_rom: (s.history_filter == HistoryFilter::CatmullRom) as u32,
        motion: motion as u32,
        adaptive: s.adaptive_weight as u32,
        young_frames: s.young_frames as f32,
        lamp_count,
        lamp_radius: s.light_disc_radius * desc.height as f32,
        scattering: s.scattering_distance as u32,
        lamps,
    }
}

/// Where the previous frame saw what pixel (x, y) of a `w`×`h` frame shows, by its motion vector
/// `mv`, in texel coordinates of the previous image (texel centres at integers).
///
/// Motion vectors as the stage reads them, per pixel: the pixel's screen position now minus
/// where the surface it shows was in the previous frame, in UV units of the image (x right,
/// y down, 1 = the image's width or height; Bevy's and most engines' convention), so the pixel
/// at p was at p − mv·(W, H). Only drawn pixels use them: sky pixels (nothing drawn, which
/// engines often leave at zero motion) are reprojected through the camera. Mirrors the motion
/// branch of `resolve` in temporal.wgsl.
pub fn motion_source(x: u32, y: u32, w: u32, h: u32, mv: [f32; 2]) -> glam::Vec2 {
    glam::Vec2::new(x as f32 - mv[0] * w as f32, y as f32 - mv[1] * h as f32)
}

/// This frame's view distance per pixel, row-major; -1 where nothing was drawn. Mirrors
/// `current_distance` in temporal.wgsl (which computes it per read; the CPU once per frame).
pub fn view_distances(desc: &FrameDesc, depth: &[f32]) -> Vec<f32> {
    let far = desc.camera.depth.far_value();
    (0..desc.height)
        .flat_map(|y| (0..desc.width).map(move |x| (x, y)))
        .map(|(x, y)| {
            let d = depth[(y * desc.width + x) as usize];
            if d == far { -1.0 } else { desc.view_distance(d, desc.pixel_ray(x, y)) }
        })
        .collect()
}

/// Whether a pixel whose view distance is `stored` shows the surface at `reference` (both -1
/// where nothing was drawn): sky with sky, else within `tolerance` of `reference`. Mirrors
/// `same_surface` in temporal.wgsl.
pub fn same_surface(stored: f32, reference: f32, tolerance: f32) -> bool {
    if reference < 0.0 { stored < 0.0 } else { stored >= 0.0 && (stored - reference).abs() <= tolerance * reference }
}

/// Catmull-Rom weights of the texels at −1, 0, 1, 2 for a point at fraction `f` ∈ [0, 1) past
/// texel 0 (they sum to 1). Mirrors `catmull_rom_weights` in temporal.wgsl.
pub fn catmull_rom_weights(f: f32) -> [f32; 4] {
    [
        f * (-0.5 + f * (1.0 - 0.5 * f)),
        1.0 + f * f * (-2.5 + 1.5 * f),
        f * (0.5 + f * (2.0 - 1.5 * f)),
        f * f * (-0.5 + 0.5 * f),
    ]
}

/// The history weight w after [`TemporalSettings::adaptive_weight`], from the running moments
/// (m1, m2) of a pixel's frame-to-frame change held with weight `a` and its input's largest
/// channel `x`: noise σ² = var/2 + ([`NOISE_FLOOR`]·x)², drift δ²
/// = m1² less the part of it the noise explains (var·(1 − a)/(1 + a), the variance of a
/// running mean of weight a). An exponential average of weight w leaves σ²·(1 − w)/(1 + w) of
/// the noise and trails the drift by δ·w/(1 − w); the sum of the two squared errors is least
/// where δ²·w·(1 + w)² = σ²·(1 − w)³, found by bisection (16 halvings) below `w`, and `w`
/// itself where that root lies above it. Mirrors `adapted_weight` in temporal.wgsl.
pub fn adapted_weight(w: f32, m1: f32, m2: f32, a: f32, x: f32) -> f32 {
    let var = (m2 - m1 * m1).max(0.0);
    let noise = 0.5 * var + (NOISE_FLOOR * x) * (NOISE_FLOOR * x);
    let drift2 = (m1 * m1 - var * (1.0 - a) / (1.0 + a)).max(0.0);
    let g = |v: f32| drift2 * v * (1.0 + v) * (1.0 + v) - noise * (1.0 - v) * (1.0 - v) * (1.0 - v);
    if g(w) <= 0.0 {
        return w;
    }
    let (mut lo, mut hi) = (0.0f32, w);
    for _ in 0..16 {
        let mid = 0.5 * (lo + hi);
        if g(mid) <= 0.0 {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    lo
}

/// The margin by which a young history's noise estimate is widened
/// ([`young_mean_weight`]; `YOUNG_NOISE_MARGIN` in temporal.wgsl): with k frames held, the
/// mean square of the k − 1 changes is taken as (1 + 2/(k − 1)) times itself, 3× on the
/// second frame, where it rests on one change. A single change is often small by chance, and
/// then the young mean would be dropped on a noisy pixel. Measured (docs/RESULTS.md, "A young
/// history that weighs its own noise"), colonnade's second frame: 46.3 dB with no margin,
/// 47.1 with 2, 47.4 with 6; with 6, stained-glass's light jump took 5 frames to recover, not 1.
pub const YOUNG_NOISE_MARGIN: f32 = 2.0;

/// The weight of the frame's 3×3 same-surface mean M in a young history's output
/// ([`TemporalSettings::young_frames`], docs/MODEL.md §7 step 4): out = T + m·(M − T), T the
/// running mean of the k frames the history holds (k ≥ 2; the first frame shows M). The
/// noise left in T is about σ²/k, σ² = m2/2 from the mean square `m2` of the pixel's
/// frame-to-frame changes (widened by [`YOUNG_NOISE_MARGIN`]), and `bias` = max(M) − max(T)
/// (largest channels, as the moments are) measures what the 3×3 mean blurs (an edge) as
/// well as T's noise. The weight σ²/k / (σ²/k + bias²) leans on M where T is noisy and on T
/// where M blurs a sharp input, capped by the ramp (N − k)/(N − 1) of N = `young_frames`, so
/// that M's share still falls to 0 at k = N. Mirrors `young_mean_weight` in temporal.wgsl.
pub fn young_mean_weight(m2: f32, youth: f32, bias: f32, young_frames: f32) -> f32 {
    let noise = 0.5 * m2 / youth * (1.0 + YOUNG_NOISE_MARGIN / (youth - 1.0));
    let total = noise + bias * bias;
    let m = if total > 0.0 { noise / total } else { 0.0 };
    m.min((young_frames - youth) / (young_frames - 1.0))
}

/// One pixel's resolve: (output rgb, history rgba, weight, statistics). `distances`: this
/// frame's ([`view_distances`]); `history` and `history_stats`: the previous frame's (read only
/// when `u.valid`; statistics: the distance the pixel was reprojected from (its view distance,
/// or its scattering distance), the input's largest channel, and the running
/// moments of its change, [`TemporalSettings::adaptive_weight`]); `motion`: the frame's motion
/// vectors (read only when `u.motion`). Mirrors `resolve` in temporal.wgsl.
#[allow(clippy::too_many_arguments)]
pub fn resolve_pixel(
    desc: &FrameDesc,
    u: &TemporalUniforms,
    distances: &[f32],
    current: &Image,
    history: &Image,
    history_stats: &[[f32; 4]],
    motion: &[[f32; 2]],
    x: u32,
    y: u32,
) -> ([f32; 3], [f32; 4], f32, [f32; 4]) {
    let (w_px, h_px) = (desc.width as i32, desc.height as i32);
    let rgb = |p: [f32; 4]| Vec3::new(p[0], p[1], p[2]);
    let at = |x: i32, y: i32| (y.clamp(0, h_px - 1) * w_px + x.clamp(0, w_px - 1)) as usize;
    let c = rgb(current.pixels[at(x as i32, y as i32)]);

    let dir = desc.pixel_ray(x, y);
    let dist = distances[at(x as i32, y as i32)];
    // The distance the history is reprojected from (and stored for the next frame): the
    // input's scattering distance where it gives one, else the surface's (-1: sky, a
    // direction).
    let alpha = current.pixels[at(x as i32, y as i32)][3];
    let scattered = u.scattering == 1 && alpha < 0.0;
    let rdist = if scattered { -alpha } else { dist };
    let sky = rdist < 0.0;
    // Within the disc of a light seen directly: the current frame as it is, and a history that
    // starts again from it.
    if in_lamp_disc(u, x, y, dist) {
        let xs = c.max_element();
        return (c.to_array(), [c.x, c.y, c.z, 1.0], 0.0, [rdist, xs, 0.0, 0.0]);
    }

    let mut w = 0.0f32;
    let mut n = 0.0f32;
    let mut h = c;
    // The reprojected statistics: the input's largest channel and the moments of its change.
    let mut hs = Vec3::ZERO;
    if u.valid == 1 {
        let x4 = if sky { dir.extend(0.0) } else { (desc.camera.position + dir * rdist).extend(1.0) };
        // Where the previous frame saw it: by the motion vector where one is given for a drawn
        // pixel reprojected by its surface, else through the previous camera; outside the
        // previous image, nowhere.
        let mut q = glam::Vec2::ZERO;
        let mut seen = false;
        if u.motion == 1 && !sky && !scattered {
            q = motion_source(x, y, desc.width, desc.height, motion[at(x as i32, y as i32)]);
            let hi = glam::Vec2::new(w_px as f32 - 0.5, h_px as f32 - 0.5);
            seen = q.cmpge(glam::Vec2::splat(-0.5)).all() && q.cmple(hi).all();
        } else {
            let clip = Mat4::from_cols_array_2d(&u.prev_view_proj) * x4;
            if clip.w > 0.0 {
                let ndc = clip.truncate().truncate() / clip.w;
                if ndc.x.abs() <= 1.0 && ndc.y.abs() <= 1.0 {
                    q = glam::Vec2::new(
                        (ndc.x * 0.5 + 0.5) * w_px as f32 - 0.5,
                        (0.5 - ndc.y * 0.5) * h_px as f32 - 0.5,
                    );
                    seen = true;
                }
            }
        }
        if seen {
            // The distance the previous frame must have stored where it saw this point: the
            // point's distance to the previous eye, -1 for sky.
            let expected =
                if sky { -1.0 } else { (x4.truncate() - Vec3::from_slice(&u.prev_camera_pos[..3])).length() };
            let b = q.floor();
            let f = q - b;
            let (ix, iy) = (b.x as i32, b.y as i32);
            let mut acc = Vec4::ZERO;
            let mut acc_s = Vec3::ZERO;
            let mut total = 0.0f32;
            for k in 0..4 {
                let (ox, oy) = (k & 1, k >> 1);
                let t = at(ix + ox, iy + oy);
                let same = same_surface(history_stats[t][0], expected, u.depth_tolerance);
                let fw = (if ox == 1 { f.x } else { 1.0 - f.x }) * (if oy == 1 { f.y } else { 1.0 - f.y });
                if same && fw > 0.0 {
                    acc += fw * Vec4::from_array(history.pixels[t]);
                    let st = history_stats[t];
                    acc_s += fw * Vec3::new(st[1], st[2], st[3]);
                    total += fw;
                }
            }
            if total > 1e-3 {
                h = acc.truncate() / total;
                n = acc.w / total;
                hs = acc_s / total;
                w = u.history_weight.min(n / (n + 1.0));
                if u.catmull_rom == 1 {
                    // Catmull-Rom over the 4×4 texels around q, where all show the same
                    // surface (a cubic's negative lobes cannot be renormalised over a
                    // partial set); its overshoot clamped at 0.
                    let (wx, wy) = (catmull_rom_weights(f.x), catmull_rom_weights(f.y));
                    let mut cr = Vec3::ZERO;
                    let mut all = true;
                    for k in 0..16 {
                        let (ox, oy) = (k & 3, k >> 2);
                        let t = at(ix + ox - 1, iy + oy - 1);
                        all &= same_surface(history_stats[t][0], expected, u.depth_tolerance);
                        cr += wx[ox as usize] * wy[oy as usize] * rgb(history.pixels[t]);
                    }
                    if all {
                        h = cr.max(Vec3::ZERO);
                    }
                }
            }
        }
    }
    // The frames this pixel's history holds with this one: 1 where it starts (the first frame,
    // a reset, a rejection).
    let youth = if w > 0.0 { n + 1.0 } else { 1.0 };
    // The running moments of the input's frame-to-frame change (its largest channel),
    // restarted with the history; they steer the weight once ADAPT_AFTER frames are held.
    let xs = c.max_element();
    let (mut m1, mut m2) = (0.0f32, 0.0f32);
    if w > 0.0 {
        let d = xs - hs.x;
        let a = MOMENT_WEIGHT.min((n - 1.0).max(0.0) / n);
        m1 = d + a * (hs.y - d);
        m2 = d * d + a * (hs.z - d * d);
        if u.adaptive == 1 && n > ADAPT_AFTER {
            w = adapted_weight(w, m1, m2, a, xs);
        }
    }
    // The current frame's 3×3 neighbourhood on the same surface: its spread clips the history,
    // its mean stands in for a young history.
    let young = youth < u.young_frames;
    let mut mean = c;
    if (w > 0.0 && u.clip == 1) || young {
        let (mut lo, mut hi) = (c, c);
        let (mut s1, mut s2) = (Vec3::ZERO, Vec3::ZERO);
        let mut count = 0.0f32;
        for dy in -1..=1 {
            for dx in -1..=1 {
                let p = at(x as i32 + dx, y as i32 + dy);
                if same_surface(distances[p], dist, u.depth_tolerance) {
                    let s = rgb(current.pixels[p]);
                    lo = lo.min(s);
                    hi = hi.max(s);
                    s1 += s;
                    s2 += s * s;
                    count += 1.0;
                }
            }
        }
        mean = s1 / count;
        if w > 0.0 && u.clip == 1 {
            let var = (s2 / count - mean * mean).max(Vec3::ZERO);
            let sigma = Vec3::new(var.x.sqrt(), var.y.sqrt(), var.z.sqrt());
            let box_lo = lo.max(mean - u.clip_sigma * sigma);
            let box_hi = hi.min(mean + u.clip_sigma * sigma);
            h = h.clamp(box_lo, box_hi);
        }
    }
    let res = c + w * (h - c);
    // The running mean, kept as the history; shown through the neighbourhood's mean while young.
    let out = if young {
        let m = if w > 0.0 {
            young_mean_weight(m2, youth, mean.max_element() - res.max_element(), u.young_frames)
        } else {
            1.0
        };
        res + m * (mean - res)
    } else {
        res
    };
    (out.to_array(), [res.x, res.y, res.z, (n + 1.0).min(MAX_FRAMES)], w, [rdist, xs, m1, m2])
}

/// The temporal stage on the CPU: the mirror of [`Temporal`].
#[derive(Clone, Debug, Default)]
pub struct CpuTemporal {
    /// The settings.
    pub settings: TemporalSettings,
    /// The last frame's resolve, its statistics per pixel (the distance it was reprojected from, the input's largest
    /// channel, the moments of its change) and its camera.
    history: Option<(Image, Vec<[f32; 4]>, Previous)>,
    weights: Vec<f32>,
}

impl CpuTemporal {
    /// A stage with no history.
    pub fn new(settings: TemporalSettings) -> Result<Self, Error> {
        settings.validate()?;
        Ok(Self { settings, history: None, weights: Vec::new() })
    }

    /// Forgets the history: the next frame is taken as it is (a camera cut, a teleport).
    pub fn reset(&mut self) {
        self.history = None;
    }

    /// Resolves `current` (the technique's in-scattering of `desc`, a negative alpha minus the
    /// pixel's scattering distance, [`TemporalSettings::scattering_distance`]; its depth
    /// `depth`) against
    /// the history and keeps the result as the next frame's history. `motion`: the frame's
    /// motion vectors, row-major, one per pixel (the convention of [`motion_source`]), or `None` to reproject
    /// every pixel through the camera (right for a static scene). The output's alpha is
    /// `current`'s, passed through.
    pub fn resolve(
        &mut self,
        desc: &FrameDesc,
        depth: &[f32],
        current: &Image,
        motion: Option<&[[f32; 2]]>,
    ) -> Result<Image, Error> {
        let (w, h) = (desc.width, desc.height);
        let n = (w * h) as usize;
        if current.width != w || current.height != h || current.pixels.len() != n {
            let size = format!("{}×{}", current.width, current.height);
            return Err(Error::invalid("temporal current", size, format!("must be the frame's {w}×{h}")));
        }
        if depth.len() != n {
            return Err(Error::invalid("temporal depth", depth.len(), format!("must hold {w}×{h} values")));
        }
        if let Some(m) = motion {
            if m.len() != n {
                return Err(Error::invalid("temporal motion", m.len(), format!("must hold {w}×{h} vectors")));
            }
            if let Some(v) = m.iter().find(|v| !(v[0].is_finite() && v[1].is_finite())) {
                return Err(Error::invalid("temporal motion", format!("{v:?}"), "must be finite"));
            }
        }
        let jump = self.settings.light_jump_degrees;
        let prev = self.history.as_ref().filter(|(_, _, p)| p.serves(desc, jump));
        let u = uniforms(&self.settings, prev.map(|(_, _, p)| p), motion.is_some(), desc);
        // Without a history (u.valid = 0) resolve_pixel reads none: empty stand-ins.
        let (hist, hist_stats): (&Image, &[[f32; 4]]) = match prev {
            Some((i, d, _)) => (i, d),
            None => (current, &[]),
        };
        let distances = view_distances(desc, depth);
        let mut out = Image::new(w, h);
        let mut next = Image::new(w, h);
        let mut stats = vec![[0.0f32; 4]; n];
        self.weights = vec![0.0; n];
        let mv = motion.unwrap_or(&[]);
        for y in 0..h {
            for x in 0..w {
                let i = (y * w + x) as usize;
                let (rgb, hp, wt, st) = resolve_pixel(desc, &u, &distances, current, hist, hist_stats, mv, x, y);
                out.pixels[i] = [rgb[0], rgb[1], rgb[2], current.pixels[i][3]];
                next.pixels[i] = hp;
                self.weights[i] = wt;
                stats[i] = st;
            }
        }
        self.history = Some((next, stats, Previous::of(desc)));
        Ok(out)
    }

    /// The history weight w of each pixel in the last resolve (0 where the history was
    /// rejected), row-major.
    pub fn weights(&self) -> &[f32] {
        &self.weights
    }
}

/// The textures of the history, per size: two of each (read one, write the other).
struct Sized {
    size: (u32, u32),
    history: [wgpu::Texture; 2],
    /// View distance, the input's largest channel, the moments of its change.
    stats: [wgpu::Texture; 2],
    weights: wgpu::Texture,
}

/// The temporal stage on the GPU: one compute pass recorded into the caller's encoder.
pub struct Temporal {
    device: wgpu::Device,
    settings: TemporalSettings,
    /// The resolve pass per output format (built on the first frame in that format).
    passes: std::collections::HashMap<wgpu::TextureFormat, Pass>,
    frame_buffer: wgpu::Buffer,
    params_buffer: wgpu::Buffer,
    sized: Option<Sized>,
    /// Which of the two histories holds the last frame.
    latest: usize,
    prev: Option<Previous>,
    /// The bind groups reading history 0 and history 1.
    binds: BindCache<[wgpu::BindGroup; 2]>,
}

impl Temporal {
    /// Builds the stage on the caller's device. Needs nothing beyond wgpu's default limits
    /// (four storage textures in one compute stage, one of them `R32Float`).
    pub fn new(device: &wgpu::Device, settings: TemporalSettings) -> Result<Self, Error> {
        settings.validate()?;
        let frame_buffer =
            pass::uniform_buffer(device, "temporal frame uniforms", size_of::<crate::FrameUniforms>() as u64);
        let params_buffer = pass::uniform_buffer(device, "temporal uniforms", size_of::<TemporalUniforms>() as u64);
        Ok(Self {
            device: device.clone(),
            settings,
            passes: Default::default(),
            frame_buffer,
            params_buffer,
            sized: None,
            latest: 0,
            prev: None,
            binds: BindCache::default(),
        })
    }

    /// The settings.
    pub fn settings(&self) -> TemporalSettings {
        self.settings
    }

    /// Changes the settings (the history is kept).
    pub fn set_settings(&mut self, settings: TemporalSettings) -> Result<(), Error> {
        settings.validate()?;
        self.settings = settings;
        Ok(())
    }

    /// Forgets the history: the next frame is taken as it is (a camera cut, a teleport).
    pub fn reset(&mut self) {
        self.prev = None;
    }

    /// Whether the next frame will be blended with a history: false before the first frame
    /// and after [`Self::reset`] (the stage may still drop it on that frame, for a new size,
    /// other lights or medium, or a light jump).
    pub fn has_history(&self) -> bool {
        self.prev.is_some()
    }

    /// The history weight w per pixel of the last frame recorded (an `R32Float` texture of the
    /// frame's size; 0 where the history was rejected): the viewer's debug view.
    pub fn weights(&self) -> Option<&wgpu::Texture> {
        self.sized.as_ref().map(|s| &s.weights)
    }

    /// How many times the stage built its bind groups (on new views from the caller or a new
    /// size, not per frame).
    pub fn bind_group_builds(&self) -> u64 {
        self.binds.builds()
    }

    /// Bytes of GPU memory the stage holds.
    pub fn gpu_memory_bytes(&self) -> u64 {
        self.sized.as_ref().map_or(0, |s| s.size.0 as u64 * s.size.1 as u64 * (2 * 16 + 2 * 16 + 4))
    }

    /// Records the resolve of `current` (the technique's output for `desc`, a `D2` view of an
    /// `Rgba32Float` or `Rgba16Float` texture of the frame's size; a negative alpha is minus
    /// the pixel's scattering distance, [`TemporalSettings::scattering_distance`]) with the frame's `depth` into
    /// `output` (a `STORAGE_BINDING` view of the frame's size, `Rgba32Float` or `Rgba16Float`)
    /// in the caller's `encoder`. No submit, no wait. `current` and `output` must be different
    /// textures. `motion`: the engine's motion vectors ([`motion_source`] says what they hold; a view of the
    /// frame's size, `Rg16Float`, `Rg32Float`, `Rgba16Float` or `Rgba32Float`, x and y in the
    /// first two channels), or `None` to reproject every pixel through the camera (right for a
    /// static scene). Errors name an input whose size or format does not fit. The output's
    /// alpha is `current`'s, passed through.
    pub fn encode(
        &mut self,
        encoder: &mut wgpu::CommandEncoder,
        desc: &FrameDesc,
        depth: &wgpu::TextureView,
        current: &wgpu::TextureView,
        output: &wgpu::TextureView,
        motion: Option<&wgpu::TextureView>,
    ) -> Result<(), Error> {
        let (w, h) = (desc.width, desc.height);
        let mut inputs = vec![("depth", depth.texture()), ("current", current.texture()), ("output", output.texture())];
        if let Some(m) = motion {
            use wgpu::TextureFormat::{Rg16Float, Rg32Float, Rgba16Float, Rgba32Float};
            let f = m.texture().format();
            if ![Rg16Float, Rg32Float, Rgba16Float, Rgba32Float].contains(&f) {
                return Err(Error::invalid(
                    "temporal motion",
                    format!("{f:?}"),
                    "must be Rg16Float, Rg32Float, Rgba16Float or Rgba32Float",
                ));
            }
            inputs.push(("motion", m.texture()));
        }
        for (key, t) in inputs {
            if (t.width(), t.height()) != (w, h) {
                return Err(Error::invalid(
                    format!("temporal {key}"),
                    format!("{}×{}", t.width(), t.height()),
                    format!("must be the frame's {w}×{h}"),
                ));
            }
        }
        let format = output.texture().format();
        if !pass::OUTPUT_FORMATS.contains(&format) {
            return Err(Error::invalid("temporal output", format!("{format:?}"), "must be Rgba32Float or Rgba16Float"));
        }
        if !output.texture().usage().contains(wgpu::TextureUsages::STORAGE_BINDING) {
            return Err(Error::invalid("temporal output", format!("{format:?}"), "needs STORAGE_BINDING usage"));
        }
        if current.texture() == output.texture() {
            return Err(Error::invalid("temporal output", "the current texture", "must differ from `current`"));
        }
        if self.sized.as_ref().is_none_or(|s| s.size != (w, h)) {
            self.sized = Some(self.allocate(w, h));
            self.prev = None;
            self.binds = BindCache::default();
        }
        let prev = self.prev.take().filter(|p| p.serves(desc, self.settings.light_jump_degrees));
        // Uniforms through the encoder (copied from this frame's own staging buffers), so
        // several frames recorded into one encoder each read their own.
        for (dst, bytes) in [
            (&self.frame_buffer, bytemuck::bytes_of(&desc.uniforms()).to_vec()),
            (
                &self.params_buffer,
                bytemuck::bytes_of(&uniforms(&self.settings, prev.as_ref(), motion.is_some(), desc)).to_vec(),
            ),
        ] {
            pass::write_in_encoder(&self.device, encoder, dst, &bytes);
        }
        let read = self.latest;
        let write = 1 - read;
        // One bind group per direction of the ping-pong (read history a, write b; and back),
        // both built when the caller's views or the size change, not every frame.
        // Without motion vectors the depth view stands in at their binding (never read).
        let motion = motion.unwrap_or(depth);
        if !self.passes.contains_key(&format) {
            let src = pass::with_output(TEMPORAL_WGSL, format);
            let built = Pass::new(&self.device, "temporal/resolve", &src, "resolve")?;
            self.passes.insert(format, built);
        }
        let resolve = &self.passes[&format];
        let key = vec![
            Bound::View(depth.clone()),
            Bound::View(current.clone()),
            Bound::View(output.clone()),
            Bound::View(motion.clone()),
        ];
        if !self.binds.is_current(&key) {
            let sized = self.sized.as_ref().expect("allocated above");
            let view = |t: &wgpu::Texture| t.create_view(&Default::default());
            let bind = |read: usize| {
                let tv = wgpu::BindingResource::TextureView;
                let (hr, sr, hw, sw, wt) = (
                    view(&sized.history[read]),
                    view(&sized.stats[read]),
                    view(&sized.history[1 - read]),
                    view(&sized.stats[1 - read]),
                    view(&sized.weights),
                );
                resolve.bind(
                    &self.device,
                    &[
                        ("frame", self.frame_buffer.as_entire_binding()),
                        ("params", self.params_buffer.as_entire_binding()),
                        ("depth_tex", tv(depth)),
                        ("current_tex", tv(current)),
                        ("motion_tex", tv(motion)),
                        ("history_tex", tv(&hr)),
                        ("stats_tex", tv(&sr)),
                        ("out_tex", tv(output)),
                        ("history_out", tv(&hw)),
                        ("stats_out", tv(&sw)),
                        ("weight_out", tv(&wt)),
                    ],
                )
            };
            let binds = [bind(0)?, bind(1)?];
            self.binds.store(key, binds);
        }
        let mut cpass = encoder
            .begin_compute_pass(&wgpu::ComputePassDescriptor { label: Some("temporal"), timestamp_writes: None });
        cpass.set_pipeline(resolve.pipeline(crate::techniques::pass::ShaderVariant::ALL));
        cpass.set_bind_group(0, &self.binds.value()[read], &[]);
        let [x, y, z] = resolve.groups_2d(w, h);
        cpass.dispatch_workgroups(x, y, z);
        drop(cpass);
        self.latest = write;
        self.prev = Some(Previous::of(desc));
        Ok(())
    }

    fn allocate(&self, w: u32, h: u32) -> Sized {
        use wgpu::TextureFormat::{R32Float, Rgba32Float};
        let texture = |label, format| crate::gpu::storage_texture(&self.device, label, format, w, h);
        Sized {
            size: (w, h),
            history: [texture("temporal history a", Rgba32Float), texture("temporal history b", Rgba32Float)],
            stats: [texture("temporal stats a", Rgba32Float), texture("temporal stats b", Rgba32Float)],
            weights: texture("temporal weights", R32Float),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::{adapted_weight, catmull_rom_weights};

    /// The adapted weight is the minimum of the squared error it balances,
    /// σ²·(1 − w)/(1 + w) + (δ·w/(1 − w))², over [0, w_max] (checked on a grid of 10⁴ weights,
    /// to the bisection's 0.9/2¹⁶), with σ² and δ² read off the moments as documented; no drift
    /// keeps w_max, no noise (and x = 0: no floor) gives 0.
    #[test]
    fn the_adapted_weight_minimises_noise_plus_lag() {
        let cost =
            |w: f32, noise: f32, drift2: f32| noise * (1.0 - w) / (1.0 + w) + drift2 * w * w / ((1.0 - w) * (1.0 - w));
        for (m1, m2, a, x) in
            [(0.05f32, 0.01f32, 0.8f32, 1.0f32), (0.02, 0.02, 0.8, 1.0), (-0.1, 0.05, 0.5, 2.0), (0.3, 0.1, 0.8, 0.5)]
        {
            let var = (m2 - m1 * m1).max(0.0);
            let noise = 0.5 * var + (x / 256.0) * (x / 256.0);
            let drift2 = (m1 * m1 - var * (1.0 - a) / (1.0 + a)).max(0.0);
            let w = adapted_weight(0.9, m1, m2, a, x);
            let best = (0..=10_000)
                .map(|k| 0.9 * k as f32 / 10_000.0)
                .map(|v| cost(v, noise, drift2))
                .fold(f32::MAX, f32::min);
            assert!(cost(w, noise, drift2) <= best * (1.0 + 1e-4) + 1e-12, "m1 {m1} m2 {m2}: w {w} is not the minimum");
            assert!((0.0..=0.9).contains(&w));
        }
        // Pure noise whose mean change is what the noise explains: no drift, w kept.
        assert_eq!(adapted_weight(0.9, 0.0, 0.04, 0.8, 1.0), 0.9);
        // A drift with no noise at all (and no floor): the history is not used.
        assert_eq!(adapted_weight(0.9, 0.1, 0.01, 0.8, 0.0), 0.0);
    }

    /// Catmull-Rom weights interpolate (f = 0 is texel 0 alone), sum to 1 and reproduce a
    /// linear and a quadratic function exactly: Σ wᵢ·xᵢ = f, Σ wᵢ·xᵢ² = f² at x = −1, 0, 1, 2
    /// (the cubic is exact on polynomials of degree ≤ 2).
    #[test]
    fn catmull_rom_weights_reproduce_polynomials_up_to_degree_two() {
        assert_eq!(catmull_rom_weights(0.0), [0.0, 1.0, 0.0, 0.0]);
        for k in 0..=16 {
            let f = k as f32 / 16.0;
            let w = catmull_rom_weights(f);
            let xs = [-1.0f32, 0.0, 1.0, 2.0];
            let sum: f32 = w.iter().sum();
            let lin: f32 = w.iter().zip(xs).map(|(w, x)| w * x).sum();
            let quad: f32 = w.iter().zip(xs).map(|(w, x)| w * x * x).sum();
            assert!((sum - 1.0).abs() < 1e-6, "f {f}: weights sum to {sum}");
            assert!((lin - f).abs() < 1e-6, "f {f}: linear {lin}");
            assert!((quad - f * f).abs() < 1e-6, "f {f}: quadratic {quad}");
        }
    }
}
