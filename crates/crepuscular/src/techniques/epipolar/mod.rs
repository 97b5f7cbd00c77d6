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
//! 2. `refine` (refine.wgsl, §4.2, §5.2): entry `refine`, one thread per texel: the paper's
//!    left/right discontinuity search inside the texel's initial segment, written to the
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
//!   every line starts there.
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

use crate::error::Error;
use crate::frame::{FrameDesc, GpuFrame};
use crate::gpu::{GpuContext, Recorder, compute_pass};
use crate::march::{DEFAULT_SPOT_DENOMINATOR, SpotSteps, validate_spot_denominator};
use crate::model::Light;
use crate::stats::TechniqueStats;
use crate::techniques::pass::{self, Bound};
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

/// The bilateral weights of the upsampling (§4.3: "Shepard's scattered data interpolation
/// a·x⁻², a Gaussian e^(−a·x²), and simple thresholding (for dᵢ only)"), written with a width σ
/// instead of a: Gaussian e^(−(x/σ)²) (a = 1/σ²), Shepard 1/(1 + (x/σ)²) (a·x⁻² regularised at
/// x = 0: a/(x² + a) with a = σ²), threshold 1 for x ≤ σ else 0 (depth only; the spatial
/// weight is then Gaussian).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Weighting {
    /// e^(−(x/σ)²) for both kernels.
    #[default]
    Gaussian,
    /// 1/(1 + (x/σ)²) for both kernels: never quite rejects a tap.
    Shepard,
    /// Depth: 1 within σ, 0 beyond; spatial: Gaussian.
    Threshold,
}

impl Weighting {
    /// Code shared with WGSL (`Params.weighting`).
    pub fn code(self) -> u32 {
        match self {
            Weighting::Gaussian => 0,
            Weighting::Shepard => 1,
            Weighting::Threshold => 2,
        }
    }
    /// Every weighting, for sweeps.
    pub const ALL: [Weighting; 3] = [Weighting::Gaussian, Weighting::Shepard, Weighting::Threshold];
}

/// How the spot light's projected texture is prefiltered for the ray-marched samples (§6: "when
/// using a lower number of epipolar lines, we have to prefilter the light texture
/// accordingly"). In a scene file: `"auto"`, `"off"` or a level, e.g. `2`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum SpotPrefilter {
    /// The level from the number of lines: L = max(1, ⌈log₂(2·texture side / slices)⌉)
    /// ([`SpotPrefilter::level`]).
    #[default]
    Auto,
    /// Never prefilter.
    Off,
    /// Box-filter by 2^L (0 = off), L in 0..=12.
    Level(u32),
}

impl SpotPrefilter {
    /// The level for a spot texture whose larger side is `texture_side` texels, on `slices`
    /// lines.
    ///
    /// Auto: L = max(1, ⌈log₂(2·n/slices)⌉) for a texture of side n > 1 (0 for a 1×1
    /// texture): about two lines per remaining texel side (the lines resolve about `slices`
    /// directions around the epipole), and at least one level. Measured on `stained-glass`
    /// (256² texture) at 320×180, in-scattering PSNR against the reference for levels 0 / 1 /
    /// 2 / 3 (the rule's choice starred): 64 lines 42.01 / 42.26 / 42.47 / 42.67* dB (level 4:
    /// 42.02), 128 lines 47.17 / 47.51 / 47.51* / 47.15, 256 lines 49.55 / 50.58* / 50.55 /
    /// 49.44, 512 lines 50.74 / 52.12* / 52.05 / 50.16, 1024 lines 50.33 / 51.71* / 51.79 /
    /// 50.11: the choice is within 0.1 dB of the best everywhere. That level 1 helps even at
    /// 1024 lines is the texture's minification on screen at these sizes (the window shows it
    /// some 60 pixels wide), which the N steps of a sample's ray alias; at 1080p set
    /// `spot_prefilter` explicitly if the texture is seen large. Cost: one box filter of the
    /// texture per frame (a 2^L × 2^L block per output texel).
    pub fn level(self, texture_side: u32, slices: u32) -> u32 {
        match self {
            SpotPrefilter::Off => 0,
            SpotPrefilter::Level(l) => l,
            SpotPrefilter::Auto if texture_side <= 1 => 0,
            SpotPrefilter::Auto => {
                let ratio = 2.0 * texture_side as f64 / slices.max(1) as f64;
                let lines = if ratio <= 1.0 { 0 } else { ratio.log2().ceil() as u32 };
                lines.clamp(1, MAX_PREFILTER_LEVEL)
            }
        }
    }
}

impl Serialize for SpotPrefilter {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        match self {
            SpotPrefilter::Auto => s.serialize_str("auto"),
            SpotPrefilter::Off => s.serialize_str("off"),
            SpotPrefilter::Level(l) => s.serialize_u32(*l),
        }
    }
}

impl<'de> Deserialize<'de> for SpotPrefilter {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        #[derive(Deserialize)]
        #[serde(untagged)]
        enum Raw {
            Level(u32),
            Name(String),
        }
        match Raw::deserialize(d)? {
            Raw::Level(l) => Ok(SpotPrefilter::Level(l)),
            Raw::Name(n) if n == "auto" => Ok(SpotPrefilter::Auto),
            Raw::Name(n) if n == "off" => Ok(SpotPrefilter::Off),
            Raw::Name(n) => Err(serde::de::Error::custom(format!(
                "spot_prefilter = \"{n}\": expected \"auto\", \"off\" or a level 0..={MAX_PREFILTER_LEVEL}"
            ))),
        }
    }
}

/// Settings of `epipolar` (`[render.epipolar]` in a scene file). Defaults were chosen by
/// measurement at 320×180 on the five built-in scenes against `reference` (512 steps), CPU
/// backend: each field quotes the means over the scenes of the in-scattering PSNR, the final
/// image's FLIP and the rays marched per pixel, changing that field alone from the defaults
/// (`tests/epipolar.rs`, `sweep_settings`, prints them). At the defaults: 45.38 dB / 0.0355 /
/// 0.106; brute-force at 64 steps 45.02 / 0.0305 / 1; subsampled at its defaults 41.96 /
/// 0.0540 / 0.085.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct EpipolarSettings {
    /// Number of epipolar lines (§4.1: "a user defined number of points equidistantly placed
    /// along the border of the screen"); also the rows of the line textures. More lines resolve
    /// thinner shafts across the lines and cost more texels in every pass (line generation,
    /// refinement, interpolation) and more ray-marched samples (K per line plus the
    /// discontinuities). When the epipole is off screen about half of them are culled. In
    /// 4..=8192. Default: auto, one line per 4 pixels of the sample rect's perimeter
    /// ([`EpipolarSettings::sizes`]: 124 at 160×90, 249 at 320×180, 749 at 960×540, 1499 at
    /// 1920×1080; the paper uses 256–1024 at 1920×1080). Measured: 64 lines 41.95 dB / 0.0536
    /// / 0.033, 128 44.43 / 0.0406 / 0.061, 192 45.09 / 0.0374 / 0.086, 256 45.43 / 0.0354 /
    /// 0.107, 384 45.59 / 0.0340 / 0.144, 512 45.66 / 0.0337 / 0.170, 1024 45.54 / 0.0331 /
    /// 0.213: the gain flattens past ~4 px spacing while the cost keeps growing.
    pub slices: Option<u32>,
    /// Texels per line, S: the most ray-march samples a line can have (§5.1: "the number of
    /// columns in this texture determines the maximum number of ray marching samples along
    /// that line") and the resolution at which depth discontinuities are found along it.
    /// Memory and the cost of the per-texel passes grow linearly with it. In 2..=8192.
    /// Default: auto, one texel per 1.5 pixels of the sample rect's diagonal (121 at 160×90,
    /// 244 at 320×180, 734 at 960×540, 1469 at 1920×1080). Measured: S = 64 45.04 dB / 0.0356
    /// / 0.087, 128 45.11 / 0.0356 / 0.098, 256 45.35 / 0.0353 / 0.106, 512 45.23 / 0.0354 /
    /// 0.108, 1024 45.21 / 0.0354 / 0.109; fewer texels than pixels along a line miss thin
    /// occluders' steps (cage: 53.7 dB at 64 and 128, 54.3 at auto).
    pub samples: Option<u32>,
    /// Initial ray-march samples per line, K (§4.1: "typically 8 to 32"), evenly spaced over
    /// the S texels; they split the line into K − 1 initial segments inside which the
    /// discontinuity search runs (cost ∝ S/K per texel). More resolves the smooth variation of
    /// the in-scattering along a line (the phase function's peak around the light, the
    /// attenuation) better, at K ray marches per line. With length-proportional initial
    /// samples, K is the count of a line as long as the screen's diagonal. In 2..=8192 and at
    /// most `samples` (a larger K is clamped to S). Default 32. Measured (length-proportional):
    /// K = 4 39.39 dB / 0.0984 / 0.073, 8 41.52 / 0.0627 / 0.078, 16 44.40 / 0.0419 / 0.087, 32
    /// 45.38 / 0.0355 / 0.106, 64 45.77 / 0.0341 / 0.141; below 16 the peak around the sun is
    /// lost (terrain: 28.7 dB at K = 4, 49.6 at 32).
    pub initial_samples: u32,
    /// Give a line K·ℓ/ℓ_max initial samples (at least 2) instead of K, ℓ its clipped on-screen
    /// length and ℓ_max the diagonal of the screen — the improvement §6 suggests for short
    /// lines near the border, which otherwise oversample: the same density of initial samples
    /// per pixel on every line. On the built-in scenes (the epipole inside the screen, lines
    /// shorter than the diagonal) it is a wash at equal cost: without it K = 8 gives 44.53 dB /
    /// 0.0406 / 0.090 and K = 16 45.48 / 0.0355 / 0.112, against 44.40 / 0.0419 / 0.087 and
    /// 45.38 / 0.0355 / 0.106 with it at K = 16 and 32; it saves the marches where the epipole
    /// is near the border. Default true.
    pub length_proportional_initial_samples: bool,
    /// Absolute part of the depth discontinuity threshold, in metres of view distance (§4.2,
    /// the paper's threshold): adjacent texels a, b are a discontinuity when |s_a − s_b| >
    /// `depth_threshold` + `threshold_growth`·min(s_a, s_b). ≥ 0 and finite; at least one of the
    /// two must be > 0. Default 0 (a purely relative threshold: the built-in scenes span 3 m
    /// to 200 m, and a fixed metre threshold suits none of them at once).
    pub depth_threshold: f32,
    /// Relative part of the threshold, dimensionless: the threshold grows with the distance
    /// (§6: "larger depth thresholds for distant parts of the scene"). Smaller places more
    /// ray-march samples (steep surfaces such as a ground plane towards the horizon trigger
    /// it), larger misses silhouettes against near backgrounds. ≥ 0 and finite. Default 0.05.
    /// Measured: 0.005 45.61 dB / 0.0323 / 0.270, 0.01 45.50 / 0.0330 / 0.213, 0.02 45.45 /
    /// 0.0338 / 0.150, 0.05 45.38 / 0.0355 / 0.106, 0.1 45.36 / 0.0364 / 0.093, 0.2 45.33 /
    /// 0.0374 / 0.083, 0.5 41.04 / 0.0400 / 0.075 (the lantern's bars are lost); absolute
    /// thresholds instead (growth 0) of 0.1 / 0.3 / 1 / 3 m: 45.75 / 0.0331 / 0.339, 45.62 /
    /// 0.0345 / 0.243, 45.49 / 0.0357 / 0.131, 45.31 / 0.0375 / 0.088 — a metre threshold
    /// cannot suit the 3 m lantern and the 180 m terrain at once (terrain marches 0.53 of its
    /// pixels at 0.1 m).
    pub threshold_growth: f32,
    /// Taps of the bilateral filter along each of the two lines (§4.3: "a 3 to 5 tap
    /// 1D-bilateral filter"), spaced by the distance between the pixel's projections on the
    /// two lines. Odd, 1..=9. Cost per pixel ∝ taps. Default 3. Measured: 1 45.19 dB / 0.0359,
    /// 3 45.38 / 0.0355, 5 and 7 45.39 / 0.0355.
    pub taps: u32,
    /// The radial basis functions of the bilateral weights. Default `"gaussian"`. Measured,
    /// by depth σ 0.02 / 0.05 / 0.1 / 0.2 / 0.5: Gaussian 45.34 / 45.37 / 45.38 / 45.39 / 45.12
    /// dB, Shepard 45.36 / 45.14 / 45.15 / 45.14 / 44.72 (its long tail never rejects a
    /// foreground tap: forest 34.3 dB against 35.5), threshold 45.34 / 45.36 / 45.37 / 45.38 /
    /// 45.36 — as the paper found, all comparable once σ is adjusted.
    pub weighting: Weighting,
    /// Width σ of the spatial kernel, in tap spacings (dimensionless): tap j weighs
    /// w(|j|/σ). Larger blurs along the lines. > 0 and finite. Default 1. Measured: 0.25 45.19
    /// dB, 0.5 45.22, 1 45.38, 2 and 4 45.40 (FLIP 0.0355 from 1 up).
    pub spatial_scale: f32,
    /// Width σ of the depth kernel on the relative view-distance difference |sᵢ − s|/s
    /// (dimensionless). Smaller rejects more taps (more outer-line searches and re-marches),
    /// larger blurs fog across silhouettes. > 0 and finite. Default 0.1 (see `weighting`).
    pub depth_scale: f32,
    /// How many lines further out the upsampling looks on each side when a line has no
    /// usable tap (§5.3: "we move to the next outer line"). Each costs `taps` more lookups for
    /// the pixels that need it. In 0..=8. Default 2. Measured: with re-marching 45.37 / 45.37 /
    /// 45.38 / 45.38 dB at 0 / 1 / 2 / 4, without 45.12 / 45.26 / 45.33 / 45.37 (forest, whose
    /// leaves defeat whole lines, decides it).
    pub outer_lines: u32,
    /// Ray-march a pixel at full resolution (as `brute-force`) when no line within
    /// `outer_lines` has a usable tap, instead of taking the tap nearest in depth. Costs N
    /// steps per such pixel (counted in `remarched_pixels`; ≤ 0.3 % of the pixels on the
    /// built-in scenes). Default true (see `outer_lines`).
    pub fallback_remarch: bool,
    /// Re-march, at full resolution, the pixels within this many pixels of the epipole instead
    /// of interpolating them (not in the paper). The in-scattering may peak at the light's own
    /// pixel — like 1/d² for a point or spot light seen directly, and for a sun seen through a
    /// strongly forward phase function (g → 1) — and the lines, which all start there, would
    /// smear the peak linearly over their first initial segment. Costs about π·r² pixel
    /// marches (counted in `remarched_pixels`; none when the epipole is off screen or in the
    /// degenerate case). Pixels, finite, in [0, 64]; 0 disables. Default 3. Measured on cage
    /// (the point light in view): 48.62 dB at 0, 47.99 at 1, 51.50 at 2, 54.33 at 3 (28
    /// pixels), 54.61 at 4 (51 pixels; brute-force 54.60); the other built-in scenes change by
    /// < 0.02 dB; the robustness sweep's g = 0.99 sun halo (tests/robustness.rs, 64×36) goes
    /// from an NMAE of 1.37 with the radius for point and spot lights only to 0.028 (brute-force
    /// 0.001, subsampled 0.86).
    pub epipole_radius: f32,
    /// Prefilter the spot light's texture for the ray-marched samples: `"auto"` (from the
    /// number of lines, [`SpotPrefilter::level`]), `"off"`, or a level L (box filter by 2^L).
    /// Costs one pass over the texture per frame. Default `"auto"`.
    pub spot_prefilter: SpotPrefilter,
    /// Ray-marching steps per sample (and per re-marched pixel), N in eq. 1 of Tóth &
    /// Umenhoffer 2009, as in `brute-force`. Cost is linear in N. In 1..=4096. Default 64.
    pub steps: u32,
    /// Offset each sample's steps by the per-pixel jitter of its pixel (as `brute-force` would
    /// there) instead of the step midpoint. Default false.
    pub jitter: bool,
    /// Seed of the jitter. Default 0.
    pub frame_index: u32,
    /// Where the N steps go for a spot light (Wyman & Ramsey 2008, App. B), as in
    /// `brute-force`: `"fixed"`, `"exact-cone"`, `"appendix-b-constant"`,
    /// `"appendix-b-smoothstep"`. Default `"exact-cone"`, the library-wide default (the
    /// robustness sweep in docs/ROBUSTNESS.md).
    pub spot_steps: SpotSteps,
    /// The App. B denominator of the `appendix-b-*` policies, in (0, 1]. Default 0.3.
    pub spot_denominator: f32,
    /// How each ray-march sample integrates its ray: `"steps"` (default: `steps` fixed steps,
    /// as `brute-force`) or `"minmax"` — the walk of `minmax` through a min-max tree on a
    /// rectified shadow map of `minmax_map_size` (Yusov 2013 combines epipolar sampling with
    /// Chen et al. 2011's 1D min-max mipmaps in exactly this way): exact at that map's
    /// resolution, no step count, its cost the tree's build (once per frame) plus nodes per
    /// sample instead of `steps` lookups. The re-marched pixels (epipole, fallback) keep their
    /// `steps`; a spot or point light's quadrature takes `steps` segments (at most 1024). The
    /// tree's own settings are `minmax`'s defaults (all levels, 512 nodes per ray); its map is
    /// always resampled from the shadow map (no host raster). Samples near a visible light's
    /// epipole, where the rectified map has little precision, walk it too: only the
    /// `epipole_radius` pixels are re-marched.
    pub march: EpipolarMarch,
    /// The rectified map of `march = "minmax"`, [columns, rows] (columns a power of two, as
    /// `minmax.map_size`). Memory: 20 bytes per texel. Default [1024, 1024].
    pub minmax_map_size: [u32; 2],
}

/// How `epipolar` integrates the ray of each ray-march sample.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum EpipolarMarch {
    /// `steps` fixed steps over the spot-step policy's interval (Engelhardt & Dachsbacher 2010).
    #[default]
    Steps,
    /// The min-max walk of `minmax` (Chen et al. 2011; Yusov 2013).
    Minmax,
}

impl Default for EpipolarSettings {
    fn default() -> Self {
        Self {
            slices: None,
            samples: None,
            initial_samples: 32,
            length_proportional_initial_samples: true,
            depth_threshold: 0.0,
            threshold_growth: 0.05,
            taps: 3,
            weighting: Weighting::Gaussian,
            spatial_scale: 1.0,
            depth_scale: 0.1,
            outer_lines: 2,
            fallback_remarch: true,
            epipole_radius: 3.0,
            spot_prefilter: SpotPrefilter::Auto,
            steps: 64,
            jitter: false,
            frame_index: 0,
            spot_steps: SpotSteps::ExactCone,
            spot_denominator: DEFAULT_SPOT_DENOMINATOR,
            march: EpipolarMarch::Steps,
            minmax_map_size: [1024, 1024],
        }
    }
}

impl From<&EpipolarSettings> for crate::march::PixelMarch {
    fn from(s: &EpipolarSettings) -> Self {
        Self {
            steps: s.steps,
            jitter: s.jitter,
            frame_index: s.frame_index,
            spot_steps: s.spot_steps,
            spot_denominator: s.spot_denominator,
        }
    }
}

impl EpipolarSettings {
    /// Checks every range (device limits are checked by [`Epipolar::encode`]).
    pub fn validate(&self) -> Result<(), Error> {
        let m = MAX_TEXELS_PER_SIDE;
        if let Some(v) = self.slices
            && !(4..=m).contains(&v)
        {
            return Err(Error::invalid("epipolar.slices", v, format!("must be in 4..={m}")));
        }
        if let Some(v) = self.samples
            && !(2..=m).contains(&v)
        {
            return Err(Error::invalid("epipolar.samples", v, format!("must be in 2..={m}")));
        }
        let k_max = self.samples.unwrap_or(m);
        if !(2..=k_max).contains(&self.initial_samples) {
            return Err(Error::invalid(
                "epipolar.initial_samples",
                self.initial_samples,
                format!("must be in 2..={k_max} (at most samples)"),
            ));
        }
        for (key, v) in [("depth_threshold", self.depth_threshold), ("threshold_growth", self.threshold_growth)] {
            if !(v.is_finite() && v >= 0.0) {
                return Err(Error::invalid(format!("epipolar.{key}"), v, "must be finite and ≥ 0"));
            }
        }
        if self.depth_threshold == 0.0 && self.threshold_growth == 0.0 {
            return Err(Error::invalid(
                "epipolar.threshold_growth",
                self.threshold_growth,
                "depth_threshold and threshold_growth cannot both be 0 (every texel would be a discontinuity)",
            ));
        }
        if !(1..=9).contains(&self.taps) || self.taps.is_multiple_of(2) {
            return Err(Error::invalid("epipolar.taps", self.taps, "must be odd, 1..=9"));
        }
        for (key, v) in [("spatial_scale", self.spatial_scale), ("depth_scale", self.depth_scale)] {
            if !(v.is_finite() && v > 0.0) {
                return Err(Error::invalid(format!("epipolar.{key}"), v, "must be finite and > 0"));
            }
        }
        if self.outer_lines > 8 {
            return Err(Error::invalid("epipolar.outer_lines", self.outer_lines, "must be in 0..=8"));
        }
        if !(self.epipole_radius.is_finite() && (0.0..=64.0).contains(&self.epipole_radius)) {
            return Err(Error::invalid(
                "epipolar.epipole_radius",
                self.epipole_radius,
                "must be finite, in [0, 64] pixels",
            ));
        }
        if let SpotPrefilter::Level(l) = self.spot_prefilter
            && l > MAX_PREFILTER_LEVEL
        {
            return Err(Error::invalid(
                "epipolar.spot_prefilter",
                l,
                format!("a level must be in 0..={MAX_PREFILTER_LEVEL}"),
            ));
        }
        if !(1..=4096).contains(&self.steps) {
            return Err(Error::invalid("epipolar.steps", self.steps, "must be in 1..=4096"));
        }
        validate_spot_denominator("epipolar.spot_denominator", self.spot_denominator)?;
        // The tree's settings (checked whatever `march` is, so a bad value is never kept).
        self.minmax().validate().map_err(|e| match e {
            Error::Invalid { key, value, reason } if key == "minmax.map_size" => {
                Error::Invalid { key: "epipolar.minmax_map_size".into(), value, reason }
            }
            other => other,
        })
    }

    /// The min-max tree's settings for `march = "minmax"`: `minmax_map_size`, `steps` quadrature
    /// segments for local lights, this technique's spot-step policy; no epipole disc (the
    /// upsampling re-marches those pixels).
    pub fn minmax(&self) -> crate::techniques::minmax::MinmaxSettings {
        crate::techniques::minmax::MinmaxSettings {
            map_size: self.minmax_map_size,
            light_steps: self.steps.min(1024),
            spot_steps: self.spot_steps,
            spot_denominator: self.spot_denominator,
            epipole_radius: 0,
            ..Default::default()
        }
    }

    /// (slices, samples) for a `width`×`height` image: the settings, or where they are unset
    /// (auto) one line per 4 pixels of the sample rect's perimeter P = 2·(W − 1 + H − 1) and
    /// one texel per 1.5 pixels of its diagonal D, i.e. round(P/4) clamped to 4..=8192 and
    /// round(D/1.5) clamped to 16..=8192.
    pub fn sizes(&self, width: u32, height: u32) -> (u32, u32) {
        let (w, h) = (width.max(1) as f64 - 1.0, height.max(1) as f64 - 1.0);
        let m = MAX_TEXELS_PER_SIDE;
        let slices = self.slices.unwrap_or_else(|| ((2.0 * (w + h) / 4.0).round() as u32).clamp(4, m));
        let samples = self.samples.unwrap_or_else(|| (((w * w + h * h).sqrt() / 1.5).round() as u32).clamp(16, m));
        (slices, samples)
    }

    /// The spot-texture prefilter level for `desc`'s light (0 without a textured spot light).
    pub fn prefilter_level(&self, desc: &FrameDesc) -> u32 {
        match desc.lights.first().map(|l| &l.light) {
            Some(Light::Spot { texture: Some(t), .. }) => {
                self.spot_prefilter.level(t.width.max(t.height), self.sizes(desc.width, desc.height).0)
            }
            _ => 0,
        }
    }
}

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
    /// [`SpotSteps::code`].
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
    /// Re-march radius around the epipole, pixels (point and spot lights).
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
            steps: s.steps,
            jitter: s.jitter as u32,
            frame_index: s.frame_index,
            spot_steps: s.spot_steps.code(),
            spot_denominator: s.spot_denominator,
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

/// The textures and buffers whose size depends on (samples, slices) and the image size.
struct Sized {
    key: [u32; 4],
    lines: wgpu::Buffer,
    list: wgpu::Buffer,
    claims: wgpu::Buffer,
    coords: wgpu::Texture,
    interp: wgpu::Texture,
    marched: wgpu::Texture,
    radiance: wgpu::Texture,
    /// Views of coords, interp, marched, radiance (made once, so the bind groups stay valid).
    views: [wgpu::TextureView; 4],
}

impl Sized {
    fn bytes(&self) -> u64 {
        let texels = self.key[0] as u64 * self.key[1] as u64;
        let pixels = self.key[2] as u64 * self.key[3] as u64;
        self.lines.size() + self.list.size() + self.claims.size() + texels * (16 + 4 + 16) + pixels * 16
    }
}

/// The prefiltered spot texture (technique-owned).
struct Prefiltered {
    texture: wgpu::Texture,
    view: wgpu::TextureView,
    /// The same texture as the one-layer array the march binds.
    array: wgpu::TextureView,
}

/// The GPU side of `epipolar`: pipelines, uniform and counter buffers, and the line textures,
/// built once and reused (the line textures are reallocated only when `samples` or `slices`
/// change, the prefiltered spot texture when its size does).
pub struct Epipolar {
    /// Current settings; changes apply on the next [`Epipolar::encode`].
    pub settings: EpipolarSettings,
    layouts: Layouts,
    pipelines: Pipelines,
    buffers: pass::FrameBuffers,
    /// The lights as the march reads them (the prefiltered spot texture's layer and size).
    march_lights: wgpu::Buffer,
    params_buffer: wgpu::Buffer,
    counters: wgpu::Buffer,
    indirect: wgpu::Buffer,
    white: wgpu::TextureView,
    sized: Option<Sized>,
    prefiltered: Option<Prefiltered>,
    last_params: Option<EpipolarParams>,
    binds: pass::BindCache<Binds>,
    /// `march = "minmax"`: the tree and the walk's pipeline, built on the first such frame.
    minmax: Option<MinmaxMarch>,
}

/// What `march = "minmax"` adds: the min-max tree of the frame and the march that walks it.
struct MinmaxMarch {
    tree: crate::techniques::minmax::TreeBuilder,
    layout: wgpu::BindGroupLayout,
    pipeline: wgpu::ComputePipeline,
    binds: pass::BindCache<wgpu::BindGroup>,
}

impl MinmaxMarch {
    fn new(device: &wgpu::Device) -> Self {
        use pass::storage_buffer_entry as buf;
        let layout = pass::frame_pass_layout(
            device,
            "epipolar march (minmax)",
            &[buf(6, true, None), buf(7, true, Some(4)), buf(8, true, Some(16))],
        );
        let pipeline =
            pass::compute_pipeline(device, "epipolar/march_minmax.wgsl", &march_minmax_source(), "march", &layout);
        Self { tree: crate::techniques::minmax::TreeBuilder::new(device), layout, pipeline, binds: Default::default() }
    }
}

/// The bind groups of one frame's passes (`prefilter` only with a prefiltered spot texture).
struct Binds {
    prefilter: Option<wgpu::BindGroup>,
    lines: wgpu::BindGroup,
    refine: wgpu::BindGroup,
    march: wgpu::BindGroup,
    interpolate: wgpu::BindGroup,
    upsample: wgpu::BindGroup,
}

struct Layouts {
    prefilter: wgpu::BindGroupLayout,
    lines: wgpu::BindGroupLayout,
    refine: wgpu::BindGroupLayout,
    march: wgpu::BindGroupLayout,
    interpolate: wgpu::BindGroupLayout,
    upsample: wgpu::BindGroupLayout,
}

struct Pipelines {
    prefilter: wgpu::ComputePipeline,
    lines: wgpu::ComputePipeline,
    coordinates: wgpu::ComputePipeline,
    refine: wgpu::ComputePipeline,
    args: wgpu::ComputePipeline,
    march: wgpu::ComputePipeline,
    interpolate: wgpu::ComputePipeline,
    upsample: wgpu::ComputePipeline,
}

/// A write-only 2D storage texture of `format` at `binding`.
fn storage_entry(binding: u32, format: wgpu::TextureFormat) -> wgpu::BindGroupLayoutEntry {
    wgpu::BindGroupLayoutEntry {
        binding,
        visibility: wgpu::ShaderStages::COMPUTE,
        ty: wgpu::BindingType::StorageTexture {
            access: wgpu::StorageTextureAccess::WriteOnly,
            format,
            view_dimension: wgpu::TextureViewDimension::D2,
        },
        count: None,
    }
}

/// A `texture_2d<u32>` at `binding`.
fn uint_texture_entry(binding: u32) -> wgpu::BindGroupLayoutEntry {
    wgpu::BindGroupLayoutEntry {
        binding,
        visibility: wgpu::ShaderStages::COMPUTE,
        ty: wgpu::BindingType::Texture {
            sample_type: wgpu::TextureSampleType::Uint,
            view_dimension: wgpu::TextureViewDimension::D2,
            multisampled: false,
        },
        count: None,
    }
}

impl Layouts {
    fn new(device: &wgpu::Device, output: wgpu::TextureFormat) -> Self {
        use pass::{storage_buffer_entry as buf, texture_entry as tex, uniform_entry as uni};
        use wgpu::TextureFormat as F;
        use wgpu::TextureViewDimension::{D2, D2Array};
        let layout = |label: &str, entries: &[wgpu::BindGroupLayoutEntry]| {
            device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor { label: Some(label), entries })
        };
        Self {
            prefilter: layout(
                "epipolar prefilter",
                &[uni(0), tex(1, D2Array), storage_entry(2, F::Rgba32Float), pass::lights_entry()],
            ),
            lines: layout(
                "epipolar lines",
                &[
                    uni(0),
                    uni(1),
                    tex(2, D2),
                    buf(3, false, Some(32)),
                    storage_entry(4, F::Rgba32Float),
                    buf(5, false, Some(16)),
                    pass::lights_entry(),
                ],
            ),
            refine: layout(
                "epipolar refine",
                &[
                    uni(0),
                    uni(1),
                    tex(2, D2),
                    buf(3, true, Some(32)),
                    storage_entry(4, F::R32Uint),
                    buf(5, false, Some(4)),
                    buf(6, false, Some(16)),
                    buf(7, false, Some(12)),
                    buf(8, false, Some(4)),
                ],
            ),
            march: pass::frame_pass_layout(device, "epipolar march", &[buf(7, true, Some(4)), buf(8, true, Some(16))]),
            interpolate: layout(
                "epipolar interpolate",
                &[uni(0), uni(1), tex(2, D2), uint_texture_entry(3), tex(4, D2), storage_entry(5, F::Rgba32Float)],
            ),
            upsample: pass::frame_pass_layout_to(
                device,
                "epipolar upsample",
                &[tex(6, D2), buf(7, true, Some(32)), buf(8, false, Some(16))],
                output,
            ),
        }
    }
}

impl Epipolar {
    /// Builds the pipelines and the size-independent buffers.
    pub fn new(gpu: &GpuContext, settings: EpipolarSettings, output: wgpu::TextureFormat) -> Result<Self, Error> {
        settings.validate()?;
        gpu.scoped("creating the epipolar pipelines", || {
            let device = &gpu.device;
            let layouts = Layouts::new(device, output);
            let pipe = |name: &str, src: &str, entry: &str, layout: &wgpu::BindGroupLayout| {
                pass::compute_pipeline(device, &format!("{name}.wgsl ({entry})"), &pass_source(src), entry, layout)
            };
            let pipelines = Pipelines {
                prefilter: pipe("epipolar/prefilter", PREFILTER_WGSL, "prefilter", &layouts.prefilter),
                lines: pipe("epipolar/lines", LINES_WGSL, "lines", &layouts.lines),
                coordinates: pipe("epipolar/lines", LINES_WGSL, "coordinates", &layouts.lines),
                refine: pipe("epipolar/refine", REFINE_WGSL, "refine", &layouts.refine),
                args: pipe("epipolar/refine", REFINE_WGSL, "args", &layouts.refine),
                march: pipe("epipolar/march", MARCH_WGSL, "march", &layouts.march),
                interpolate: pipe("epipolar/interpolate", INTERPOLATE_WGSL, "interpolate", &layouts.interpolate),
                upsample: pipe(
                    "epipolar/upsample",
                    &pass::with_output(UPSAMPLE_WGSL, output),
                    "upsample",
                    &layouts.upsample,
                ),
            };
            let buf = |label, size, usage| {
                device.create_buffer(&wgpu::BufferDescriptor {
                    label: Some(label),
                    size,
                    usage,
                    mapped_at_creation: false,
                })
            };
            use wgpu::BufferUsages as U;
            Self {
                settings,
                layouts,
                pipelines,
                buffers: pass::FrameBuffers::new(device),
                march_lights: pass::uniform_buffer(
                    device,
                    "epipolar march lights",
                    std::mem::size_of::<crate::LightsUniforms>() as u64,
                ),
                params_buffer: pass::uniform_buffer(
                    device,
                    "epipolar params",
                    std::mem::size_of::<EpipolarParams>() as u64,
                ),
                counters: buf("epipolar counters", 16, U::STORAGE | U::COPY_DST | U::COPY_SRC),
                indirect: buf("epipolar march dispatch", 12, U::STORAGE | U::INDIRECT),
                white: pass::white_array(gpu),
                sized: None,
                prefiltered: None,
                last_params: None,
                binds: Default::default(),
                minmax: None,
            }
        })
    }

    /// Bytes of GPU memory this technique holds: uniform, counter and indirect buffers, the
    /// 1×1 white texture, the line buffer, the sample list, the per-pixel claims (4 B per
    /// pixel), the three line textures (coordinates 16 B, interpolation 4 B, radiance 16 B per
    /// texel), the marched texture (16 B per pixel) and the prefiltered spot texture.
    pub fn gpu_memory_bytes(&self) -> u64 {
        let pre = self.prefiltered.as_ref().map_or(0, |p| p.texture.width() as u64 * p.texture.height() as u64 * 16);
        self.buffers.size()
            + self.params_buffer.size()
            + self.counters.size()
            + self.indirect.size()
            + 16
            + self.sized.as_ref().map_or(0, Sized::bytes)
            + pre
            + self.minmax.as_ref().map_or(0, |m| m.tree.gpu_memory_bytes())
    }

    /// The coordinate texture of the last frame (`Rgba32Float`, `samples` × `slices`: p.x,
    /// p.y, view distance s of pixel ⌊p⌋, valid); None before the first render.
    pub fn coordinate_texture(&self) -> Option<&wgpu::Texture> {
        self.sized.as_ref().map(|s| &s.coords)
    }
    /// The interpolation texture of the last frame (`R32Uint`: left | right << 16; left =
    /// right = t marks a ray-march sample; 0 on culled lines).
    pub fn interpolation_texture(&self) -> Option<&wgpu::Texture> {
        self.sized.as_ref().map(|s| &s.interp)
    }
    /// The ray-marched samples of the last frame, by pixel (`Rgba32Float`, image size:
    /// in-scattering, s); pixels that were not ray-marched hold stale values.
    pub fn marched_texture(&self) -> Option<&wgpu::Texture> {
        self.sized.as_ref().map(|s| &s.marched)
    }
    /// The radiance texture of the last frame (`Rgba32Float`: in-scattering interpolated
    /// along the lines, view distance s in alpha; 0 on culled lines).
    pub fn radiance_texture(&self) -> Option<&wgpu::Texture> {
        self.sized.as_ref().map(|s| &s.radiance)
    }
    /// The uniform block of the last frame (with its epipole).
    pub fn last_params(&self) -> Option<&EpipolarParams> {
        self.last_params.as_ref()
    }

    /// Reads the last frame's lines and line textures back for the debug views and tests.
    pub fn read_debug(&self, gpu: &GpuContext) -> Result<EpipolarDebug, Error> {
        let (Some(s), Some(p)) = (self.sized.as_ref(), self.last_params.as_ref()) else {
            return Err(Error::invalid("epipolar debug", "none", "no frame rendered yet"));
        };
        let rgba = |t: &wgpu::Texture| -> Result<Vec<[f32; 4]>, Error> {
            Ok(gpu.read_texture_f32(t, 0)?.chunks_exact(4).map(|c| [c[0], c[1], c[2], c[3]]).collect())
        };
        let interp: Vec<u32> = gpu.read_texture_f32(&s.interp, 0)?.into_iter().map(f32::to_bits).collect();
        let lines: Vec<EpipolarLine> = bytemuck::cast_slice(&crate::scattering::read_buffer(gpu, &s.lines)?).to_vec();
        Ok(EpipolarDebug { params: *p, lines, coords: rgba(&s.coords)?, interp, radiance: rgba(&s.radiance)? })
    }

    /// (Re)allocates the line textures and buffers for `samples` × `slices` and the per-pixel
    /// ones for `width` × `height`.
    fn ensure_sized(
        &mut self,
        gpu: &GpuContext,
        samples: u32,
        slices: u32,
        width: u32,
        height: u32,
    ) -> Result<(), Error> {
        let key = [samples, slices, width, height];
        if self.sized.as_ref().is_some_and(|s| s.key == key) {
            return Ok(());
        }
        gpu.check_texture_size("epipolar line textures (samples × slices)", samples, slices)?;
        gpu.check_texture_size("epipolar marched texture", width, height)?;
        let texels = samples as u64 * slices as u64;
        let pixels = width as u64 * height as u64;
        let list_bytes = texels.min(pixels) * 4;
        let limit = gpu.device.limits().max_storage_buffer_binding_size;
        for (what, bytes) in [
            ("epipolar sample list (4 bytes × min(samples × slices, pixels))", list_bytes),
            ("epipolar pixel claims (4 bytes × pixels)", pixels * 4),
        ] {
            if bytes > limit {
                return Err(Error::Limit { what: what.into(), value: bytes, limit });
            }
        }
        self.sized = None;
        self.sized = Some(gpu.scoped("allocating the epipolar line textures", || {
            let device = &gpu.device;
            let texture =
                |label, format, width, height| crate::gpu::storage_texture(device, label, format, width, height);
            let buffer = |label, size| {
                device.create_buffer(&wgpu::BufferDescriptor {
                    label: Some(label),
                    size,
                    usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC | wgpu::BufferUsages::COPY_DST,
                    mapped_at_creation: false,
                })
            };
            use wgpu::TextureFormat as F;
            let coords = texture("epipolar coordinates", F::Rgba32Float, samples, slices);
            let interp = texture("epipolar interpolation", F::R32Uint, samples, slices);
            let marched = texture("epipolar marched radiance", F::Rgba32Float, width, height);
            let radiance = texture("epipolar radiance", F::Rgba32Float, samples, slices);
            let views = [&coords, &interp, &marched, &radiance].map(|t| t.create_view(&Default::default()));
            Sized {
                key,
                lines: buffer("epipolar lines", slices as u64 * 32),
                list: buffer("epipolar sample list", list_bytes.max(4)),
                claims: buffer("epipolar pixel claims", pixels * 4),
                coords,
                interp,
                marched,
                radiance,
                views,
            }
        })?);
        Ok(())
    }

    /// Records the in-scattering of `frame` into `output` (an `Rgba32Float` storage view of
    /// the frame's size) through `rec`. Passes, each timed: `prefilter` (when it runs),
    /// `lines`, `refine`, `march`, `interpolate`, `upsample` (see the module documentation).
    /// The stats' counts come from the GPU's counters once they are read back (the fields:
    /// module documentation, Stats).
    pub fn encode(
        &mut self,
        gpu: &GpuContext,
        rec: &mut Recorder,
        frame: &GpuFrame,
        output: &wgpu::TextureView,
    ) -> Result<TechniqueStats, Error> {
        self.settings.validate()?;
        let desc = frame.desc;
        let light = desc.single_light()?;
        let s = self.settings.clone();
        let max_wg = gpu.device.limits().max_compute_workgroups_per_dimension.max(1);
        let mut params = EpipolarParams::new(&s, desc, max_wg);
        self.ensure_sized(gpu, params.samples, params.slices, desc.width, desc.height)?;
        let spot = frame.spot_textures.filter(|_| light.spot_texture().is_some());
        if spot.is_none() {
            params.prefilter_level = 0;
        }
        // The prefiltered spot texture: ⌈w/2^L⌉ × ⌈h/2^L⌉ of the light's own texture.
        let pre_size = light.spot_texture().filter(|_| spot.is_some() && params.prefilter_level > 0).map(|t| {
            let n = 1u32 << params.prefilter_level;
            (t.width.div_ceil(n), t.height.div_ceil(n))
        });
        match pre_size {
            Some((w, h)) => {
                if self.prefiltered.as_ref().is_none_or(|p| p.texture.width() != w || p.texture.height() != h) {
                    self.prefiltered = Some(gpu.scoped("allocating the prefiltered spot texture", || {
                        let texture = crate::gpu::storage_texture(
                            &gpu.device,
                            "epipolar prefiltered spot texture",
                            wgpu::TextureFormat::Rgba32Float,
                            w,
                            h,
                        );
                        let view = texture.create_view(&Default::default());
                        let array = texture.create_view(&wgpu::TextureViewDescriptor {
                            dimension: Some(wgpu::TextureViewDimension::D2Array),
                            ..Default::default()
                        });
                        Prefiltered { texture, view, array }
                    })?);
                }
            }
            None => self.prefiltered = None,
        }
        self.buffers.write(rec, desc);
        // The march reads the prefiltered texture: layer 0 of its own array, at its size.
        let mut march_lights = desc.lights_uniforms();
        if let Some((w, h)) = pre_size {
            march_lights.items[0].texture_layer = 0;
            march_lights.items[0].texture_size = [w, h];
        }
        rec.write_buffer(&self.march_lights, bytemuck::bytes_of(&march_lights));
        rec.write_buffer(&self.params_buffer, bytemuck::bytes_of(&params));
        let sized = self.sized.as_ref().expect("allocated above");
        let [coords, interp, marched, radiance] = &sized.views;
        let frame_spot = frame.spot_textures.unwrap_or(&self.white);
        let march_spot = self.prefiltered.as_ref().map_or(frame_spot, |p| &p.array);
        let mut key = pass::frame_key(frame, output);
        key.extend([Bound::View(coords.clone()), Bound::View(march_spot.clone())]);
        key.push(match (&self.prefiltered, spot) {
            (Some(p), Some(_)) => Bound::View(p.view.clone()),
            _ => Bound::Choice(0),
        });
        if !self.binds.is_current(&key) {
            let binds = gpu.scoped("binding the epipolar inputs", || {
                use wgpu::BindingResource as R;
                let device = &gpu.device;
                let group = |label, layout, entries: &[wgpu::BindGroupEntry]| {
                    device.create_bind_group(&wgpu::BindGroupDescriptor { label: Some(label), layout, entries })
                };
                let e = |binding, resource| wgpu::BindGroupEntry { binding, resource };
                let fb = || self.buffers.frame.as_entire_binding();
                let pb = || self.params_buffer.as_entire_binding();
                let prefilter = match (&self.prefiltered, spot) {
                    (Some(p), Some(src)) => Some(group(
                        "epipolar prefilter",
                        &self.layouts.prefilter,
                        &[
                            e(0, pb()),
                            e(1, R::TextureView(src)),
                            e(2, R::TextureView(&p.view)),
                            pass::lights_binding(&self.buffers.lights),
                        ],
                    )),
                    _ => None,
                };
                let lines = group(
                    "epipolar lines",
                    &self.layouts.lines,
                    &[
                        e(0, fb()),
                        e(1, pb()),
                        e(2, R::TextureView(frame.depth)),
                        e(3, sized.lines.as_entire_binding()),
                        e(4, R::TextureView(coords)),
                        e(5, self.counters.as_entire_binding()),
                        pass::lights_binding(&self.buffers.lights),
                    ],
                );
                let refine = group(
                    "epipolar refine",
                    &self.layouts.refine,
                    &[
                        e(0, fb()),
                        e(1, pb()),
                        e(2, R::TextureView(coords)),
                        e(3, sized.lines.as_entire_binding()),
                        e(4, R::TextureView(interp)),
                        e(5, sized.list.as_entire_binding()),
                        e(6, self.counters.as_entire_binding()),
                        e(7, self.indirect.as_entire_binding()),
                        e(8, sized.claims.as_entire_binding()),
                    ],
                );
                let mut me =
                    pass::frame_pass_bindings(&self.buffers, &self.params_buffer, frame, &self.white, marched).to_vec();
                me[4] = e(4, R::TextureView(march_spot));
                me[6] = pass::lights_binding(&self.march_lights);
                me.extend([e(7, sized.list.as_entire_binding()), e(8, self.counters.as_entire_binding())]);
                let march = group("epipolar march", &self.layouts.march, &me);
                let interpolate = group(
                    "epipolar interpolate",
                    &self.layouts.interpolate,
                    &[
                        e(0, fb()),
                        e(1, pb()),
                        e(2, R::TextureView(coords)),
                        e(3, R::TextureView(interp)),
                        e(4, R::TextureView(marched)),
                        e(5, R::TextureView(radiance)),
                    ],
                );
                let mut ue =
                    pass::frame_pass_bindings(&self.buffers, &self.params_buffer, frame, &self.white, output).to_vec();
                ue.extend([
                    e(6, R::TextureView(radiance)),
                    e(7, sized.lines.as_entire_binding()),
                    e(8, self.counters.as_entire_binding()),
                ]);
                let upsample = group("epipolar upsample", &self.layouts.upsample, &ue);
                Binds { prefilter, lines, refine, march, interpolate, upsample }
            })?;
            self.binds.store(key, binds);
        }
        let Binds {
            prefilter: prefilter_bind,
            lines: lines_bind,
            refine: refine_bind,
            march: march_bind,
            interpolate: interpolate_bind,
            upsample: upsample_bind,
        } = self.binds.value();
        let (samples, slices) = (params.samples, params.slices);
        let (w, h) = (desc.width, desc.height);
        let p = &self.pipelines;
        if let (Some(bind), Some(pre)) = (&prefilter_bind, &self.prefiltered) {
            let (pw, ph) = (pre.texture.width(), pre.texture.height());
            rec.dispatch("prefilter", "epipolar prefilter", &p.prefilter, bind, [pw.div_ceil(8), ph.div_ceil(8), 1])?;
        }
        rec.pass("lines", |enc, ts| {
            enc.clear_buffer(&self.counters, 0, None);
            let mut pass = compute_pass(enc, "epipolar lines", ts);
            pass.set_bind_group(0, lines_bind, &[]);
            pass.set_pipeline(&p.lines);
            pass.dispatch_workgroups(slices.div_ceil(64), 1, 1);
            pass.set_pipeline(&p.coordinates);
            pass.dispatch_workgroups(samples.div_ceil(8), slices.div_ceil(8), 1);
        })?;
        rec.pass("refine", |enc, ts| {
            enc.clear_buffer(&sized.claims, 0, None);
            let mut pass = compute_pass(enc, "epipolar refine", ts);
            pass.set_bind_group(0, refine_bind, &[]);
            pass.set_pipeline(&p.refine);
            pass.dispatch_workgroups(samples.div_ceil(8), slices.div_ceil(8), 1);
            pass.set_pipeline(&p.args);
            pass.dispatch_workgroups(1, 1, 1);
        })?;
        let minmax_march = s.march == EpipolarMarch::Minmax;
        if minmax_march {
            // The tree (minmax's `rectify` and `build`), then the walk per listed pixel.
            let mm = self.minmax.get_or_insert_with(|| MinmaxMarch::new(&gpu.device));
            let march_frame = GpuFrame { spot_textures: Some(march_spot), ..*frame };
            // Always resampled (epipolar asks the host for no rectified raster), as on the CPU.
            mm.tree.encode(gpu, rec, &march_frame, &s.minmax(), &self.buffers, false)?;
            let tree = mm.tree.tree().expect("built by encode").clone();
            let mut key = pass::frame_key(frame, marched);
            key.extend([Bound::Buffer(tree.clone()), Bound::View(march_spot.clone())]);
            if !mm.binds.is_current(&key) {
                let group = gpu.scoped("binding the epipolar min-max march", || {
                    let e = |binding, resource| wgpu::BindGroupEntry { binding, resource };
                    let mut me =
                        pass::frame_pass_bindings(&self.buffers, mm.tree.params_buffer(), frame, &self.white, marched)
                            .to_vec();
                    me[4] = e(4, wgpu::BindingResource::TextureView(march_spot));
                    me[6] = pass::lights_binding(&self.march_lights);
                    me.extend([
                        e(6, tree.as_entire_binding()),
                        e(7, sized.list.as_entire_binding()),
                        e(8, self.counters.as_entire_binding()),
                    ]);
                    gpu.device.create_bind_group(&wgpu::BindGroupDescriptor {
                        label: Some("epipolar march (minmax)"),
                        layout: &mm.layout,
                        entries: &me,
                    })
                })?;
                mm.binds.store(key, group);
            }
            let (pipeline, bind) = (&mm.pipeline, mm.binds.value());
            rec.pass("march", |enc, ts| {
                let mut pass = compute_pass(enc, "epipolar march (minmax)", ts);
                pass.set_pipeline(pipeline);
                pass.set_bind_group(0, bind, &[]);
                pass.dispatch_workgroups_indirect(&self.indirect, 0);
            })?;
        } else {
            rec.pass("march", |enc, ts| {
                let mut pass = compute_pass(enc, "epipolar march", ts);
                pass.set_pipeline(&p.march);
                pass.set_bind_group(0, march_bind, &[]);
                pass.dispatch_workgroups_indirect(&self.indirect, 0);
            })?;
        }
        let groups = [samples.div_ceil(8), slices.div_ceil(8), 1];
        rec.dispatch("interpolate", "epipolar interpolate", &p.interpolate, interpolate_bind, groups)?;
        rec.pass("upsample", |enc, ts| {
            let mut pass = compute_pass(enc, "epipolar upsample", ts);
            pass.set_pipeline(&p.upsample);
            pass.set_bind_group(0, upsample_bind, &[]);
            pass.dispatch_workgroups(w.div_ceil(8), h.div_ceil(8), 1);
        })?;
        self.last_params = Some(params);
        // The GPU-classified counts join the stats once the counters are read back (never with
        // StatsMode::Off: reading them at once would stall the frame).
        let steps = s.steps as u64;
        rec.read_counters(&self.counters, move |data, stats| {
            let v: &[u32] = bytemuck::cast_slice(&data[..16]);
            let [marched_n, remarched, valid_lines, sample_texels] = [v[0], v[1], v[2], v[3]].map(u64::from);
            // The min-max march walks its samples instead of stepping them.
            stats.raymarched_samples = (if minmax_march { remarched } else { marched_n + remarched }) * steps;
            stats.extra = stats_extra(&params, (w, h), valid_lines, marched_n, remarched, sample_texels);
        });
        let mut extra = stats_extra(&params, (w, h), 0, 0, 0, 0);
        for k in ["valid_lines", "marched_samples", "sample_texels", "remarched_pixels", "marched_share"] {
            extra.remove(k);
        }
        Ok(TechniqueStats {
            technique: "epipolar".into(),
            backend: "gpu".into(),
            timing: String::new(),
            passes: Vec::new(),
            raymarched_samples: 0,
            gpu_memory_bytes: self.gpu_memory_bytes(),
            extra,
        })
    }
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

gpu_technique!(Epipolar, EpipolarSettings);
