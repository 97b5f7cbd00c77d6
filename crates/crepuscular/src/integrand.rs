//! The single-scattering integrand shared by every technique (docs/MODEL.md §1):
//! L_scatt = ∫₀ˢ T(t)·σs·p(cos θ)·L_in(x_t)·V(x_t) dt. Each function here has a WGSL twin of the
//! same name in `shaders/common.wgsl`.

use crate::frame::{CpuFrame, FrameLight};
use crate::model::{Light, Medium};
use crate::shadow::ShadowMap;
use glam::{Vec3, Vec4, Vec4Swizzles};

/// Unshadowed incident radiance at `p` and the unit direction ω_l in which that light travels
/// at `p`. Directional: E, no extinction along the light path. Spot / point:
/// I·tex·cone·exp(−σt·d)/d². The spot texture is looked up through the shadow projection
/// `spot_view_proj` (the spot's shadow frustum). [`light_incident`] scales it for scattering.
pub fn light_radiance(light: &Light, medium: &Medium, spot_view_proj: &glam::Mat4, p: Vec3) -> (Vec3, Vec3) {
    match light {
        Light::Directional { direction, color, intensity } => (*color * *intensity, direction.normalize()),
        Light::Point { position, color, intensity } => {
            let v = p - *position;
            let d2 = v.length_squared().max(1e-8);
            let d = d2.sqrt();
            let att = (-medium.extinction() * d).exp() / d2;
            (*color * *intensity * att, v / d)
        }
        Light::Spot { position, direction, outer_angle_degrees, inner_angle_degrees, color, intensity, texture } => {
            let v = p - *position;
            let d2 = v.length_squared().max(1e-8);
            let d = d2.sqrt();
            let wl = v / d;
            let cos_a = wl.dot(direction.normalize());
            let cone =
                Light::spot_cone(outer_angle_degrees.to_radians().cos(), inner_angle_degrees.to_radians().cos(), cos_a);
            if cone <= 0.0 {
                return (Vec3::ZERO, wl);
            }
            let mut tex = Vec3::ONE;
            if let Some(t) = texture {
                let c = *spot_view_proj * Vec4::new(p.x, p.y, p.z, 1.0);
                if c.w > 0.0 {
                    let ndc = c.xy() / c.w;
                    tex = t.sample(ndc.x * 0.5 + 0.5, 0.5 - ndc.y * 0.5);
                }
            }
            let att = (-medium.extinction() * d).exp() / d2;
            (*color * *intensity * cone * att * tex, wl)
        }
    }
}

/// The radiance of one light of the frame at `p` as the in-scattering sees it:
/// [`light_radiance`] × [`FrameLight::scattering`], and ω_l. Mirrors `light_incident` in WGSL
/// (whose light colour carries the scale).
pub fn light_incident(fl: &FrameLight, medium: &Medium, p: Vec3) -> (Vec3, Vec3) {
    let (l, wl) = light_radiance(&fl.light, medium, &fl.shadow.view_proj[0], p);
    (l * fl.scattering, wl)
}

/// Position of a local light (unused for directional lights).
pub fn light_position(light: &Light) -> Vec3 {
    match light {
        Light::Directional { .. } => Vec3::ZERO,
        Light::Spot { position, .. } | Light::Point { position, .. } => *position,
    }
}

/// L_in(x)·V(x)·scattering and ω_l of one light of the frame: the integrand without σs and the
/// phase function, for passes that look the phase function up in a table. Mirrors
/// `lit_incident` in WGSL (whose light colour carries [`FrameLight::scattering`]).
pub fn lit_incident(fl: &FrameLight, medium: &Medium, shadow: &ShadowMap, p: Vec3) -> (Vec3, Vec3) {
    let (l_in, wl) = light_incident(fl, medium, p);
    if l_in == Vec3::ZERO {
        return (l_in, wl);
    }
    (l_in * shadow.visibility(light_position(&fl.light), p, fl.shadow_bias, fl.shadow_filter), wl)
}

/// σs·p(cos θ)·L_in(x)·V(x) of one light at a point x on a view ray of unit direction
/// `view_dir`: the in-scattered radiance per unit length before transmittance to the eye.
/// Mirrors `inscatter_density` in WGSL.
pub fn inscatter_density(fl: &FrameLight, medium: &Medium, shadow: &ShadowMap, view_dir: Vec3, p: Vec3) -> Vec3 {
    let (l_in, wl) = lit_incident(fl, medium, shadow, p);
    if l_in == Vec3::ZERO {
        return Vec3::ZERO;
    }
    // cos θ = dot(ω_l, −ω): θ = 0 looking straight into the light (docs/MODEL.md §1).
    let cos_theta = -wl.dot(view_dir);
    medium.scattering * medium.phase.eval(cos_theta) * l_in
}

/// How a host renderer shades its surfaces — not part of the effect's frame: the
/// in-scattering never depends on it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SurfaceShading {
    /// Ambient radiance added as ambient·albedo (rgb, linear). Default 0.03.
    pub ambient: Vec3,
    /// The shadow lookup's offset along the surface normal, in shadow-map texels (against
    /// shadow acne). Default 1.5.
    pub normal_offset_texels: f32,
}

impl Default for SurfaceShading {
    fn default() -> Self {
        Self { ambient: Vec3::splat(0.03), normal_offset_texels: 1.5 }
    }
}

impl SurfaceShading {
    /// As the host's surface shader reads it (`shading` in common.wgsl's `surface_radiance`):
    /// ambient (rgb), normal offset (w).
    pub fn uniform(&self) -> [f32; 4] {
        [self.ambient.x, self.ambient.y, self.ambient.z, self.normal_offset_texels]
    }
}

/// Lambert surface radiance from every light of the frame with its shadow map, plus
/// ambient·albedo. The normal is flipped to face the camera (surfaces are double-sided).
/// [`FrameLight::scattering`] does not dim surfaces. Mirrors `surface_radiance` in common.wgsl.
pub fn surface_radiance(frame: &CpuFrame, shading: &SurfaceShading, p: Vec3, normal: Vec3, albedo: Vec3) -> Vec3 {
    let desc = frame.desc;
    let mut n = normal.normalize_or_zero();
    if n.dot(desc.camera.position - p) < 0.0 {
        n = -n;
    }
    let mut direct = Vec3::ZERO;
    for (fl, shadow) in desc.lights.iter().zip(frame.shadow_maps) {
        let (l_in, wl) = light_radiance(&fl.light, &desc.medium, &fl.shadow.view_proj[0], p);
        let cosine = n.dot(-wl).max(0.0);
        if cosine > 0.0 && l_in.max_element() > 0.0 {
            let v =
                shadow.visibility_pcf(light_position(&fl.light), p, n, fl.shadow_bias, shading.normal_offset_texels);
            direct += albedo / std::f32::consts::PI * l_in * cosine * v;
        }
    }
    direct + shading.ambient * albedo
}
