//! Settings of `prefiltered` and the uniform block its passes share.

use super::rectify::{MAX_BANDS, MAX_REGIONS, Rectification, RectificationChoice, RectifyOptions, ReferenceRay};
use crate::error::Error;
use crate::march::StepPolicy;
use serde::{Deserialize, Serialize};

/// Storage of the filtered-basis textures (§3.3, Appendix A).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum BasisPrecision {
    /// `Rgba8Unorm`: 1 byte per basis per texel. The normalised running mean (Listing 2) keeps
    /// every stored value in [0, 1], which is why 8 bits suffice (the paper saw no improvement
    /// above 8 bits).
    #[default]
    Unorm8,
    /// `Rgba16Float`: 2 bytes per basis per texel; twice the memory and bandwidth.
    Float16,
}

impl BasisPrecision {
    /// The texture format.
    pub fn format(self) -> wgpu::TextureFormat {
        match self {
            BasisPrecision::Unorm8 => wgpu::TextureFormat::Rgba8Unorm,
            BasisPrecision::Float16 => wgpu::TextureFormat::Rgba16Float,
        }
    }
    /// The WGSL storage format name.
    pub fn wgsl(self) -> &'static str {
        match self {
            BasisPrecision::Unorm8 => "rgba8unorm",
            BasisPrecision::Float16 => "rgba16float",
        }
    }
    /// Bytes per basis value.
    pub fn bytes(self) -> u64 {
        match self {
            BasisPrecision::Unorm8 => 1,
            BasisPrecision::Float16 => 2,
        }
    }
    /// What the storage does to a value in [0, 1] (the CPU mirror's quantisation).
    pub fn quantise(self, v: f32) -> f32 {
        match self {
            BasisPrecision::Unorm8 => (v.clamp(0.0, 1.0) * 255.0).round() / 255.0,
            BasisPrecision::Float16 => half_round(v),
        }
    }
}

/// Rounds to the nearest IEEE half (normal range, which [0, 1] values above 2⁻¹⁴ are in).
fn half_round(v: f32) -> f32 {
    if v.abs() < 6.1e-5 {
        return (v * 16777216.0).round() / 16777216.0;
    }
    let bits = v.to_bits();
    // Keep 10 mantissa bits, round to nearest even.
    let rounded = (bits + 0x0fff + ((bits >> 13) & 1)) & !0x1fff;
    f32::from_bits(rounded)
}

/// Settings of `prefiltered` (`[render.prefiltered]` in a scene file).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct PrefilteredSettings {
    /// M, the number of Fourier basis functions (sine and cosine counted separately, §5), a
    /// multiple of 4 in 4..=128; stored as M/4 RGBA layers. The series of eq. 9 is truncated at
    /// M/2 harmonics: fewer bases ring more around shadow edges (Fig. 7); cost of the prefilter
    /// and of the per-pixel dot product and memory grow linearly with M. Default 32 (the paper's
    /// conservative choice).
    pub bases: u32,
    /// Size of the rectified shadow map [columns, rows]: columns along the view rays, rows one
    /// per epipolar slice. Memory is columns·rows·M bytes (8-bit) plus 8 bytes per texel of
    /// depth and weight; prefilter time grows with it, the per-pixel cost does not (Table 2).
    /// Each side in 8..=8192. Default [1024, 1024] (the paper's Table 1 size).
    pub map_size: [u32; 2],
    /// Storage of the filtered bases: `"unorm8"` (default) or `"float16"` (2× memory).
    pub precision: BasisPrecision,
    /// `"auto"` (default): the projective rectification of §4.2 for a directional light whose
    /// projected camera frustum spans at most `max_projective_angle`, else the epipolar
    /// resampling of §4.1 (always for spot and point lights). `"projective"`: §4.2 whenever it is
    /// possible. `"epipolar"`: §4.1 always.
    pub rectification: RectificationChoice,
    /// The widest projected camera frustum (full angle around the light direction, degrees, in
    /// (0, 180)) that `"auto"` rectifies projectively. Towards 180° the epipole nears the screen
    /// and the projective map grows non-linear (§4.2): columns crowd near the camera. Default 150.
    pub max_projective_angle: f32,
    /// The largest ratio of far to near extent along the projective map's x axis that
    /// `"auto"` rectifies projectively (§4.2 "Non-linearity"). The projective map's columns are
    /// uniform in 1/x, so half of them lie between x_near and 2·x_near: with the camera's near
    /// plane at 0.1 m and far at 200 m (ratio ~2000) about 2 % of the columns cover 5–216 m, and
    /// on side-lit variants of the built-in scenes the epipolar map of the same frame is 2–12 dB
    /// better (colonnade 30.9 vs 32.8, terrain 46.2 vs 57.4, forest 41.0 vs 53.2 dB, measured by
    /// tests/prefiltered.rs). Must be > 1. Default 100: scenes with a sensible near plane for
    /// their extent get the paper's directly rasterized map, the built-in ones the epipolar one.
    pub max_projective_depth_ratio: f32,
    /// Regions per row, 1..=8 (§3.3 and Table 1: "regions per slice"; §4.2 "split shadow maps").
    /// Each region has its own prefix sum, run by its own threads (more parallelism in the
    /// prefilter); the evaluation then adds one lookup per region in front of the surface.
    /// Default 1.
    pub regions: u32,
    /// Where the region boundaries go in the projective map, in [0, 1]: 0 cuts one projective
    /// map into equal column ranges (Table 1's parallelisation only); 1 gives the regions equal
    /// world extents along x, each with its own projective map (the "split shadow maps" of §4.2,
    /// which counteract the map's crowding near the camera). Ignored by the epipolar map.
    /// Default 0.
    pub split_lambda: f32,
    /// Bases per prefilter thread, a multiple of 4 dividing `bases` (Table 1's "bases per
    /// thread"): fewer means more threads, each re-reading the depth row. Default 8 (the paper's
    /// choice on its hardware; see docs/RESULTS.md for this project's measurements).
    pub bases_per_thread: u32,
    /// Weight the prefix sum by transmittance along a reference ray per slice (§3.2, Listing 2;
    /// for local lights also by the light's falloff, cone and phase function there) instead of
    /// averaging visibility evenly (§3.1). Free; the paper recommends it. Default true.
    pub transmittance_weights: bool,
    /// The reference ray of each slice: `"bisectrix"` (default, the paper's) or `"optimal"`
    /// (k_ref = √(k_min·k_max), §3.2).
    pub reference_ray: ReferenceRay,
    /// Reference rays per slice, 1..=8 ("bands"). With one (the paper), every view ray of a
    /// slice is weighted as the slice's reference ray (§3.2) — but the world distance a ray
    /// travels per column grows as 1/sin θ towards the epipole, so rays near a visible sun are
    /// weighted far from their own transmittance, and the error grows towards the sun (Fig. 8's
    /// bleeding, well beyond the ray-marched disc). With more, the prefix sum runs once per
    /// band, each with its own reference ray (spread in ln θ over the slice, denser near the
    /// epipole), and each pixel blends the two bands around its own ray. At 160×90 against the
    /// reference (forest / colonnade / terrain, dB): 1 band 29.9 / 37.6 / 39.6, 4 bands
    /// 36.4 / 45.5 / 46.7, 8 bands 40.3 / 48.8 / 49.5 (brute-force at 64 steps: 33.7 / 35.4 /
    /// 49.5). Cost: the prefilter's time and the basis memory grow linearly with it (4 × 32 MiB
    /// at the default map and M), the per-pixel cost doubles from one band to two or more
    /// (two lookups); `reference_ray` applies to one band only. Our extension, not in the
    /// paper. Default 4.
    pub bands: u32,
    /// For a spot light with a texture: prefilter the visibility separately with each colour
    /// channel's light as the weight (§3.2 "Angular-dependency": "If the light has an associated
    /// color texture, we need to store one value for each color component"), so coloured shafts
    /// keep their colour where parts of the texture are occluded. 3× the prefilter's time and
    /// the basis memory for such a light; ignored for other lights. Default true.
    pub rgb_spot_weights: bool,
    /// Radius in pixels of the disc around the light's epipole that is ray-marched instead
    /// (§5, Fig. 8: "brute-force ray marching in a small block of pixels around the light
    /// source, if it is directly visible"), where view and light rays are nearly parallel and
    /// the rectification has no precision. Cost: π·r²·`epipole_steps` samples when the light is
    /// on screen. 0 turns it off. Default 8.
    pub epipole_radius: u32,
    /// Ray-marching steps per pixel in the epipole disc (eq. 1 of Tóth & Umenhoffer 2009).
    /// 1..=4096. Default 64.
    pub epipole_steps: u32,
    /// Quadrature points for the unoccluded in-scattering of a spot or point light along each
    /// view ray (the factor that multiplies the prefiltered visibility; a directional light has
    /// the closed form of eq. 3). Shadow-free, so cheap; 1..=1024. Default 32.
    pub light_steps: u32,
    /// Where the epipole march's steps and the local-light quadrature's segments go
    /// ([`StepPolicy`], flattened: the keys `spot_steps`, `spot_denominator`, `local_steps`).
    #[serde(flatten)]
    pub policy: StepPolicy,
}

/// How the epipole disc's pixels are ray-marched (§5): `epipole_steps`, step midpoints.
impl From<&PrefilteredSettings> for crate::march::MarchSettings {
    fn from(s: &PrefilteredSettings) -> Self {
        Self { steps: s.epipole_steps, jitter: false, frame_index: 0 }
    }
}

impl Default for PrefilteredSettings {
    fn default() -> Self {
        Self {
            bases: 32,
            map_size: [1024, 1024],
            precision: BasisPrecision::Unorm8,
            rectification: RectificationChoice::Auto,
            max_projective_angle: 150.0,
            max_projective_depth_ratio: 100.0,
            regions: 1,
            split_lambda: 0.0,
            bases_per_thread: 8,
            transmittance_weights: true,
            reference_ray: ReferenceRay::Bisectrix,
            bands: 4,
            rgb_spot_weights: true,
            epipole_radius: 8,
            epipole_steps: 64,
            light_steps: 32,
            policy: StepPolicy::default(),
        }
    }
}

impl PrefilteredSettings {
    /// Checks the ranges.
    pub fn validate(&self) -> Result<(), Error> {
        let m = self.bases;
        if !(4..=128).contains(&m) || m % 4 != 0 {
            return Err(Error::invalid("prefiltered.bases", m, "must be a multiple of 4 in 4..=128"));
        }
        let [w, h] = self.map_size;
        if !(8..=8192).contains(&w) || !(8..=8192).contains(&h) {
            return Err(Error::invalid("prefiltered.map_size", format!("[{w}, {h}]"), "each side must be in 8..=8192"));
        }
        if !(self.max_projective_angle > 0.0 && self.max_projective_angle < 180.0) {
            return Err(Error::invalid(
                "prefiltered.max_projective_angle",
                self.max_projective_angle,
                "must be in (0, 180) degrees",
            ));
        }
        if !(self.max_projective_depth_ratio > 1.0) {
            return Err(Error::invalid(
                "prefiltered.max_projective_depth_ratio",
                self.max_projective_depth_ratio,
                "must be > 1",
            ));
        }
        if !(1..=MAX_REGIONS).contains(&self.regions) || self.regions > w {
            return Err(Error::invalid(
                "prefiltered.regions",
                self.regions,
                format!("must be in 1..={MAX_REGIONS} and at most the map's columns"),
            ));
        }
        if !(0.0..=1.0).contains(&self.split_lambda) {
            return Err(Error::invalid("prefiltered.split_lambda", self.split_lambda, "must be in [0, 1]"));
        }
        let b = self.bases_per_thread;
        if b == 0 || b % 4 != 0 || m % b != 0 {
            return Err(Error::invalid(
                "prefiltered.bases_per_thread",
                b,
                format!("must be a multiple of 4 that divides bases ({m})"),
            ));
        }
        if !(1..=MAX_BANDS).contains(&self.bands) {
            return Err(Error::invalid("prefiltered.bands", self.bands, format!("must be in 1..={MAX_BANDS}")));
        }
        if !(1..=4096).contains(&self.epipole_steps) {
            return Err(Error::invalid("prefiltered.epipole_steps", self.epipole_steps, "must be in 1..=4096"));
        }
        if self.epipole_radius > 4096 {
            return Err(Error::invalid("prefiltered.epipole_radius", self.epipole_radius, "must be at most 4096"));
        }
        if !(1..=1024).contains(&self.light_steps) {
            return Err(Error::invalid("prefiltered.light_steps", self.light_steps, "must be in 1..=1024"));
        }
        self.policy.validate("prefiltered")
    }

    /// What the rectification needs.
    pub fn rectify_options(&self) -> RectifyOptions {
        RectifyOptions {
            width: self.map_size[0],
            height: self.map_size[1],
            regions: self.regions,
            split_lambda: self.split_lambda,
            choice: self.rectification,
            max_projective_angle: self.max_projective_angle,
            reference: self.reference_ray,
            bands: self.bands,
            max_projective_depth_ratio: self.max_projective_depth_ratio,
        }
    }

    /// Colour channels with their own weights for `light`: 3 for a textured spot with
    /// `rgb_spot_weights`, else 1.
    pub fn channels(&self, light: &crate::Light) -> u32 {
        if self.rgb_spot_weights && matches!(light, crate::Light::Spot { texture: Some(_), .. }) { 3 } else { 1 }
    }

    /// Weight sets (bands × channels) for `light`: each a full set of filtered bases.
    pub fn sets(&self, light: &crate::Light) -> u32 {
        self.bands * self.channels(light)
    }

    /// Layers of the filtered-basis texture array (M/4).
    pub fn layers(&self) -> u32 {
        self.bases / 4
    }

    /// Bytes of one set of filtered-basis textures (the paper's Table 2 "Memory" column); a
    /// frame holds [`PrefilteredSettings::sets`] of them.
    pub fn basis_bytes(&self) -> u64 {
        self.map_size[0] as u64 * self.map_size[1] as u64 * self.bases as u64 * self.precision.bytes()
    }
}

/// Bit of [`PrefilteredParams::flags`]: weight the bases by transmittance (`FLAG_TRANSMITTANCE_WEIGHTS`).
pub const FLAG_TRANSMITTANCE_WEIGHTS: u32 = 1;
/// Bit of [`PrefilteredParams::flags`]: the epipolar rectification covers the full circle (`FLAG_FULL_CIRCLE`).
pub const FLAG_FULL_CIRCLE: u32 = 2;
/// Bit of [`PrefilteredParams::flags`]: the host rasterized the depth map, so the volume bias is
/// added in the lookups (`FLAG_HOST_RASTER`).
pub const FLAG_HOST_RASTER: u32 = 4;

/// The uniform block of every prefiltered and minmax pass (`struct Params` in
/// prefiltered/geometry.wgsl, field for field).
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct PrefilteredParams {
    /// The rectification: [`super::rectify::Mode::code`] (`RECT_PROJECTIVE`, `RECT_EPIPOLAR`).
    pub mode: u32,
    /// 1 for a spot or point light.
    pub local: u32,
    /// Rectified map width (columns).
    pub width: u32,
    /// Rectified map height (rows).
    pub height: u32,
    /// Column regions.
    pub regions: u32,
    /// Bases M.
    pub bases: u32,
    /// Bases per prefilter thread.
    pub bases_per_thread: u32,
    /// [`FLAG_TRANSMITTANCE_WEIGHTS`] | [`FLAG_FULL_CIRCLE`] | [`FLAG_HOST_RASTER`].
    pub flags: u32,
    /// Epipole disc radius in pixels (0: off, or the light is not on screen).
    pub epipole_radius: u32,
    /// Steps of the epipole disc's march.
    pub epipole_steps: u32,
    /// Segments of the local light's quadrature.
    pub light_steps: u32,
    /// The step policy's code ([`crate::march::StepPolicy::code`]).
    pub spot_steps: u32,
    /// Camera position, mean extinction σ̄ for the weights.
    pub camera: [f32; 4],
    /// Light position, camera–light distance.
    pub light: [f32; 4],
    /// The three axes (xyz), w unused.
    pub axes: [[f32; 4]; 3],
    /// Projective (q₀, q₁, r₀, r₁); epipolar (φ₀, φ₁, θ₀, θ₁).
    pub ranges: [f32; 4],
    /// Epipole pixel (x, y), the volume bias (world units), the App. B denominator.
    pub epipole: [f32; 4],
    /// Region boundaries (regions + 1 used), padded to 12.
    pub region_x: [[f32; 4]; 3],
    /// Depth bands.
    pub bands: u32,
    /// Channels per band: 1, or 3 for an RGB spot texture.
    pub channels: u32,
    /// Levels of the min-max tree (minmax only; 0 for prefiltered).
    pub tree_levels: u32,
    /// The walk's node budget (minmax only; 0 for prefiltered).
    pub max_nodes: u32,
}

const _: () = assert!(std::mem::size_of::<PrefilteredParams>() == 224);

impl PrefilteredParams {
    /// The block for a frame.
    pub fn new(
        s: &PrefilteredSettings,
        r: &Rectification,
        sigma_mean: f32,
        bias: f32,
        epipole: Option<[f32; 2]>,
        host_raster: bool,
        channels: u32,
    ) -> Self {
        let mut rx = [0.0f32; 12];
        for (i, x) in r.region_x.iter().enumerate().take(12) {
            rx[i] = *x;
        }
        let bit = |on: bool, flag: u32| if on { flag } else { 0 };
        let flags = bit(s.transmittance_weights, FLAG_TRANSMITTANCE_WEIGHTS)
            | bit(r.full_circle, FLAG_FULL_CIRCLE)
            | bit(host_raster, FLAG_HOST_RASTER);
        let e = epipole.unwrap_or([0.0; 2]);
        let v = |v: glam::Vec3, w: f32| [v.x, v.y, v.z, w];
        Self {
            mode: r.mode.code(),
            local: r.local as u32,
            width: r.width,
            height: r.height,
            regions: r.regions,
            bases: s.bases,
            bases_per_thread: s.bases_per_thread,
            flags,
            epipole_radius: if epipole.is_some() { s.epipole_radius } else { 0 },
            epipole_steps: s.epipole_steps,
            light_steps: s.light_steps,
            spot_steps: s.policy.code(),
            camera: v(r.camera, sigma_mean),
            light: v(r.light, r.light_distance),
            axes: r.axes.map(|a| v(a, 0.0)),
            ranges: r.ranges.to_array(),
            epipole: [e[0], e[1], bias, s.policy.denominator],
            region_x: [[rx[0], rx[1], rx[2], rx[3]], [rx[4], rx[5], rx[6], rx[7]], [rx[8], rx[9], rx[10], rx[11]]],
            bands: r.bands,
            channels,
            tree_levels: 0,
            max_nodes: 0,
        }
    }
}
