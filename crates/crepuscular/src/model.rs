//! The physical model shared by every technique (docs/MODEL.md §1): camera, medium, phase
//! functions and lights. Everything here is plain data plus the closed-form pieces of the
//! single-scattering integral; the GPU mirrors these functions in `shaders/common.wgsl`
//! under the same names.

use glam::{Mat4, Vec3};
use serde::{Deserialize, Serialize};
use std::f32::consts::PI;

/// A pinhole camera. World space is right-handed with +Y up; clip-space depth is in [0, 1]
/// (wgpu / WebGPU convention), 0 at `near`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Camera {
    /// Eye position, world units (metres).
    pub position: Vec3,
    /// Point the camera looks at, world units.
    pub look_at: Vec3,
    /// Up vector; need not be orthogonal to the view direction. Default +Y.
    pub up: Vec3,
    /// Vertical field of view, degrees. Default 60.
    pub fov_y_degrees: f32,
    /// Near plane distance along the view axis, world units. Default 0.1.
    pub near: f32,
    /// Far plane distance along the view axis, world units; rays that hit nothing end here
    /// (the in-scattering integral runs to the far plane). Default 200.
    pub far: f32,
}

impl Default for Camera {
    fn default() -> Self {
        Self {
            position: Vec3::new(0.0, 1.0, 5.0),
            look_at: Vec3::ZERO,
            up: Vec3::Y,
            fov_y_degrees: 60.0,
            near: 0.1,
            far: 200.0,
        }
    }
}

impl Camera {
    /// Checks what the matrices need: finite position, look-at point and up; the look-at point
    /// away from the eye; `fov_y_degrees` in (0, 180); 0 < `near` < `far`, both finite. The
    /// error names the field (`camera.near`, …) and its value. (An `up` parallel to the view
    /// is not an error here: [`Camera::effective_up`] replaces it.)
    pub fn validate(&self) -> Result<(), crate::Error> {
        use crate::Error;
        let vec = |v: Vec3| format!("[{}, {}, {}]", v.x, v.y, v.z);
        for (key, v) in [("camera.position", self.position), ("camera.look_at", self.look_at), ("camera.up", self.up)] {
            if !v.is_finite() {
                return Err(Error::invalid(key, vec(v), "must be finite"));
            }
        }
        if (self.look_at - self.position).length() <= 1e-6 * (1.0 + self.position.length()) {
            return Err(Error::invalid("camera.look_at", vec(self.look_at), "must differ from camera.position"));
        }
        if !(self.fov_y_degrees > 0.0 && self.fov_y_degrees < 180.0) {
            return Err(Error::invalid("camera.fov_y_degrees", self.fov_y_degrees, "must be in (0, 180) degrees"));
        }
        if !(self.near.is_finite() && self.near > 0.0) {
            return Err(Error::invalid("camera.near", self.near, "must be a finite number > 0"));
        }
        if !(self.far.is_finite() && self.far > self.near) {
            return Err(Error::invalid(
                "camera.far",
                self.far,
                format!("must be finite and > camera.near ({})", self.near),
            ));
        }
        Ok(())
    }
    /// Unit view direction.
    pub fn forward(&self) -> Vec3 {
        (self.look_at - self.position).normalize()
    }
    /// The up vector the view matrix uses: `up`, or — when `up` is (nearly) parallel to the view
    /// direction (looking straight up or down), zero or not finite — the world axis least
    /// aligned with the view direction, so the matrices never hold NaN.
    pub fn effective_up(&self) -> Vec3 {
        let f = self.forward();
        if self.up.is_finite() && f.cross(self.up.normalize_or_zero()).length() > 1e-4 {
            return self.up;
        }
        if f.x.abs() < 0.9 { Vec3::X.cross(f).normalize() } else { Vec3::Z.cross(f).normalize() }
    }
    /// World → view matrix.
    pub fn view(&self) -> Mat4 {
        Mat4::look_at_rh(self.position, self.look_at, self.effective_up())
    }
    /// View → clip matrix for an image of the given aspect (width / height); depth in [0, 1].
    pub fn projection(&self, aspect: f32) -> Mat4 {
        Mat4::perspective_rh(self.fov_y_degrees.to_radians(), aspect, self.near, self.far)
    }
    /// World → clip.
    pub fn view_projection(&self, aspect: f32) -> Mat4 {
        self.projection(aspect) * self.view()
    }
    /// The eight world-space corners of the frustum slice between view depths `d0` and `d1`.
    pub fn frustum_corners(&self, aspect: f32, d0: f32, d1: f32) -> [Vec3; 8] {
        let f = self.forward();
        let r = f.cross(self.effective_up()).normalize();
        let u = r.cross(f);
        let ty = (self.fov_y_degrees.to_radians() * 0.5).tan();
        let tx = ty * aspect;
        let mut out = [Vec3::ZERO; 8];
        for (k, d) in [d0, d1].into_iter().enumerate() {
            for (j, (sx, sy)) in [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)].into_iter().enumerate() {
                out[k * 4 + j] = self.position + f * d + r * (sx * tx * d) + u * (sy * ty * d);
            }
        }
        out
    }
}

/// Linear view depth (distance along the view axis) from a [0, 1] perspective depth-buffer
/// value, for `Mat4::perspective_rh`. Mirrors `linear_depth` in common.wgsl.
pub fn linear_depth(d: f32, near: f32, far: f32) -> f32 {
    near * far / (far - d * (far - near))
}

/// A phase function p(cos θ), normalised to integrate to 1 over the sphere.
/// θ is the scattering angle: 0 when looking straight into the light (docs/MODEL.md §1).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "kebab-case", deny_unknown_fields)]
pub enum Phase {
    /// p = 1 / (4π).
    Isotropic,
    /// Henyey–Greenstein: p = (1 − g²) / (4π (1 + g² − 2g cos θ)^{3/2}).
    HenyeyGreenstein {
        /// Asymmetry in (−1, 1); > 0 scatters forward (bright halo around the sun). Default 0.7.
        #[serde(default = "default_g")]
        g: f32,
    },
    /// Rayleigh: p = 3 / (16π) (1 + cos² θ).
    Rayleigh,
    /// Hoffman & Preetham 2002: a per-channel mix of Rayleigh and Mie (Mie through
    /// Henyey–Greenstein with asymmetry `g`): p_c = f_c·p_R + (1 − f_c)·p_HG.
    HoffmanPreetham {
        /// Mie asymmetry in (−1, 1). Default 0.76.
        #[serde(default = "default_mie_g")]
        g: f32,
        /// Fraction f of the scattering coefficient that is Rayleigh, per RGB channel, in [0, 1].
        /// Default (0.216, 0.391, 0.612): β_R = (5.8, 13.5, 33.1)·10⁻⁶ m⁻¹ against β_M = 21·10⁻⁶ m⁻¹.
        #[serde(default = "default_rayleigh_fraction")]
        rayleigh_fraction: Vec3,
    },
}

fn default_g() -> f32 {
    0.7
}
fn default_mie_g() -> f32 {
    0.76
}
fn default_rayleigh_fraction() -> Vec3 {
    Vec3::new(5.8 / 26.8, 13.5 / 34.5, 33.1 / 54.1)
}

impl Default for Phase {
    fn default() -> Self {
        Phase::HenyeyGreenstein { g: 0.7 }
    }
}

/// Henyey–Greenstein phase function.
pub fn phase_hg(cos_theta: f32, g: f32) -> f32 {
    let denom = (1.0 + g * g - 2.0 * g * cos_theta).max(1e-6);
    (1.0 - g * g) / (4.0 * PI * denom * denom.sqrt())
}

/// Rayleigh phase function.
pub fn phase_rayleigh(cos_theta: f32) -> f32 {
    3.0 / (16.0 * PI) * (1.0 + cos_theta * cos_theta)
}

impl Phase {
    /// p(cos θ) per RGB channel (only Hoffman–Preetham differs between channels).
    /// Mirrors `phase` in common.wgsl.
    pub fn eval(&self, cos_theta: f32) -> Vec3 {
        match *self {
            Phase::Isotropic => Vec3::splat(1.0 / (4.0 * PI)),
            Phase::HenyeyGreenstein { g } => Vec3::splat(phase_hg(cos_theta, g)),
            Phase::Rayleigh => Vec3::splat(phase_rayleigh(cos_theta)),
            Phase::HoffmanPreetham { g, rayleigh_fraction: f } => {
                f * phase_rayleigh(cos_theta) + (Vec3::ONE - f) * phase_hg(cos_theta, g)
            }
        }
    }
    /// f64 evaluation for the reference.
    pub fn eval_f64(&self, c: f64) -> [f64; 3] {
        use std::f64::consts::PI;
        let hg = |g: f64| {
            let d = (1.0 + g * g - 2.0 * g * c).max(1e-12);
            (1.0 - g * g) / (4.0 * PI * d * d.sqrt())
        };
        let ray = 3.0 / (16.0 * PI) * (1.0 + c * c);
        match *self {
            Phase::Isotropic => [1.0 / (4.0 * PI); 3],
            Phase::HenyeyGreenstein { g } => [hg(g as f64); 3],
            Phase::Rayleigh => [ray; 3],
            Phase::HoffmanPreetham { g, rayleigh_fraction: f } => {
                let m = hg(g as f64);
                let f = [f.x as f64, f.y as f64, f.z as f64];
                [0, 1, 2].map(|i| f[i] * ray + (1.0 - f[i]) * m)
            }
        }
    }
    /// Code and parameters as the GPU sees them: (kind, g, rayleigh fraction).
    pub fn gpu_params(&self) -> (u32, f32, Vec3) {
        match *self {
            Phase::Isotropic => (crate::frame::PHASE_ISOTROPIC, 0.0, Vec3::ZERO),
            Phase::HenyeyGreenstein { g } => (crate::frame::PHASE_HENYEY_GREENSTEIN, g, Vec3::ZERO),
            Phase::Rayleigh => (crate::frame::PHASE_RAYLEIGH, 0.0, Vec3::ONE),
            Phase::HoffmanPreetham { g, rayleigh_fraction } => {
                (crate::frame::PHASE_HOFFMAN_PREETHAM, g, rayleigh_fraction)
            }
        }
    }
}

/// A homogeneous participating medium (docs/MODEL.md §1). Coefficients are per world unit
/// (metre) and per RGB channel; σt = σs + σa.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Medium {
    /// Scattering coefficient σs, m⁻¹, RGB, ≥ 0. Default 0.02 (light fog).
    pub scattering: Vec3,
    /// Absorption coefficient σa, m⁻¹, RGB, ≥ 0. Default 0.005.
    pub absorption: Vec3,
    /// Phase function. Default Henyey–Greenstein, g = 0.7.
    pub phase: Phase,
}

impl Default for Medium {
    fn default() -> Self {
        Self { scattering: Vec3::splat(0.02), absorption: Vec3::splat(0.005), phase: Phase::default() }
    }
}

/// `v` as `[x, y, z]` for an error message.
fn vec3_text(v: Vec3) -> String {
    format!("[{}, {}, {}]", v.x, v.y, v.z)
}

/// Checks a finite RGB value ≥ 0 per channel (`key` names it in the error).
fn check_rgb(key: &str, v: Vec3) -> Result<(), crate::Error> {
    if !(v.is_finite() && v.min_element() >= 0.0) {
        return Err(crate::Error::invalid(key, vec3_text(v), "must be finite and ≥ 0 in every channel"));
    }
    Ok(())
}

/// Checks a finite unit-able direction (`key` names it in the error).
fn check_direction(key: &str, v: Vec3) -> Result<(), crate::Error> {
    if !(v.is_finite() && v.length() > 1e-12) {
        return Err(crate::Error::invalid(key, vec3_text(v), "must be finite and non-zero"));
    }
    Ok(())
}

impl Medium {
    /// Checks the coefficients (finite, ≥ 0 per channel) and the phase function's parameters
    /// (asymmetry in (−1, 1), Rayleigh fractions in [0, 1]); the error names the field
    /// (`medium.scattering`, …) and its value.
    pub fn validate(&self) -> Result<(), crate::Error> {
        check_rgb("medium.scattering", self.scattering)?;
        check_rgb("medium.absorption", self.absorption)?;
        let g_ok = |g: f32| g.is_finite() && g > -1.0 && g < 1.0;
        match self.phase {
            Phase::HenyeyGreenstein { g } | Phase::HoffmanPreetham { g, .. } if !g_ok(g) => {
                Err(crate::Error::invalid("medium.phase.g", g, "must be in (−1, 1)"))
            }
            Phase::HoffmanPreetham { rayleigh_fraction: f, .. }
                if !(f.is_finite() && f.min_element() >= 0.0 && f.max_element() <= 1.0) =>
            {
                Err(crate::Error::invalid("medium.phase.rayleigh_fraction", vec3_text(f), "must be in [0, 1]"))
            }
            _ => Ok(()),
        }
    }

    /// Extinction σt = σs + σa.
    pub fn extinction(&self) -> Vec3 {
        self.scattering + self.absorption
    }
    /// Transmittance T(t) = exp(−σt·t).
    pub fn transmittance(&self, t: f32) -> Vec3 {
        (-self.extinction() * t).exp()
    }
}

/// ∫₀^Δ exp(−σt·t) dt = (1 − exp(−σt·Δ)) / σt, per channel, stable as σt → 0.
/// Mirrors `segment_transmittance` in common.wgsl.
pub fn segment_transmittance(sigma_t: Vec3, delta: f32) -> Vec3 {
    let f = |s: f32| {
        let x = s * delta;
        if x < 1e-4 { delta * (1.0 - 0.5 * x) } else { (1.0 - (-x).exp()) / s }
    };
    Vec3::new(f(sigma_t.x), f(sigma_t.y), f(sigma_t.z))
}

/// (c₁, c₂) of the quadratic q(r) = v₀ + c₁·r + c₂·r² on r ∈ [0, 1] through `v` = [q(0),
/// q(½), q(1)]; both exactly 0 where the three values are equal. Mirrors `ramp_coefficients`
/// in walk.wgsl.
pub fn ramp_coefficients(v: [f32; 3]) -> (f32, f32) {
    let [v0, vm, v1] = v;
    (4.0 * (vm - v0) - (v1 - v0), 2.0 * (v1 - v0) - 4.0 * (vm - v0))
}

/// ∫₀^Δ q(t)·exp(−σt·t) dt, per channel, for the quadratic q through `v` = [q(0), q(Δ/2), q(Δ)]:
/// the transmittance integral of a visibility that ramps along the span (`minmax`'s mixed texels
/// under the bilinear shadow filter, docs/MODEL.md §8). With r = t/Δ, q = v₀ + c₁·r + c₂·r² and
/// the integral is Δ·(v₀·J₀ + c₁·J₁ + c₂·J₂), J_k(x) = ∫₀¹ r^k·e^(−x·r) dr at x = σt·Δ: by its
/// power series below x = 1 (ten terms, stable as σt → 0), in closed form above. A constant q
/// (all three equal) gives v₀·[`segment_transmittance`] exactly. Mirrors `ramp_transmittance`
/// in walk.wgsl.
pub fn ramp_transmittance(sigma_t: Vec3, delta: f32, v: [f32; 3]) -> Vec3 {
    let [v0, ..] = v;
    let (c1, c2) = ramp_coefficients(v);
    let base = segment_transmittance(sigma_t, delta) * v0;
    if c1 == 0.0 && c2 == 0.0 {
        return base;
    }
    let f = |s: f32| {
        let x = s * delta;
        let (j1, j2) = if x < 1.0 {
            let (mut j1, mut j2, mut term) = (0.0f32, 0.0f32, 1.0f32);
            for m in 0..10 {
                j1 += term / (m as f32 + 2.0);
                j2 += term / (m as f32 + 3.0);
                term *= -x / (m as f32 + 1.0);
            }
            (j1, j2)
        } else {
            let e = (-x).exp();
            ((1.0 - e * (1.0 + x)) / (x * x), (2.0 - e * (2.0 + x * (2.0 + x))) / (x * x * x))
        };
        delta * (c1 * j1 + c2 * j2)
    };
    base + Vec3::new(f(sigma_t.x), f(sigma_t.y), f(sigma_t.z))
}

/// An RGB texture in linear colour, row-major from the top-left texel, used as a spot light's
/// projected "gobo" (stained glass).
#[derive(Clone, Debug, PartialEq)]
pub struct RgbTexture {
    /// Width in texels.
    pub width: u32,
    /// Height in texels.
    pub height: u32,
    /// Linear RGBA texels (alpha ignored), `width * height` of them.
    pub texels: Vec<[f32; 4]>,
}

impl RgbTexture {
    /// Bilinear lookup with clamp-to-edge at uv in [0, 1]² (v down), texel centres at
    /// (i + 0.5) / width. Mirrors `sample_spot_texture` in common.wgsl, which uses four
    /// `textureLoad`s so that both sides filter bit-for-bit alike.
    pub fn sample(&self, u: f32, v: f32) -> Vec3 {
        let x = u * self.width as f32 - 0.5;
        let y = v * self.height as f32 - 0.5;
        let x0 = x.floor();
        let y0 = y.floor();
        let fx = x - x0;
        let fy = y - y0;
        let w = self.width as i32;
        let h = self.height as i32;
        let at = |i: i32, j: i32| {
            let t = self.texels[(j.clamp(0, h - 1) * w + i.clamp(0, w - 1)) as usize];
            Vec3::new(t[0], t[1], t[2])
        };
        let (i, j) = (x0 as i32, y0 as i32);
        let a = at(i, j).lerp(at(i + 1, j), fx);
        let b = at(i, j + 1).lerp(at(i + 1, j + 1), fx);
        a.lerp(b, fy)
    }
}

/// A light source. A frame holds any number of them ([`crate::FrameDesc::lights`], each with
/// its shadow map); the in-scattering is the sum over the lights (docs/MODEL.md §6).
#[derive(Clone, Debug, PartialEq)]
pub enum Light {
    /// A distant light (sun). Radiance scale E = colour·intensity arrives unattenuated: no
    /// extinction along the light path (the convention of Klehm et al. 2014).
    Directional {
        /// Direction in which the light travels (from the sun towards the scene), unit length.
        direction: Vec3,
        /// Linear RGB colour.
        color: Vec3,
        /// Scale E applied to `color`.
        intensity: f32,
    },
    /// A spot light: L_in = I·tex(ω)·cone(ω)·exp(−σt·d)/d².
    Spot {
        /// Position, world units.
        position: Vec3,
        /// Axis direction (where the spot points), unit length.
        direction: Vec3,
        /// Half-angle where the cone falls to zero, degrees, in (0, 89].
        outer_angle_degrees: f32,
        /// Half-angle inside which the cone is at full strength, degrees, ≤ outer.
        inner_angle_degrees: f32,
        /// Linear RGB colour.
        color: Vec3,
        /// Intensity I (per steradian), scales `color`.
        intensity: f32,
        /// Optional projected RGB texture, mapped over the spot's square shadow frustum.
        texture: Option<std::sync::Arc<RgbTexture>>,
    },
    /// A point light: L_in = I·exp(−σt·d)/d² (Tóth & Umenhoffer's Φ/(4πd²) with I = Φ/4π),
    /// shadowed by a cube shadow map (six layers).
    Point {
        /// Position, world units.
        position: Vec3,
        /// Linear RGB colour.
        color: Vec3,
        /// Intensity I (per steradian), scales `color`.
        intensity: f32,
    },
}

impl Light {
    /// Checks the light's fields: finite positions, finite non-zero directions, colour and
    /// intensity finite and ≥ 0, a spot's outer half-angle in (0, 90) degrees and its inner one
    /// in [0, outer]. `key` (`lights[2]`) prefixes the field in the error.
    pub fn validate(&self, key: &str) -> Result<(), crate::Error> {
        let (color, intensity) = match self {
            Light::Directional { direction, color, intensity } => {
                check_direction(&format!("{key}.direction"), *direction)?;
                (color, intensity)
            }
            Light::Spot {
                position,
                direction,
                outer_angle_degrees: outer,
                inner_angle_degrees: inner,
                color,
                intensity,
                ..
            } => {
                if !position.is_finite() {
                    return Err(crate::Error::invalid(
                        format!("{key}.position"),
                        vec3_text(*position),
                        "must be finite",
                    ));
                }
                check_direction(&format!("{key}.direction"), *direction)?;
                if !(*outer > 0.0 && *outer < 90.0) {
                    return Err(crate::Error::invalid(
                        format!("{key}.outer_angle_degrees"),
                        outer,
                        "must be in (0, 90)",
                    ));
                }
                if !(*inner >= 0.0 && inner <= outer) {
                    return Err(crate::Error::invalid(
                        format!("{key}.inner_angle_degrees"),
                        inner,
                        format!("must be in [0, outer_angle_degrees = {outer}]"),
                    ));
                }
                (color, intensity)
            }
            Light::Point { position, color, intensity } => {
                if !position.is_finite() {
                    return Err(crate::Error::invalid(
                        format!("{key}.position"),
                        vec3_text(*position),
                        "must be finite",
                    ));
                }
                (color, intensity)
            }
        };
        check_rgb(&format!("{key}.color"), *color)?;
        if !(intensity.is_finite() && *intensity >= 0.0) {
            return Err(crate::Error::invalid(format!("{key}.intensity"), intensity, "must be finite and ≥ 0"));
        }
        Ok(())
    }

    /// Short name of the light kind.
    pub fn kind_name(&self) -> &'static str {
        match self {
            Light::Directional { .. } => "directional",
            Light::Spot { .. } => "spot",
            Light::Point { .. } => "point",
        }
    }
    /// Kind code shared with WGSL.
    pub fn kind_code(&self) -> u32 {
        match self {
            Light::Directional { .. } => crate::frame::LIGHT_DIRECTIONAL,
            Light::Spot { .. } => crate::frame::LIGHT_SPOT,
            Light::Point { .. } => crate::frame::LIGHT_POINT,
        }
    }
    /// colour × intensity: E of a directional light, I of a spot or point light (rgb).
    pub fn radiance_scale(&self) -> Vec3 {
        match self {
            Light::Directional { color, intensity, .. }
            | Light::Spot { color, intensity, .. }
            | Light::Point { color, intensity, .. } => *color * *intensity,
        }
    }
    /// Number of shadow-map layers this light uses (six cube faces for a point light).
    pub fn shadow_layers(&self) -> u32 {
        if matches!(self, Light::Point { .. }) { 6 } else { 1 }
    }
    /// Spot cone factor: smoothstep between the outer and inner half-angles.
    pub fn spot_cone(cos_outer: f32, cos_inner: f32, cos_a: f32) -> f32 {
        let t = ((cos_a - cos_outer) / (cos_inner - cos_outer).max(1e-6)).clamp(0.0, 1.0);
        t * t * (3.0 - 2.0 * t)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The ramp's integral against a fine midpoint rule in f64, on both sides of the series'
    /// switch (x = σt·Δ = 1), as σt → 0 and deep into the medium; a constant ramp is exactly
    /// the constant times the plain transmittance integral.
    #[test]
    fn ramp_transmittance_is_the_integral_of_its_quadratic() {
        let delta = 2.0f32;
        for st in [0.0f32, 1e-6, 0.01, 0.4999, 0.5001, 3.0, 40.0] {
            for v in [[0.0f32, 0.25, 1.0], [1.0, 0.5, 0.0], [0.2, 0.9, 0.4], [0.0, 1.0, 0.0]] {
                let [v0, vm, v1] = v.map(|x| x as f64);
                let (c1, c2) = (4.0 * vm - 3.0 * v0 - v1, 2.0 * v0 + 2.0 * v1 - 4.0 * vm);
                let n = 200_000;
                let d = delta as f64 / n as f64;
                let exact: f64 = (0..n)
                    .map(|i| {
                        let t = (i as f64 + 0.5) * d;
                        let r = t / delta as f64;
                        (v0 + c1 * r + c2 * r * r) * (-(st as f64) * t).exp() * d
                    })
                    .sum();
                let got = ramp_transmittance(Vec3::splat(st), delta, v).x as f64;
                let scale =
                    delta as f64 * (-(st as f64) * delta as f64).exp().max(1.0 / (1.0 + st as f64 * delta as f64));
                assert!((got - exact).abs() < 2e-6 * scale.max(1e-3), "σt {st}, v {v:?}: {got} against {exact}");
            }
            let c = ramp_transmittance(Vec3::splat(st), delta, [0.7; 3]);
            assert_eq!(c, segment_transmittance(Vec3::splat(st), delta) * 0.7, "σt {st}");
        }
    }

    /// ∫ p dω over the sphere by a fine midpoint rule in cos θ (p depends on θ only).
    fn integrate(p: &Phase) -> Vec3 {
        let n = 200_000;
        let mut sum = glam::DVec3::ZERO;
        for i in 0..n {
            let c = -1.0 + (i as f64 + 0.5) * 2.0 / n as f64;
            sum += glam::DVec3::from(p.eval_f64(c)) * (2.0 / n as f64) * 2.0 * std::f64::consts::PI;
        }
        sum.as_vec3()
    }

    #[test]
    fn every_phase_function_integrates_to_one() {
        let phases = [
            Phase::Isotropic,
            Phase::HenyeyGreenstein { g: 0.0 },
            Phase::HenyeyGreenstein { g: 0.7 },
            Phase::HenyeyGreenstein { g: -0.5 },
            Phase::HenyeyGreenstein { g: 0.95 },
            Phase::Rayleigh,
            Phase::HoffmanPreetham { g: 0.76, rayleigh_fraction: default_rayleigh_fraction() },
        ];
        for p in phases {
            let s = integrate(&p);
            assert!((s - Vec3::ONE).abs().max_element() < 1e-3, "{p:?} integrates to {s}");
        }
    }

    #[test]
    fn f32_and_f64_phase_agree() {
        for p in [
            Phase::HenyeyGreenstein { g: 0.7 },
            Phase::Rayleigh,
            Phase::HoffmanPreetham { g: 0.8, rayleigh_fraction: Vec3::new(0.2, 0.4, 0.6) },
        ] {
            for i in 0..=20 {
                let c = -1.0 + i as f32 * 0.1;
                let a = p.eval(c);
                let b = Vec3::from(p.eval_f64(c as f64).map(|x| x as f32));
                assert!(((a - b) / b).abs().max_element() < 1e-4, "{p:?} at {c}: {a} vs {b}");
            }
        }
    }

    #[test]
    fn segment_transmittance_matches_the_integral_and_its_limit() {
        for s in [0.0f32, 1e-7, 1e-3, 0.1, 1.0, 50.0] {
            let d = 2.0;
            let got = segment_transmittance(Vec3::splat(s), d).x as f64;
            let exact = if s == 0.0 { d as f64 } else { (1.0 - (-(s as f64) * d as f64).exp()) / s as f64 };
            assert!((got - exact).abs() / exact < 1e-5, "σt {s}: {got} vs {exact}");
        }
    }

    #[test]
    fn linear_depth_inverts_the_projection() {
        let cam = Camera::default();
        let proj = cam.projection(1.5);
        for z in [0.1f32, 0.5, 3.0, 50.0, 199.0] {
            let c = proj * glam::Vec4::new(0.0, 0.0, -z, 1.0);
            let d = c.z / c.w;
            assert!((linear_depth(d, cam.near, cam.far) - z).abs() / z < 1e-4);
        }
    }
}
