//! Technique `epipolar`: epipolar sampling (Engelhardt & Dachsbacher 2010, §4–5). The
//! in-scattering varies smoothly along the epipolar lines through the light's projection (the
//! screen-space crepuscular rays, §4) and abruptly across them and at depth discontinuities, so
//! the technique ray-marches sparse samples on `slices` epipolar lines, adds samples at depth
//! discontinuities, interpolates along each line and then, bilaterally, between the two lines
//! around each pixel. Seven compute entry points in five timed passes (six with the spot
//! texture prefilter), and their CPU mirror in `cpu.rs`, function for function:
//!
//! 0. `prefilter` (prefilter.wgsl, only for a textured spot light when the level is > 0, §6
//!    last paragraph): box-filters the spot texture by 2^L into a technique-owned texture that
//!    the ray-marched samples read instead (the upsample's full-resolution re-marches keep
//!    the original).
//! 1. `lines` (lines.wgsl, §4.1, §5.1): entry `lines`, one thread per line k: the border point
//!    b_k, the segment [e, b_k] ∩ R clipped to the sample rect R (and, for a spot light, to the
//!    rays that meet its cone), its initial-sample count; entry `coordinates`, one thread per
//!    texel: the *coordinate texture* (slices rows × `samples` columns, `Rgba32Float`: the
//!    point p, the view distance s of pixel ⌊p⌋, valid).
//! 2. `refine` (refine.wgsl, §4.2, §5.2): entry `refine`, one thread per initial segment: the
//!    paper's left/right discontinuity search inside each texel's initial segment, found for
//!    all of the segment's texels in one walk over it (the ends of each run of texels with no
//!    break inside; S reads per line instead of the per-texel search's S × S/K), written to the
//!    *interpolation texture* (`R32Uint`, left | right << 16); every ray-march sample (left =
//!    right = itself) claims its pixel ⌊p⌋ with an atomic, and the first claim of a pixel
//!    appends it to a list with an atomic counter — compaction instead of the paper's stencil
//!    mask; entry `args`, one thread: the indirect dispatch arguments.
//! 3. `march` (march.wgsl, §4.3, §5.3): `dispatch_workgroups_indirect` over the compacted list
//!    — this replaces the paper's stencil + early-z trick, which WebGPU compute does not have —
//!    each entry marching its pixel's own ray exactly as `brute-force` does (shared
//!    `march_pixel`), into the *marched* texture, which is indexed by pixel.
//! 4. `interpolate` (interpolate.wgsl, §5.3): every texel linearly between its two ray-march
//!    samples (read at their pixels in the marched texture), into the *radiance texture* (rgb,
//!    view distance in alpha). A second texture rather than the same one read-write: WebGPU
//!    core has no read-write `rgba32float` storage.
//! 5. `upsample` (upsample.wgsl, §4.3, Fig. 5, Fig. 8): each pixel finds its two closest lines
//!    in closed form (the paper's 1D border → line lookup texture is the inverse of an
//!    equidistant placement, so it is computed, not stored), runs a `taps`-tap bilateral filter
//!    along each, blends them by their total weights, moves to outer lines where one has no
//!    depth-compatible tap, and re-marches the pixel at full resolution where none has
//!    (`fallback_remarch`, counted on the GPU).
//!
//! The extras of §6 are settings: initial samples proportional to a line's on-screen length
//! (`length_proportional_initial_samples`) and a depth threshold that grows with distance
//! (`threshold_growth`). Where this implementation departs from or adds to the paper, with the
//! measurements in the settings' documentation:
//! - Marching by pixel rather than by texel: every sample takes the ray of its pixel anyway,
//!   and near the epipole (where all lines meet) and where lines are denser than pixels
//!   several ray-march texels share a pixel; each pixel is marched once. The output is
//!   identical to marching every texel; on the built-in scenes it saves 12–40 % of the marches
//!   (60–88 % of the ray-march texels are distinct pixels, at 160×90 and 320×180).
//! - `slices` and `samples` default to sizes relative to the image (one line per 4 px of the
//!   border, one texel per 1.5 px of the diagonal), so the same defaults suit a 160×90 test and
//!   a 1080p frame; the paper's absolute counts are settings.
//! - Pixels within `epipole_radius` (3 px) of the epipole are re-marched: a point or spot light
//!   seen directly, or a strongly forward phase function, peaks at the light's own pixel, and
//!   every line starts there. The disc's edge also breaks the lines (its texels on either side
//!   are ray-march samples), and the texels inside it (which interpolate from the line's first
//!   texel, on the epipole) are left out of the taps of the pixels outside it: a light a few
//!   metres from the camera puts half the in-scattering within 4 px of its pixel, and those
//!   taps made the long robustness sweep's worst views (docs/ROBUSTNESS.md) 0.60–0.66 off;
//!   under a sun whose epipole sits on an occluder's edge, the first texel's ray reads the
//!   edge's partial light over its whole length, and the lines spread it as a starburst over
//!   the occluder (docs/RESULTS.md, the Bevy comparison). A pixel just outside the disc
//!   whose points on both lines around it lie inside is re-marched too: near the epipole the
//!   lines fan out, and the next lines out offer only taps farther from the light.
//! - A spot light's pixels whose own ray misses the cone get zero without any filtering
//!   (exact: the light is zero outside the cone), and the lines are clipped to the rays that
//!   meet the cone (§4.1's "clip to the light frustum", found by testing the rays of each
//!   line's texels).
//! - The 1D border → line lookup texture (Fig. 8) is computed in closed form, and the
//!   camera-at-the-light case (§4.1: "naïve screen space sub-sampling") uses horizontal lines,
//!   an epipole at infinity to the left.
//!
//! Stats (`TechniqueStats`): one time per pass as above; `raymarched_samples` = (marched pixels
//! + re-marched pixels)·`steps`, counted on the GPU with atomics; `gpu_memory_bytes`: every
//! buffer and texture the technique holds; `extra`: `slices`, `samples` (S, after auto),
//! `valid_lines` (after culling), `marched_samples` (pixels ray-marched for the lines),
//! `sample_texels` (texels classified as ray-march samples, the paper's count),
//! `remarched_pixels` (full-resolution marches of the upsampling), `marched_share`
//! ((marched_samples + remarched_pixels) / pixels; the paper reports 5.8 % at 1920×1080),
//! `degenerate` (1: camera at the light), `spot_prefilter_level`.
//!
//! Geometry conventions (shared by both backends, `geometry.wgsl` / `cpu.rs`): pixel space,
//! x right, y down, pixel (i, j) has centre (i + ½, j + ½); the *sample rect* R = [½, W − ½] ×
//! [½, H − ½] holds every pixel centre, and a sample at p takes pixel ⌊p⌋ (its depth and ray,
//! as `brute-force`). The epipole is kept homogeneous, (x, y, w) in pixels, so that a light
//! direction parallel to the image plane (w = 0, parallel lines) needs no special case; it is a
//! per-frame constant computed once on the host ([`cpu::epipole`]) and handed to every pass in
//! the uniform block, so both backends use bit-identical epipoles.

pub mod cpu;
pub mod debug;
mod gpu;
mod settings;

pub use gpu::Epipolar;
pub use settings::{EpipolarMarch, EpipolarSettings, SpotPrefilter, Weighting};

use crate::error::Error;
use crate::frame::{FrameDesc, GpuFrame};
use crate::gpu::{GpuContext, Recorder};
use crate::march::{MarchSettings, StepPolicy};
use crate::model::Light;
use crate::stats::TechniqueStats;
use crate::techniques::pass::{self, Bound, Pass};
use serde::{Deserialize, Deserializer, Serialize, Serializer};

pub use debug::{EpipolarDebug, classification_view, radiance_view};

/// What every epipolar pass shares: `struct Params`, `struct Line`, the line geometry.
pub const GEOMETRY_WGSL: &str = include_str!("geometry.wgsl");
/// Pass `prefilter` (entry `prefilter`).
pub const PREFILTER_WGSL: &str = include_str!("prefilter.wgsl");
/// Pass `lines` (entries `lines` and `coordinates`).
pub const LINES_WGSL: &str = include_str!("lines.wgsl");
/// Pass `refine` (entries `refine` and `args`).
pub const REFINE_WGSL: &str = include_str!("refine.wgsl");
/// Pass `march` (entry `march`).
pub const MARCH_WGSL: &str = include_str!("march.wgsl");
/// Pass `march` with `march = "minmax"` (entry `march`): composed with the rectification's
/// geometry and minmax's walk instead of the epipolar geometry ([`march_minmax_source`]).
pub const MARCH_MINMAX_WGSL: &str = include_str!("march_minmax.wgsl");

/// The min-max march's source: prefiltered/geometry.wgsl + minmax/walk.wgsl + the pass
/// (common.wgsl is added by [`crate::shaders::compose`]).
pub fn march_minmax_source() -> String {
    use crate::techniques::{minmax, prefiltered};
    prefiltered::pass_source(
        &format!("{}\n{MARCH_MINMAX_WGSL}", minmax::WALK_WGSL),
        prefiltered::BasisPrecision::Unorm8,
    )
}

/// Pass `interpolate` (entry `interpolate`).
pub const INTERPOLATE_WGSL: &str = include_str!("interpolate.wgsl");
/// Pass `upsample` (entry `upsample`).
pub const UPSAMPLE_WGSL: &str = include_str!("upsample.wgsl");

/// Every pass shader with its name and entry points; each is composed as common.wgsl +
/// geometry.wgsl + the pass ([`pass_source`]).
pub const SHADERS: [(&str, &str, &[&str]); 6] = [
    ("epipolar/prefilter", PREFILTER_WGSL, &["prefilter"]),
    ("epipolar/lines", LINES_WGSL, &["lines", "coordinates"]),
    ("epipolar/refine", REFINE_WGSL, &["refine", "args"]),
    ("epipolar/march", MARCH_WGSL, &["march"]),
    ("epipolar/interpolate", INTERPOLATE_WGSL, &["interpolate"]),
    ("epipolar/upsample", UPSAMPLE_WGSL, &["upsample"]),
];

/// A pass shader with the epipolar geometry prepended (common.wgsl is added by
/// [`crate::shaders::compose`]).
pub fn pass_source(pass: &str) -> String {
    format!("{GEOMETRY_WGSL}\n// ---- epipolar pass ----\n{pass}")
}

/// Lines whose visible segment is shorter than this (pixels) are culled (§4.1).
/// `MIN_LINE_LENGTH` in geometry.wgsl.
pub const MIN_LINE_LENGTH: f32 = 0.5;

/// Below this total bilateral weight a line has no usable tap for a pixel (§4.3, "all taps
/// have weights close to 0"): the upsampling moves to the next outer line. A centre tap on the
/// pixel's own surface weighs 1. `MIN_WEIGHT` in geometry.wgsl.
pub const MIN_WEIGHT: f32 = 1e-3;

/// The camera "coincides" with a point or spot light (§4.1) when they are closer than this
/// fraction of the scene's coordinate magnitude, max(1, |camera|, |light|) (about a hundred
/// f32 ulps of those coordinates: below it the direction from the camera to the light is mostly
/// rounding). The lines then degenerate and the technique falls back to naïve screen-space
/// subsampling: horizontal lines, each row of slices evenly spaced from top to bottom.
pub const DEGENERATE_DISTANCE: f32 = 1e-5;

/// Largest `slices` and `samples` (texel indices are packed in 16 bits; the device limit on
/// texture sizes is checked at render time).
pub const MAX_TEXELS_PER_SIDE: u32 = 8192;

/// Largest `spot_prefilter` level.
pub const MAX_PREFILTER_LEVEL: u32 = 12;

/// The uniform block of every pass (`struct Params` in geometry.wgsl).
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct EpipolarParams {
    /// Steps per ray.
    pub steps: u32,
    /// 1 to jitter.
    pub jitter: u32,
    /// Jitter seed.
    pub frame_index: u32,
    /// [`crate::march::StepPolicy::code`]: the spot policy and the equiangular bit.
    pub spot_steps: u32,
    /// App. B denominator.
    pub spot_denominator: f32,
    /// Lines.
    pub slices: u32,
    /// Texels per line, S.
    pub samples: u32,
    /// Initial samples per line, K.
    pub initial_samples: u32,
    /// 1: K proportional to the line's length.
    pub length_proportional: u32,
    /// Absolute threshold, metres.
    pub depth_threshold: f32,
    /// Relative threshold.
    pub threshold_growth: f32,
    /// Filter taps per line.
    pub taps: u32,
    /// [`Weighting::code`].
    pub weighting: u32,
    /// σ of the spatial kernel, tap spacings.
    pub spatial_scale: f32,
    /// σ of the depth kernel, relative.
    pub depth_scale: f32,
    /// Outer lines searched per side.
    pub outer_lines: u32,
    /// 1 to re-march pixels without a usable tap.
    pub fallback_remarch: u32,
    /// 1 when the camera coincides with the light (naïve subsampling lines).
    pub degenerate: u32,
    /// The device's maximum workgroups per dispatch dimension (for the indirect arguments).
    pub max_workgroups: u32,
    /// Spot texture prefilter level (0: none).
    pub prefilter_level: u32,
    /// Re-march radius around the epipole, pixels; the refinement breaks the lines at the
    /// disc's edge, the upsampling's taps skip the texels inside it and the lines on which
    /// the pixel's own point lies inside it (cpu.rs `refine_line`, `line_taps`,
    /// `upsample_pixel`).
    pub epipole_radius: f32,
    /// Padding.
    pub _pad: [u32; 3],
    /// The epipole, homogeneous pixel coordinates (x, y, w) scaled to max-abs 1; w = 0 is a
    /// point at infinity (parallel lines). The fourth component is 0.
    pub epipole: [f32; 4],
}

const _: () = assert!(std::mem::size_of::<EpipolarParams>() == 112);

impl EpipolarParams {
    /// The block for `settings` on the frame `desc`; `max_workgroups` is the device's
    /// `max_compute_workgroups_per_dimension` (any value on the CPU).
    pub fn new(s: &EpipolarSettings, desc: &FrameDesc, max_workgroups: u32) -> Self {
        let (epipole, degenerate) = cpu::epipole(desc);
        let (slices, samples) = s.sizes(desc.width, desc.height);
        Self {
            steps: s.ray_march.steps,
            jitter: s.ray_march.jitter as u32,
            frame_index: s.ray_march.frame_index,
            spot_steps: s.policy.code(),
            spot_denominator: s.policy.denominator,
            slices,
            samples,
            initial_samples: s.initial_samples.min(samples),
            length_proportional: s.length_proportional_initial_samples as u32,
            depth_threshold: s.depth_threshold,
            threshold_growth: s.threshold_growth,
            taps: s.taps,
            weighting: s.weighting.code(),
            spatial_scale: s.spatial_scale,
            depth_scale: s.depth_scale,
            outer_lines: s.outer_lines,
            fallback_remarch: s.fallback_remarch as u32,
            degenerate: degenerate as u32,
            max_workgroups,
            prefilter_level: s.prefilter_level(desc),
            epipole_radius: s.epipole_radius,
            _pad: [0; 3],
            epipole,
        }
    }
}

/// One epipolar line as the passes store it (`struct Line` in geometry.wgsl, a storage
/// buffer): texel t of a valid line lies at `end + dir·length·(S − 1 − t)/(S − 1)`, so texel
/// S − 1 is `end` (on the border of the sample rect, or where a spot light's cone ends) and
/// texel 0 the epipole-side end (the epipole itself when it is inside the rect).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct EpipolarLine {
    /// Texel S − 1, pixels. For a culled line: its border point b_k.
    pub end: [f32; 2],
    /// Unit direction from `end` towards the epipole (set for culled lines too).
    pub dir: [f32; 2],
    /// Length of the visible segment, pixels (0 when culled).
    pub length: f32,
    /// 1 valid, 0 culled.
    pub valid: u32,
    /// Initial ray-march samples K of this line (0 when culled).
    pub initial: u32,
    /// Padding.
    pub _pad: u32,
}

const _: () = assert!(std::mem::size_of::<EpipolarLine>() == 32);

impl EpipolarLine {
    /// Texel S − 1 (the border end).
    pub fn end(&self) -> glam::Vec2 {
        glam::Vec2::from(self.end)
    }
    /// Texel 0 (the epipole-side end).
    pub fn start(&self) -> glam::Vec2 {
        self.end() + glam::Vec2::from(self.dir) * self.length
    }
    /// Whether the line survived culling.
    pub fn is_valid(&self) -> bool {
        self.valid == 1
    }
}

/// `TechniqueStats::extra` of a frame: `slices`, `samples` (S), `valid_lines` (after culling),
/// `marched_samples` (pixels ray-marched for the lines, each once), `sample_texels` (texels
/// classified as ray-march samples, the paper's count, ≥ `marched_samples`),
/// `remarched_pixels` (full-resolution marches of the upsampling), `marched_share`
/// ((marched_samples + remarched_pixels) / pixels; the paper reports 5.8 % at 1920×1080),
/// `degenerate` (1 when the camera is at the light), `spot_prefilter_level`.
pub(crate) fn stats_extra(
    params: &EpipolarParams,
    (width, height): (u32, u32),
    valid_lines: u64,
    marched: u64,
    remarched: u64,
    sample_texels: u64,
) -> std::collections::BTreeMap<String, f64> {
    let pixels = (width as f64 * height as f64).max(1.0);
    [
        ("slices", params.slices as f64),
        ("samples", params.samples as f64),
        ("valid_lines", valid_lines as f64),
        ("marched_samples", marched as f64),
        ("sample_texels", sample_texels as f64),
        ("remarched_pixels", remarched as f64),
        ("marched_share", (marched + remarched) as f64 / pixels),
        ("degenerate", params.degenerate as f64),
        ("spot_prefilter_level", params.prefilter_level as f64),
    ]
    .into_iter()
    .map(|(k, v)| (k.to_string(), v))
    .collect()
}

impl crate::techniques::Technique for EpipolarSettings {
    const INFO: crate::techniques::TechniqueInfo = crate::techniques::TechniqueInfo {
        name: "epipolar",
        summary: "epipolar sampling: ray-march samples on epipolar lines refined at depth discontinuities, interpolated along and bilaterally between the lines (GPU: lines, refine, indirect march over a compacted list, interpolate, upsample; CPU mirror)",
        paper: "Engelhardt & Dachsbacher 2010, §4–5",
        gpu: true,
        cpu: true,
        per_light: true,
    };
    fn validate(&self) -> Result<(), Error> {
        EpipolarSettings::validate(self)
    }
    fn render_cpu(
        &self,
        frame: &crate::CpuFrame,
        _rectified: Option<&[f32]>,
        _progress: &(dyn Fn(u64, u64) + Sync),
    ) -> Result<(crate::Image, TechniqueStats), Error> {
        cpu::render(frame, self)
    }
}
