//! Shadow-map setup and lookups. One convention for every light kind: a depth texture array
//! (one layer for directional and spot lights, six cube faces for a point light), each layer
//! with its own world → clip matrix and [0, 1] depth. Lookups compare *linear* light-space
//! depths so a bias means the same distance everywhere. Mirrored by `shadow_visibility` in
//! common.wgsl.

use crate::camera::DepthConvention;
use crate::model::{Camera, Light};
use glam::{Mat4, UVec2, Vec2, Vec3, Vec4, Vec4Swizzles};
use serde::{Deserialize, Serialize};

/// World-space axis-aligned bounds of a scene's geometry.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Bounds {
    /// Minimum corner.
    pub min: Vec3,
    /// Maximum corner.
    pub max: Vec3,
}

impl Bounds {
    /// The eight corners.
    pub fn corners(&self) -> [Vec3; 8] {
        let (a, b) = (self.min, self.max);
        [
            Vec3::new(a.x, a.y, a.z),
            Vec3::new(b.x, a.y, a.z),
            Vec3::new(a.x, b.y, a.z),
            Vec3::new(b.x, b.y, a.z),
            Vec3::new(a.x, a.y, b.z),
            Vec3::new(b.x, a.y, b.z),
            Vec3::new(a.x, b.y, b.z),
            Vec3::new(b.x, b.y, b.z),
        ]
    }
    /// Centre.
    pub fn center(&self) -> Vec3 {
        0.5 * (self.min + self.max)
    }
    /// Half the diagonal.
    pub fn radius(&self) -> f32 {
        0.5 * (self.max - self.min).length()
    }
}

/// Settings of the host shadow map.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ShadowSettings {
    /// Texels per side of each shadow-map layer. Default 2048. Memory: 4 bytes per texel per
    /// layer (six layers for a point light); the cost of the shadow pass grows with it.
    pub size: u32,
    /// Constant depth bias for the volume lookups, in world units along the light's depth
    /// axis. Default 0.02. Too small → acne-like noise in the shafts; too large → light leaks
    /// at contact points.
    pub bias: f32,
    /// Normal offset for surface lookups, in shadow-map texels. Default 1.5.
    pub normal_offset_texels: f32,
    /// How the volume lookups read the map ([`ShadowFilter`]; each light's
    /// [`crate::FrameLight::shadow_filter`]). Default [`ShadowFilter::Bilinear`] (four texture
    /// reads per march sample); `Nearest` reads one.
    pub filter: ShadowFilter,
}

impl Default for ShadowSettings {
    fn default() -> Self {
        Self { size: 2048, bias: 0.02, normal_offset_texels: 1.5, filter: ShadowFilter::Bilinear }
    }
}

/// How the in-scattering reads a light's shadow map at a sample point: the visibility V of
/// docs/MODEL.md §1 ("Visibility"), for the reference and every step-by-step march
/// (brute-force, interleaved, subsampled, epipolar's stepped samples and re-marched pixels, and
/// the ray-marched epipole disc of `minmax` and `prefiltered`), and `minmax`'s walk (and
/// epipolar's `march = "minmax"`), which integrates either filter exactly in its mixed texels
/// (docs/MODEL.md §8). `prefiltered` has its own filtered visibility (Klehm et al. 2014 §3):
/// outside the epipole disc it ignores this setting.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum ShadowFilter {
    /// One texel, the one the point falls in: V is 0 or 1 (one texture read per sample).
    /// The model the papers' techniques are written for: the papers' bench presets pin it.
    Nearest,
    /// Percentage-closer, 2×2 bilinear: the four texels around the point, each tested, the
    /// results weighted by the point's bilinear position between their centres (what a
    /// comparison sampler with linear filtering returns in an engine's own lookups, Bevy's
    /// and Unreal's). V ramps across one texel instead of stepping, so a march's samples
    /// alias less on shaft edges. Cost: four texture reads per sample instead of one; for
    /// `minmax`, more mixed texels and four reads per piece of each (docs/RESULTS.md,
    /// "minmax under the bilinear filter"). Default: at every technique's defaults it reads
    /// as high as or higher than nearest against its own reference, and with the temporal
    /// stage it is what reaches 40 dB on every built-in scene (docs/RESULTS.md, "The default
    /// shadow filter is bilinear").
    #[default]
    Bilinear,
}

impl ShadowFilter {
    /// The code the shaders read (`Light::shadow_filter` in common.wgsl): 0 nearest, 1 bilinear.
    pub fn code(self) -> u32 {
        match self {
            Self::Nearest => 0,
            Self::Bilinear => 1,
        }
    }

    /// The setting's name as the scene file and the command line spell it.
    pub fn name(self) -> &'static str {
        match self {
            Self::Nearest => "nearest",
            Self::Bilinear => "bilinear",
        }
    }

    /// Parses `nearest` or `bilinear`; the error lists both.
    pub fn parse(s: &str) -> Result<Self, String> {
        match s {
            "nearest" => Ok(Self::Nearest),
            "bilinear" => Ok(Self::Bilinear),
            _ => Err(format!("unknown shadow filter {s:?}: expected \"nearest\" or \"bilinear\"")),
        }
    }
}

/// The matrices and depth ranges of a light's shadow map: everything needed to rasterize it and
/// to look it up. This is the part of the frame boundary a user's renderer fills in with its
/// own matrices if it already has a shadow map.
#[derive(Clone, Debug, PartialEq)]
pub struct ShadowProjection {
    /// World → clip per layer (only the first `layers` are used).
    pub view_proj: [Mat4; 6],
    /// Number of layers: 1, or 6 for a point light's cube faces (+X, −X, +Y, −Y, +Z, −Z).
    pub layers: u32,
    /// Near plane of the light projection, world units.
    pub near: f32,
    /// Far plane of the light projection, world units.
    pub far: f32,
    /// True for an orthographic projection (directional light): depth is linear.
    pub orthographic: bool,
    /// Texels per side.
    pub size: u32,
    /// World-space size of one texel at unit distance (perspective) or everywhere (orthographic).
    pub texel_world: f32,
    /// How the shadow map stores depth: [`DepthConvention::Standard`] (0 at `near`, 1 at `far`,
    /// cleared to 1; what [`ShadowProjection::fit`] makes) or [`DepthConvention::Reversed`]
    /// (1 at `near`, 0 at `far`, cleared to 0 — an engine's reversed-Z shadow maps, made with
    /// near and far swapped in the projection). `near` and `far` are the distances either way.
    pub depth: DepthConvention,
}

impl ShadowProjection {
    /// Checks what the lookups need: `layers` 1 or 6, finite `near` < `far` (`near` > 0 for a
    /// perspective map), `texel_world` finite and > 0, and each used layer's matrix finite and
    /// invertible. `key` (`lights[0].shadow`) prefixes the field in the error.
    pub fn validate(&self, key: &str) -> Result<(), crate::Error> {
        use crate::Error;
        if !matches!(self.layers, 1 | 6) {
            return Err(Error::invalid(format!("{key}.layers"), self.layers, "must be 1, or 6 for a cube map"));
        }
        if !(self.near.is_finite() && self.far.is_finite() && self.far > self.near) {
            return Err(Error::invalid(
                format!("{key}.far"),
                self.far,
                format!("near ({}) and far must be finite with far > near", self.near),
            ));
        }
        if !self.orthographic && self.near <= 0.0 {
            return Err(Error::invalid(format!("{key}.near"), self.near, "must be > 0 for a perspective shadow map"));
        }
        if !(self.texel_world.is_finite() && self.texel_world > 0.0) {
            return Err(Error::invalid(format!("{key}.texel_world"), self.texel_world, "must be finite and > 0"));
        }
        for (l, m) in self.view_proj.iter().take(self.layers as usize).enumerate() {
            let det = m.determinant();
            if !(m.is_finite() && det.is_finite() && det != 0.0) {
                return Err(Error::invalid(
                    format!("{key}.view_proj[{l}]"),
                    format!("determinant {det}"),
                    "must be a finite, invertible matrix",
                ));
            }
        }
        Ok(())
    }
}

/// Look-at targets and up vectors of the six cube faces, in layer order.
pub const CUBE_FACES: [(Vec3, Vec3); 6] = [
    (Vec3::X, Vec3::NEG_Y),
    (Vec3::NEG_X, Vec3::NEG_Y),
    (Vec3::Y, Vec3::Z),
    (Vec3::NEG_Y, Vec3::NEG_Z),
    (Vec3::Z, Vec3::NEG_Y),
    (Vec3::NEG_Z, Vec3::NEG_Y),
];

/// Cube face (layer) for a direction from the light: the major axis. Mirrors `cube_face` in WGSL.
pub fn cube_face(v: Vec3) -> u32 {
    let a = v.abs();
    if a.x >= a.y && a.x >= a.z {
        if v.x >= 0.0 { 0 } else { 1 }
    } else if a.y >= a.z {
        if v.y >= 0.0 { 2 } else { 3 }
    } else if v.z >= 0.0 {
        4
    } else {
        5
    }
}

/// Steps per doubling of a directional light's shadow-map sides in [`ShadowProjection::fit`]:
/// each side is rounded up to 2^(k/64) times the scene's diameter, so a map is at most 1.1 %
/// wider (its texels 1.1 % coarser) than the fit needs, and the texel grid holds still while
/// the sides keep their steps. Measured (docs/RESULTS.md, "A stable fit of the sun's shadow
/// map"): 8 steps per doubling (9 % wider) held the grid longer and gave the same gain under
/// a slow camera move, but changed single frames where a few texels decide everything (the
/// robustness sweep's dense medium: brute-force NMAE 0.25 → 0.36); 64 leave them as they were.
pub const STABLE_FIT_STEPS: f32 = 64.0;

impl ShadowProjection {
    /// Fits the shadow projection for `light`. Directional: orthographic, fitted to the part of
    /// the view frustum that holds geometry (each side rounded up to a step of
    /// [`STABLE_FIT_STEPS`], its centre snapped to whole texels, so that its texels stay put in
    /// the world as the camera moves: a stable fit), with the depth range covering every caster
    /// in `bounds`. Spot: perspective over the cone (square, full angle 2·outer). Point: six 90°
    /// faces. `aspect` is the camera image's width / height.
    pub fn fit(light: &Light, camera: &Camera, aspect: f32, bounds: Bounds, size: u32) -> Self {
        let reach = (bounds.center() - camera.position).length() + bounds.radius();
        match light {
            Light::Directional { direction, .. } => {
                let dir = direction.normalize();
                let up = if dir.y.abs() > 0.99 { Vec3::Z } else { Vec3::Y };
                let c = bounds.center();
                let r = bounds.radius().max(1e-3);
                let view = Mat4::look_at_rh(c - dir * (2.0 * r), c, up);
                let far_fit = camera.far.min(reach).max(camera.near * 2.0);
                let frustum = camera.frustum_corners(aspect, camera.near, far_fit);
                let (mut fmin, mut fmax) = (Vec3::splat(f32::MAX), Vec3::splat(f32::MIN));
                for p in frustum {
                    let q = view.transform_point3(p);
                    fmin = fmin.min(q);
                    fmax = fmax.max(q);
                }
                let (mut bmin, mut bmax) = (Vec3::splat(f32::MAX), Vec3::splat(f32::MIN));
                for p in bounds.corners() {
                    let q = view.transform_point3(p);
                    bmin = bmin.min(q);
                    bmax = bmax.max(q);
                }
                // xy: the frustum ∩ the geometry; z: every caster (view looks down −z).
                let lo = fmin.max(bmin);
                let hi = fmax.min(bmax);
                let (lo, hi) = if lo.x < hi.x && lo.y < hi.y { (lo, hi) } else { (bmin, bmax) };
                let pad = 0.01 * r;
                let near = (-bmax.z - pad).max(1e-3);
                let far = -bmin.z + pad;
                // A stable fit (docs/MODEL.md §2, "the sun's shadow map"): each side of the map is
                // the fitted extent rounded up to a step of 2^(1/64) from the scene's diameter, and
                // its centre is snapped to whole texels of the light's view, so as the camera moves
                // the texel grid stays put in the world (it changes only when a side takes another
                // step) and shadow edges do not swim from frame to frame.
                let side = |extent: f32| {
                    let steps = ((extent / (2.0 * r)).log2() * STABLE_FIT_STEPS).ceil();
                    2.0 * r * (steps / STABLE_FIT_STEPS).exp2()
                };
                let (ex, ey) = (side(hi.x - lo.x + 2.0 * pad), side(hi.y - lo.y + 2.0 * pad));
                let (tx, ty) = (ex / size as f32, ey / size as f32);
                let cx = ((lo.x + hi.x) * 0.5 / tx).round() * tx;
                let cy = ((lo.y + hi.y) * 0.5 / ty).round() * ty;
                let proj = Mat4::orthographic_rh(cx - 0.5 * ex, cx + 0.5 * ex, cy - 0.5 * ey, cy + 0.5 * ey, near, far);
                let texel = tx.max(ty);
                let m = proj * view;
                Self {
                    view_proj: [m; 6],
                    layers: 1,
                    near,
                    far,
                    orthographic: true,
                    size,
                    texel_world: texel,
                    depth: DepthConvention::Standard,
                }
            }
            Light::Spot { position, direction, outer_angle_degrees, .. } => {
                let dir = direction.normalize();
                let up = if dir.y.abs() > 0.99 { Vec3::Z } else { Vec3::Y };
                let fov = (2.0 * outer_angle_degrees.to_radians()).min(179f32.to_radians());
                let far = ((bounds.center() - *position).length() + bounds.radius()).max(1.0);
                let near = (far * 1e-3).max(0.02);
                let m = Mat4::perspective_rh(fov, 1.0, near, far) * Mat4::look_at_rh(*position, *position + dir, up);
                let texel = 2.0 * (fov * 0.5).tan() / size as f32;
                Self {
                    view_proj: [m; 6],
                    layers: 1,
                    near,
                    far,
                    orthographic: false,
                    size,
                    texel_world: texel,
                    depth: DepthConvention::Standard,
                }
            }
            Light::Point { position, .. } => {
                let far = ((bounds.center() - *position).length() + bounds.radius()).max(1.0);
                let near = (far * 1e-3).max(0.02);
                let proj = Mat4::perspective_rh(std::f32::consts::FRAC_PI_2, 1.0, near, far);
                let view_proj = CUBE_FACES.map(|(f, u)| proj * Mat4::look_at_rh(*position, *position + f, u));
                Self {
                    view_proj,
                    layers: 6,
                    near,
                    far,
                    orthographic: false,
                    size,
                    texel_world: 2.0 / size as f32,
                    depth: DepthConvention::Standard,
                }
            }
        }
    }

    /// Linear light-space depth from a [0, 1] depth value (either convention: a reversed map
    /// swaps near and far). Mirrors `shadow_linear_depth`.
    pub fn linear(&self, d: f32) -> f32 {
        let (near, far) = self.depth_range();
        if self.orthographic { near + d * (far - near) } else { crate::model::linear_depth(d, near, far) }
    }

    /// [`ShadowProjection::linear`] in f64 (the reference's precision).
    pub fn linear_f64(&self, d: f64) -> f64 {
        let (near, far) = self.depth_range();
        let (near, far) = (near as f64, far as f64);
        if self.orthographic { near + d * (far - near) } else { near * far / (far - d * (far - near)) }
    }

    /// The distances at depth 0 and depth 1: (near, far), swapped for a reversed-Z map.
    fn depth_range(&self) -> (f32, f32) {
        match self.depth {
            DepthConvention::Standard => (self.near, self.far),
            DepthConvention::Reversed => (self.far, self.near),
        }
    }

    /// True where a stored depth is the clear value (no occluder at that texel).
    pub fn is_empty(&self, d: f32) -> bool {
        match self.depth {
            DepthConvention::Standard => d >= 1.0,
            DepthConvention::Reversed => d <= 0.0,
        }
    }
}

/// A shadow map on the CPU: `layers` images of `size × size` [0, 1] depths, row-major from the
/// top-left texel (texture v = 0 at the top, as wgpu stores it).
#[derive(Clone, Debug)]
pub struct ShadowMap {
    /// The projection that produced it.
    pub projection: ShadowProjection,
    /// Depths, `layers * size * size`, cleared to 1.0 where nothing was drawn.
    pub depth: Vec<f32>,
}

/// Where a world point falls in a light's shadow map (`ShadowCoord` in common.wgsl).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ShadowCoord {
    /// The layer (0, or a cube face).
    pub layer: u32,
    /// Texture coordinates in [0, 1]², v = 0 at the top.
    pub uv: Vec2,
    /// The texel that holds `uv`.
    pub texel: UVec2,
    /// The point's linear light-space depth (world units).
    pub depth: f32,
}

impl ShadowMap {
    /// Which layer, texel and linear depth a world point falls on; None outside the map's
    /// footprint or nearer the light than its near plane; a point beyond its far plane gets
    /// the far plane's depth (docs/MODEL.md §1 "Visibility"). Mirrors `shadow_coord` in
    /// common.wgsl.
    pub fn coord(&self, light_pos: Vec3, p: Vec3) -> Option<ShadowCoord> {
        let pr = &self.projection;
        let layer = if pr.layers == 6 { cube_face(p - light_pos) } else { 0 };
        self.clip_coord(layer, pr.view_proj[layer as usize] * Vec4::new(p.x, p.y, p.z, 1.0))
    }

    /// [`ShadowMap::coord`] of a point already in layer `layer`'s clip space (`c`); None
    /// behind the light, outside the map's footprint or nearer than its near plane; beyond
    /// the far plane, the far plane's depth. Mirrors `shadow_coord_clip` in common.wgsl.
    pub fn clip_coord(&self, layer: u32, c: Vec4) -> Option<ShadowCoord> {
        let pr = &self.projection;
        if c.w <= 0.0 {
            return None;
        }
        let ndc = c.xyz() / c.w;
        if ndc.x.abs() > 1.0 || ndc.y.abs() > 1.0 {
            return None;
        }
        // Light-space depth as a fraction from the near plane (0) to the far plane (1).
        let from_near = match pr.depth {
            DepthConvention::Standard => ndc.z,
            DepthConvention::Reversed => 1.0 - ndc.z,
        };
        // Nearer the light than the near plane: nothing the map holds lies in front of it.
        if from_near < 0.0 {
            return None;
        }
        // Beyond the far plane, but inside the map's footprint: behind whatever occluder its
        // texel holds, so it is tested at the far plane — shadowed where the texel holds an
        // occluder, lit where it is empty (docs/MODEL.md §1 "Visibility"). An engine's sun
        // cascade is fitted to the view frustum's slice, whose far side (from the light) can
        // stop short of the eye: until 2026-12-05 the first centimetres of every view ray
        // facing the sun read lit there.
        let z = if from_near > 1.0 { pr.depth.far_value() } else { ndc.z };
        let n = pr.size as f32;
        let uv = Vec2::new(ndc.x * 0.5 + 0.5, 0.5 - ndc.y * 0.5);
        let texel = (uv * n).floor().min(Vec2::splat(n - 1.0)).as_uvec2();
        Some(ShadowCoord { layer, uv, texel, depth: pr.linear(z) })
    }

    /// Stored depth at a texel.
    pub fn texel(&self, layer: u32, x: u32, y: u32) -> f32 {
        let n = self.projection.size;
        self.depth[((layer * n + y) * n + x) as usize]
    }

    /// Visibility of a point from the light, in [0, 1] (1 lit, 0 shadowed), read with
    /// `filter`; points outside the map's footprint or nearer than its near plane are lit,
    /// points beyond its far plane are lit only where their texels are empty. Mirrors
    /// `shadow_visibility` in common.wgsl.
    pub fn visibility(&self, light_pos: Vec3, p: Vec3, bias: f32, filter: ShadowFilter) -> f32 {
        let Some(sc) = self.coord(light_pos, p) else {
            return 1.0;
        };
        let pr = &self.projection;
        let lit = |x: u32, y: u32| if sc.depth <= pr.linear(self.texel(sc.layer, x, y)) + bias { 1.0 } else { 0.0 };
        match filter {
            ShadowFilter::Nearest => lit(sc.texel.x, sc.texel.y),
            ShadowFilter::Bilinear => {
                let (corner, w) = bilinear_footprint(sc.uv, pr.size);
                let [x0, y0, x1, y1] = corner;
                bilinear_blend([lit(x0, y0), lit(x1, y0), lit(x0, y1), lit(x1, y1)], w)
            }
        }
    }
}

/// The bilinear blend of the 2×2 texels' tests `v` = [v00, v10, v01, v11] (in the order of
/// [`bilinear_footprint`]'s corners) at the weights `w` of x1 and y1: a + (b − a)·w along x,
/// then along y. Mirrors `bilinear_blend` in common.wgsl.
pub fn bilinear_blend(v: [f32; 4], w: Vec2) -> f32 {
    let top = v[0] + (v[1] - v[0]) * w.x;
    let bottom = v[2] + (v[3] - v[2]) * w.x;
    top + (bottom - top) * w.y
}

/// The 2×2 texels around `uv` in a `size`² map and the bilinear weights between their centres:
/// ([x0, y0, x1, y1] clamped to the map, (wx, wy) the weights of x1 and y1). Mirrors
/// `bilinear_footprint` in common.wgsl.
pub fn bilinear_footprint(uv: Vec2, size: u32) -> ([u32; 4], Vec2) {
    let x = uv * size as f32 - 0.5;
    let x0 = x.floor();
    let w = x - x0;
    let hi = size as i32 - 1;
    let (i, j) = (x0.x as i32, x0.y as i32);
    let c = |v: i32| v.clamp(0, hi) as u32;
    ([c(i), c(j), c(i + 1), c(j + 1)], w)
}

impl ShadowMap {
    /// 3×3 percentage-closer filtered visibility for a surface point with normal `n`, pushed
    /// along the normal by `normal_offset_texels` texels. Mirrors `shadow_pcf` in common.wgsl.
    pub fn visibility_pcf(&self, light_pos: Vec3, p: Vec3, n: Vec3, bias: f32, normal_offset_texels: f32) -> f32 {
        let pr = &self.projection;
        let mut texel = pr.texel_world;
        if !pr.orthographic {
            texel *= (p - light_pos).length();
        }
        let q = p + n * (normal_offset_texels * texel);
        let Some(ShadowCoord { layer, texel, depth: z, .. }) = self.coord(light_pos, q) else {
            return 1.0;
        };
        let (tx, ty) = (texel.x, texel.y);
        let size = pr.size as i32;
        let mut sum = 0.0;
        for dy in -1..=1 {
            for dx in -1..=1 {
                let x = (tx as i32 + dx).clamp(0, size - 1) as u32;
                let y = (ty as i32 + dy).clamp(0, size - 1) as u32;
                let stored = pr.linear(self.texel(layer, x, y));
                sum += if z <= stored + bias { 1.0 } else { 0.0 };
            }
        }
        sum / 9.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// An 8² orthographic map looking down −z from the origin over [−1, 1]², depth 0..10 m:
    /// its left half (columns 0..4) holds an occluder at 2 m, its right half is empty.
    fn half_map() -> ShadowMap {
        let size = 8;
        let projection = ShadowProjection {
            view_proj: [Mat4::orthographic_rh(-1.0, 1.0, -1.0, 1.0, 0.0, 10.0); 6],
            layers: 1,
            near: 0.0,
            far: 10.0,
            orthographic: true,
            size,
            texel_world: 2.0 / size as f32,
            depth: DepthConvention::Standard,
        };
        let depth = (0..size * size).map(|i| if i % size < size / 2 { 0.2 } else { 1.0 }).collect();
        ShadowMap { projection, depth }
    }

    /// The point at 5 m depth over map coordinate u (x = 2u − 1), v = 0.3 (y = 0.4).
    fn at(u: f32) -> Vec3 {
        Vec3::new(2.0 * u - 1.0, 0.4, -5.0)
    }

    #[test]
    fn bilinear_filter_ramps_across_one_texel_and_equals_nearest_at_texel_centres() {
        let m = half_map();
        let v = |u: f32, f| m.visibility(Vec3::ZERO, at(u), 0.02, f);
        // Nearest: a step at u = 0.5 (the occluder's edge).
        assert_eq!(v(0.49, ShadowFilter::Nearest), 0.0);
        assert_eq!(v(0.51, ShadowFilter::Nearest), 1.0);
        // At every texel centre the four texels' weights are (1, 0): the nearest test exactly.
        for i in 0..8 {
            let u = (i as f32 + 0.5) / 8.0;
            assert_eq!(v(u, ShadowFilter::Bilinear), v(u, ShadowFilter::Nearest), "texel {i}");
        }
        // Between the centres of columns 3 (shadowed) and 4 (lit), V = 8u − 3.5 exactly (the
        // closed form of the 2×2 filter over this step); flat outside them.
        for k in 0..=20 {
            let u = 3.5 / 8.0 + k as f32 / 20.0 / 8.0;
            let want = 8.0 * u - 3.5;
            let got = v(u, ShadowFilter::Bilinear);
            assert!((got - want).abs() < 1e-5, "u {u}: V {got}, closed form {want}");
        }
        assert_eq!(v(0.3, ShadowFilter::Bilinear), 0.0);
        assert_eq!(v(0.7, ShadowFilter::Bilinear), 1.0);
        // Half a texel from the map's border the footprint clamps to the edge texel.
        assert_eq!(v(0.01, ShadowFilter::Bilinear), 0.0);
        assert_eq!(v(0.99, ShadowFilter::Bilinear), 1.0);
        // Outside the map is lit, either way.
        assert_eq!(m.visibility(Vec3::ZERO, Vec3::new(-1.5, 0.4, -5.0), 0.02, ShadowFilter::Bilinear), 1.0);
    }

    /// Beyond the far plane a point is behind whatever its texel holds: shadowed over the
    /// occluder, lit over the empty half; nearer than the near plane it is lit. In both depth
    /// conventions and with both filters (docs/MODEL.md §1 "Visibility").
    #[test]
    fn beyond_the_far_plane_is_tested_at_it_and_before_the_near_plane_is_lit() {
        let standard = half_map();
        // The same map stored reversed: 1 at the near plane, 0 (the clear value) at the far.
        let mut reversed = half_map();
        reversed.projection.view_proj = [Mat4::orthographic_rh(-1.0, 1.0, -1.0, 1.0, 10.0, 0.0); 6];
        reversed.projection.depth = DepthConvention::Reversed;
        reversed.depth = standard.depth.iter().map(|d| 1.0 - d).collect();
        for m in [&standard, &reversed] {
            for f in [ShadowFilter::Nearest, ShadowFilter::Bilinear] {
                let v = |u: f32, depth: f32| m.visibility(Vec3::ZERO, Vec3::new(2.0 * u - 1.0, 0.4, -depth), 0.02, f);
                let conv = m.projection.depth;
                // Inside the depth range: the occluder at 2 m shadows what is behind it.
                assert_eq!(v(0.2, 5.0), 0.0, "{conv:?} {f:?}");
                assert_eq!(v(0.8, 5.0), 1.0, "{conv:?} {f:?}");
                // Beyond the far plane (10 m): tested there.
                assert_eq!(v(0.2, 10.5), 0.0, "{conv:?} {f:?}: behind the occluder");
                assert_eq!(v(0.8, 10.5), 1.0, "{conv:?} {f:?}: over an empty texel");
                assert_eq!(v(0.8, 1000.0), 1.0, "{conv:?} {f:?}: far beyond, empty texel");
                // Nearer the light than the near plane (0 m): lit, whatever the texel.
                assert_eq!(v(0.2, -0.5), 1.0, "{conv:?} {f:?}");
                let c = m.coord(Vec3::ZERO, Vec3::new(-0.6, 0.4, -10.5)).expect("inside the footprint");
                assert!((c.depth - 10.0).abs() < 1e-5, "{conv:?}: the far plane's depth, got {}", c.depth);
            }
        }
    }

    #[test]
    fn bilinear_footprint_clamps_and_weights() {
        assert_eq!(bilinear_footprint(Vec2::new(0.5, 0.5), 8), ([3, 3, 4, 4], Vec2::splat(0.5)));
        assert_eq!(bilinear_footprint(Vec2::new(0.0, 1.0), 8), ([0, 7, 0, 7], Vec2::splat(0.5)));
        let (c, w) = bilinear_footprint(Vec2::new(4.5 / 8.0, 0.25 / 8.0), 8);
        assert_eq!(c, [4, 0, 5, 0]);
        assert_eq!(w, Vec2::new(0.0, 0.75));
    }

    #[test]
    fn shadow_filter_names_round_trip() {
        for f in [ShadowFilter::Nearest, ShadowFilter::Bilinear] {
            assert_eq!(ShadowFilter::parse(f.name()), Ok(f));
        }
        assert_eq!(ShadowFilter::Nearest.code(), 0);
        assert_eq!(ShadowFilter::Bilinear.code(), 1);
        let e = ShadowFilter::parse("pcf").unwrap_err();
        assert!(e.contains("\"pcf\"") && e.contains("bilinear"), "{e}");
    }
}
