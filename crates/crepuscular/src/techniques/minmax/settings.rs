//! Settings of `minmax`.

use crate::error::Error;
use crate::march::StepPolicy;
use crate::techniques::prefiltered::{PrefilteredSettings, RectificationChoice, rectify::RectifyOptions};
use serde::{Deserialize, Serialize};

/// The most coarser levels above the texels (a row of 8192 columns has 13).
pub const MAX_LEVELS: u32 = 13;

/// Settings of `minmax` (`[render.minmax]` in a scene file).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct MinmaxSettings {
    /// Size of the rectified shadow map [columns, rows]: columns along the view rays (a power of
    /// two, so that every level of the min-max tree halves its row exactly), rows one per
    /// epipolar slice; a pixel's ray walks its nearest row. Where the host rasterized the map
    /// (projective frames) this is the resolution at which the result is exact (docs/MODEL.md
    /// §8): a shadow edge lands on a column boundary. Where the map resamples the standard
    /// shadow map, a rectified texel bounds the standard texels it covers and a ray it leaves
    /// undecided is resolved exactly against the standard map there, so a coarser map costs
    /// more of those resolutions (`mixed_texels_per_ray` in the stats), not accuracy. Memory:
    /// columns·rows·16 bytes of tree (min and max for ~2 nodes per texel). Columns a power of
    /// two in 8..=8192, rows in 8..=8192. Default [1024, 1024].
    pub map_size: [u32; 2],
    /// Coarser levels of the 1D min-max tree above the texels, 0..=13 (clamped to log2 of the
    /// columns: all of them). Each level halves the nodes of the one below (Chen et al. 2011,
    /// §3): a view ray skips a span of 2^k columns that is all lit or all shadowed in one node
    /// visit. 0 walks the row texel by texel (cost proportional to the columns the ray crosses,
    /// the linear scan the tree accelerates; the same answer). Default 13.
    pub levels: u32,
    /// The most tree nodes one view ray may visit, 1..=65536: the cost bound. When a ray reaches
    /// it, the rest of its row is no longer refined: it climbs as high as the tree allows and
    /// counts each remaining node as lit (minimum ≥ the ray's depth), shadowed (maximum below
    /// it) or, where mixed, half lit — an error of at most half the in-scattering of the
    /// unrefined spans; `rays_over_budget` in the stats counts such rays. A bound on the cost
    /// with the tree's full height (`levels` at its default): with fewer levels the rest of the
    /// row is still walked node by node at the top level (columns / 2^levels nodes at most).
    /// Default 1024: never reached on the one-light built-in scenes at the default map (forest's
    /// longest walk is 573 nodes at 320×180), but reached by 9 % of night-street's walks (a
    /// pixel and a light each; mean 899 nodes, at most 6486 at 160×90) and by a few hundred of
    /// atrium's; see docs/RESULTS.md, "minmax's walk on every built-in scene".
    pub max_nodes: u32,
    /// The rectification, as `prefiltered`'s (§4 of Klehm et al. 2014): `"auto"` (default),
    /// `"projective"` or `"epipolar"`.
    pub rectification: RectificationChoice,
    /// As `prefiltered.max_projective_angle` (degrees, in (0, 180)). Default 150.
    pub max_projective_angle: f32,
    /// As `prefiltered.max_projective_depth_ratio` (> 1). Default 100.
    pub max_projective_depth_ratio: f32,
    /// Spot and point lights: radius in pixels of the disc around a visible light's epipole
    /// that is ray-marched instead, as `prefiltered` does (Klehm et al. 2014 §5). Near a local
    /// light its 1/d² falloff changes faster than `light_steps` segments follow; the disc's
    /// march samples it per step (cage: 46.4 dB without, 56.5 dB with, docs/quality.toml). A
    /// directional light never gets the disc ([`MinmaxSettings::for_frame`]): its lit spans are
    /// closed-form and its mixed texels exact, where the disc's march has a step error (on the
    /// shadowed closed form, docs/MODEL.md §4, the disc's pixels were the worst, 2.3 % of the
    /// peak; 0.5 % without; colonnade 63.6 → 67.3 dB). Cost: π·r²·`epipole_steps` samples when
    /// the light is on screen. 0 turns it off. Default 8.
    pub epipole_radius: u32,
    /// Ray-marching steps per pixel in the epipole disc, 1..=4096. Default 64.
    pub epipole_steps: u32,
    /// Spot and point lights: quadrature segments over the ray's lit interval, 1..=1024. The
    /// light's falloff, cone, texture and phase function are evaluated once per segment (at its
    /// transmittance-weighted midpoint) and multiply the exact transmittance integral of the
    /// segment's lit part. A directional light needs none (its integral is closed, exact at any
    /// setting). Cost: one light evaluation per segment a lit span touches. Default 32.
    pub light_steps: u32,
    /// Where the epipole march's steps and the local-light quadrature's segments go
    /// ([`StepPolicy`], flattened: the keys `spot_steps`, `spot_denominator`, `local_steps`).
    #[serde(flatten)]
    pub policy: StepPolicy,
}

impl Default for MinmaxSettings {
    fn default() -> Self {
        Self {
            map_size: [1024, 1024],
            levels: MAX_LEVELS,
            max_nodes: 1024,
            rectification: RectificationChoice::Auto,
            max_projective_angle: 150.0,
            max_projective_depth_ratio: 100.0,
            epipole_radius: 8,
            epipole_steps: 64,
            light_steps: 32,
            policy: StepPolicy::default(),
        }
    }
}

impl MinmaxSettings {
    /// Checks the ranges; the error names the setting and value.
    pub fn validate(&self) -> Result<(), Error> {
        let [w, h] = self.map_size;
        if !(8..=8192).contains(&w) || !w.is_power_of_two() || !(8..=8192).contains(&h) {
            return Err(Error::invalid(
                "minmax.map_size",
                format!("[{w}, {h}]"),
                "columns must be a power of two in 8..=8192, rows in 8..=8192",
            ));
        }
        if self.levels > MAX_LEVELS {
            return Err(Error::invalid("minmax.levels", self.levels, format!("must be in 0..={MAX_LEVELS}")));
        }
        if !(1..=65536).contains(&self.max_nodes) {
            return Err(Error::invalid("minmax.max_nodes", self.max_nodes, "must be in 1..=65536"));
        }
        if !(1..=4096).contains(&self.epipole_steps) {
            return Err(Error::invalid("minmax.epipole_steps", self.epipole_steps, "must be in 1..=4096"));
        }
        if self.epipole_radius > 4096 {
            return Err(Error::invalid("minmax.epipole_radius", self.epipole_radius, "must be at most 4096"));
        }
        if !(1..=1024).contains(&self.light_steps) {
            return Err(Error::invalid("minmax.light_steps", self.light_steps, "must be in 1..=1024"));
        }
        if !(self.max_projective_angle > 0.0 && self.max_projective_angle < 180.0) {
            return Err(Error::invalid(
                "minmax.max_projective_angle",
                self.max_projective_angle,
                "must be in (0, 180) degrees",
            ));
        }
        if !(self.max_projective_depth_ratio > 1.0) {
            return Err(Error::invalid(
                "minmax.max_projective_depth_ratio",
                self.max_projective_depth_ratio,
                "must be > 1",
            ));
        }
        self.policy.validate("minmax")
    }

    /// The settings a frame runs with: these, with no epipole disc for a directional light
    /// (see `epipole_radius`).
    pub fn for_frame(&self, desc: &crate::frame::FrameDesc) -> MinmaxSettings {
        let directional = desc.lights.first().is_some_and(|l| matches!(l.light, crate::Light::Directional { .. }));
        MinmaxSettings { epipole_radius: if directional { 0 } else { self.epipole_radius }, ..self.clone() }
    }

    /// The levels the tree has for these settings: `levels`, at most log2(columns).
    pub fn tree_levels(&self) -> u32 {
        self.levels.min(self.map_size[0].trailing_zeros())
    }

    /// The settings of the rectified map as `prefiltered` builds it (one band, one region: the
    /// rectification, the epipole disc and the local-light quadrature are shared).
    pub fn rectified(&self) -> PrefilteredSettings {
        PrefilteredSettings {
            map_size: self.map_size,
            rectification: self.rectification,
            max_projective_angle: self.max_projective_angle,
            max_projective_depth_ratio: self.max_projective_depth_ratio,
            regions: 1,
            bands: 1,
            epipole_radius: self.epipole_radius,
            epipole_steps: self.epipole_steps,
            light_steps: self.light_steps,
            policy: self.policy,
            ..PrefilteredSettings::default()
        }
    }

    /// What the rectification needs.
    pub fn rectify_options(&self) -> RectifyOptions {
        self.rectified().rectify_options()
    }

    /// Bytes of the tree: per row 2·columns (min, max) pairs of f32 (the texels and every
    /// level above them, laid out level after level).
    pub fn tree_bytes(&self) -> u64 {
        self.map_size[1] as u64 * 2 * self.map_size[0] as u64 * 8
    }
}
