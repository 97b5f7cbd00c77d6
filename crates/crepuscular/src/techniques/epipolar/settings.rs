//! `epipolar`'s settings (Engelhardt & Dachsbacher 2010 §3–4; docs/MODEL.md): what each knob
//! means, its unit, default and cost, and their validation.

use super::*;

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
    /// discontinuity search runs (one walk over each segment: S texel reads per line whatever
    /// K). More resolves the smooth variation of the in-scattering along a line (the phase
    /// function's peak around the light, the attenuation) better, at K ray marches per line. With length-proportional initial
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
    /// smear the peak linearly over their first initial segment. The disc's edge breaks the
    /// lines (both texels across it are ray-march samples) and its texels are left out of the
    /// upsampling's taps, for every light: under a sun whose epipole sits on an occluder's
    /// edge, the first texel's ray reads the edge's partial light over its whole length, and
    /// without the break the lines spread it over the occluder as a starburst (the Bevy demo
    /// at 480×270, bilinear lookups: the fast preset 28.5 → 37.8 dB, balanced 34.3 → 41.5 dB;
    /// terrain −0.24 dB, night-street +1.25 dB, the other built-in scenes unchanged). A pixel
    /// outside the disc whose points on both lines around it fall inside (the lines fan out
    /// near the epipole, radians apart where it sits a few pixels inside the border) is
    /// re-marched too: those lines offer no taps there, and the next ones only taps farther
    /// from the light (the shadowed closed form, tests/shadowed.rs, with the sun 3.6 px below
    /// the top border: 0.114 → 0.057 of the peak). Costs
    /// about π·r² pixel marches (counted in `remarched_pixels`; none when the epipole is off screen or in the
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
    /// How the ray-march samples and re-marched pixels march their rays ([`MarchSettings`], flattened: the keys `steps`, `jitter`, `frame_index`). `steps` is N in eq. 1 per sample and per re-marched pixel; a sample's
    /// jitter is its pixel's, as `brute-force` would use there.
    #[serde(flatten)]
    pub ray_march: MarchSettings,
    /// Where the steps go for spot and point lights ([`StepPolicy`], flattened: the keys
    /// `spot_steps`, `spot_denominator`, `local_steps`).
    #[serde(flatten)]
    pub policy: StepPolicy,
    /// How each ray-march sample integrates its ray: `"steps"` (default: `steps` fixed steps,
    /// as `brute-force`) or `"minmax"` — the walk of `minmax` through a min-max tree on a
    /// rectified shadow map of `minmax_map_size` (Yusov 2013 combines epipolar sampling with
    /// Chen et al. 2011's 1D min-max mipmaps in exactly this way): exact at that map's
    /// resolution, no step count, its cost the tree's build (once per frame) plus nodes per
    /// sample instead of `steps` lookups. The re-marched pixels (epipole, fallback) keep their
    /// `steps`; a spot or point light's quadrature takes `steps` segments (at most 1024). The
    /// tree's own settings are `minmax`'s defaults (all levels, 1024 nodes per ray); its map is
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
            ray_march: MarchSettings::default(),
            policy: StepPolicy::default(),
            march: EpipolarMarch::Steps,
            minmax_map_size: [1024, 1024],
        }
    }
}

impl EpipolarSettings {
    /// Checks every range (device limits are checked by `Epipolar::encode`).
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
        self.ray_march.validate("epipolar")?;
        self.policy.validate("epipolar")?;
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
            light_steps: self.ray_march.steps.min(1024),
            policy: self.policy,
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
