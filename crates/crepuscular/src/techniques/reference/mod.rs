//! Technique `reference`: the ground truth every other technique is measured against.
//!
//! CPU only, f64 throughout, the same shadow map as every technique (so the visibility term is
//! identical and differences measure the technique, not the shadow map). Each pixel's integral
//! L_scatt = ∫₀ˢ T(t)·σs·p(cos θ)·L_in(x_t)·V(x_t) dt (docs/MODEL.md §1) is estimated, per
//! light over its own interval, with N stratified samples, one uniformly jittered sample in each
//! stratum; the estimator Σ f(t_k)·w_k is unbiased. The strata are equal in the transmittance's
//! integral for a sun and equal in the angle seen from the light for a point or spot light (the
//! change of variables of docs/MODEL.md §9, which cancels the 1/d² falloff), so the yardstick is
//! finest where each integrand peaks. Convergence is estimated per pixel by comparing it with
//! the N/2-stratum estimator built from the even strata alone (weight 2·w_k).

use crate::error::Error;
use crate::frame::CpuFrame;
use crate::image::Image;
use crate::integrand::light_position;
use crate::march::cone_interval;
use crate::model::Light;
use crate::shaders::pcg_hash;
use crate::shadow::ShadowFilter;
use crate::stats::{PassTime, TechniqueStats};
use glam::{DMat4, DVec3, DVec4};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::sync::atomic::{AtomicU64, Ordering};

/// Settings of `reference` (`[render.reference]` in a scene file).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ReferenceSettings {
    /// Stratified samples per pixel. Error falls roughly as N^-1.5 for smooth integrands and
    /// N^-1 across shadow edges; cost is linear in N. Even, in 2..=1048576. Default 1024.
    pub steps: u32,
    /// Seed of the per-pixel stratified jitter. Default 1.
    pub seed: u32,
}

impl Default for ReferenceSettings {
    fn default() -> Self {
        Self { steps: 1024, seed: 1 }
    }
}

/// f64 evaluation of σs·p·L_in·V of one light at `p` (see `integrand::inscatter_density` for
/// the f32 twin).
struct Integrand<'a> {
    frame: &'a CpuFrame<'a>,
    light: &'a crate::FrameLight,
    shadow: &'a crate::ShadowMap,
    sigma_s: DVec3,
    sigma_t: DVec3,
    light_pos: DVec3,
    color: DVec3,
    shadow_vp: Vec<DMat4>,
    spot_axis: DVec3,
    cos_outer: f64,
    cos_inner: f64,
}

impl<'a> Integrand<'a> {
    fn new(frame: &'a CpuFrame<'a>, k: usize) -> Self {
        let d = frame.desc;
        let fl = &d.lights[k];
        let dv = |v: glam::Vec3| v.as_dvec3();
        let (color, axis, co, ci) = match &fl.light {
            Light::Directional { direction, color, intensity } => {
                (dv(*color) * *intensity as f64, dv(direction.normalize()), 0.0, 0.0)
            }
            Light::Spot { direction, color, intensity, outer_angle_degrees, inner_angle_degrees, .. } => (
                dv(*color) * *intensity as f64,
                dv(direction.normalize()),
                (*outer_angle_degrees as f64).to_radians().cos(),
                (*inner_angle_degrees as f64).to_radians().cos(),
            ),
            Light::Point { color, intensity, .. } => (dv(*color) * *intensity as f64, DVec3::ZERO, 0.0, 0.0),
        };
        Self {
            frame,
            light: fl,
            shadow: &frame.shadow_maps[k],
            sigma_s: dv(d.medium.scattering),
            sigma_t: dv(d.medium.extinction()),
            light_pos: dv(light_position(&fl.light)),
            color: color * fl.scattering as f64,
            shadow_vp: fl.shadow.view_proj.iter().map(|m| m.as_dmat4()).collect(),
            spot_axis: axis,
            cos_outer: co,
            cos_inner: ci,
        }
    }

    fn visibility(&self, p: DVec3) -> f64 {
        let sm = self.shadow;
        let pr = &sm.projection;
        let layer = if pr.layers == 6 { crate::shadow::cube_face((p - self.light_pos).as_vec3()) } else { 0 };
        let c = self.shadow_vp[layer as usize] * DVec4::new(p.x, p.y, p.z, 1.0);
        if c.w <= 0.0 {
            return 1.0;
        }
        let ndc = c.truncate() / c.w;
        if ndc.x.abs() > 1.0 || ndc.y.abs() > 1.0 {
            return 1.0;
        }
        // shadow.rs ShadowMap::clip_coord: lit nearer the light than the near plane, tested at
        // the far plane beyond it.
        let reversed = pr.depth == crate::camera::DepthConvention::Reversed;
        let from_near = if reversed { 1.0 - ndc.z } else { ndc.z };
        if from_near < 0.0 {
            return 1.0;
        }
        let nz = if from_near > 1.0 { pr.depth.far_value() as f64 } else { ndc.z };
        let n = pr.size as f64;
        let (u, v) = (ndc.x * 0.5 + 0.5, 0.5 - ndc.y * 0.5);
        let z = pr.linear_f64(nz);
        let bias = self.light.shadow_bias as f64;
        let lit = |x: u32, y: u32| if z <= pr.linear_f64(sm.texel(layer, x, y) as f64) + bias { 1.0 } else { 0.0 };
        match self.light.shadow_filter {
            ShadowFilter::Nearest => {
                let tx = (u * n).floor().min(n - 1.0) as u32;
                let ty = (v * n).floor().min(n - 1.0) as u32;
                lit(tx, ty)
            }
            // The 2×2 percentage-closer filter of shadow.rs ShadowMap::visibility, in f64.
            ShadowFilter::Bilinear => {
                let (x, y) = (u * n - 0.5, v * n - 0.5);
                let (x0, y0) = (x.floor(), y.floor());
                let (wx, wy) = (x - x0, y - y0);
                let hi = pr.size as i64 - 1;
                let c = |i: f64| (i as i64).clamp(0, hi) as u32;
                let (i0, j0, i1, j1) = (c(x0), c(y0), c(x0 + 1.0), c(y0 + 1.0));
                let top = lit(i0, j0) + (lit(i1, j0) - lit(i0, j0)) * wx;
                let bottom = lit(i0, j1) + (lit(i1, j1) - lit(i0, j1)) * wx;
                top + (bottom - top) * wy
            }
        }
    }

    fn density(&self, view_dir: DVec3, p: DVec3) -> DVec3 {
        let d = self.frame.desc;
        let (l_in, wl) = match &self.light.light {
            Light::Directional { .. } => (self.color, self.spot_axis),
            Light::Point { .. } | Light::Spot { .. } => {
                let v = p - self.light_pos;
                let d2 = v.length_squared().max(1e-16);
                let dist = d2.sqrt();
                let wl = v / dist;
                let att = (-self.sigma_t * dist).exp() / d2;
                let mut l = self.color * att;
                if let Light::Spot { texture, .. } = &self.light.light {
                    let c = wl.dot(self.spot_axis);
                    let t = ((c - self.cos_outer) / (self.cos_inner - self.cos_outer).max(1e-12)).clamp(0.0, 1.0);
                    l *= t * t * (3.0 - 2.0 * t);
                    if let Some(tex) = texture {
                        let h = self.shadow_vp[0] * DVec4::new(p.x, p.y, p.z, 1.0);
                        if h.w > 0.0 {
                            let (u, v) = (h.x / h.w * 0.5 + 0.5, 0.5 - h.y / h.w * 0.5);
                            l *= tex.sample(u as f32, v as f32).as_dvec3();
                        }
                    }
                }
                (l, wl)
            }
        };
        if l_in == DVec3::ZERO {
            return DVec3::ZERO;
        }
        let v = self.visibility(p);
        if v == 0.0 {
            return DVec3::ZERO;
        }
        let ph = d.medium.phase.eval_f64(-wl.dot(view_dir));
        self.sigma_s * DVec3::from(ph) * l_in * v
    }
}

/// Where the N strata of one light's interval [t_lo, t_hi] lie on a view ray, and what each
/// sample weighs (its stratum's length over its density, so Σ f(t_k)·w_k is unbiased).
enum Strata {
    /// Equal in the transmittance's integral: t = t_lo − ln(1 − ξ·(1 − e^(−σ̄·len)))/σ̄ with
    /// density σ̄·e^(−σ̄(t − t_lo))/(1 − e^(−σ̄·len)) (σ̄ the mean extinction of the three
    /// channels), so a dense medium's first few centimetres get the samples they need. A sun's
    /// integrand varies only with the transmittance (and the shadows).
    Transmittance { t_lo: f64, sigma: f64, norm: f64 },
    /// Equal lengths, where σ̄·len is tiny.
    Uniform { t_lo: f64, len: f64 },
    /// Equal in the angle seen from a local light (docs/MODEL.md §9): t = Δ + D·tan θ, θ
    /// uniform in [θ_lo, θ_hi], density D/((θ_hi − θ_lo)·d²) with d² = D² + (t − Δ)², so the
    /// 1/d² falloff of a point or spot light's radiance cancels in f/density and a lamp next
    /// to the ray gets strata as fine as its peak. Δ is the light's foot on the ray, D its
    /// distance from the ray.
    Equiangular { foot: f64, dist: f64, theta_lo: f64, theta_span: f64 },
}

impl Strata {
    fn new(integrand: &Integrand, eye: DVec3, dir: DVec3, (t_lo, t_hi): (f64, f64), sigma_mean: f64) -> Self {
        let len = (t_hi - t_lo).max(0.0);
        if !matches!(integrand.light.light, Light::Directional { .. }) {
            let v = integrand.light_pos - eye;
            let foot = v.dot(dir);
            let dist = (v - dir * foot).length();
            // A light on the ray (to f64 rounding at its distance) has a non-integrable peak
            // there; keep the transmittance strata rather than divide by D ≈ 0.
            if dist > 1e-9 * v.length().max(1.0) {
                let theta_lo = ((t_lo - foot) / dist).atan();
                let theta_hi = ((t_hi - foot) / dist).atan();
                return Self::Equiangular { foot, dist, theta_lo, theta_span: theta_hi - theta_lo };
            }
        }
        if sigma_mean * len > 1e-3 {
            Self::Transmittance { t_lo, sigma: sigma_mean, norm: -(-sigma_mean * len).exp_m1() }
        } else {
            Self::Uniform { t_lo, len }
        }
    }

    /// The sample at the fraction ξ ∈ [0, 1) of the strata's measure, and its weight with `n`
    /// strata in all.
    fn sample(&self, xi: f64, n: u32) -> (f64, f64) {
        let n = n as f64;
        match *self {
            Self::Transmittance { t_lo, sigma, norm } => {
                let dt = -(-xi * norm).ln_1p() / sigma;
                (t_lo + dt, norm / (sigma * (-sigma * dt).exp() * n))
            }
            Self::Uniform { t_lo, len } => (t_lo + xi * len, len / n),
            Self::Equiangular { foot, dist, theta_lo, theta_span } => {
                let tan = (theta_lo + xi * theta_span).tan();
                (foot + dist * tan, theta_span * dist * (1.0 + tan * tan) / n)
            }
        }
    }
}

impl ReferenceSettings {
    /// Checks the ranges.
    pub fn validate(&self) -> Result<(), Error> {
        if self.steps < 2 || self.steps % 2 != 0 || self.steps > 1 << 20 {
            return Err(Error::invalid("reference.steps", self.steps, "must be even and in 2..=1048576"));
        }
        Ok(())
    }
}

/// Renders the reference. `progress(rows_done, rows_total)` is called as rows finish.
pub fn render(
    frame: &CpuFrame,
    settings: &ReferenceSettings,
    progress: &(dyn Fn(u64, u64) + Sync),
) -> Result<(Image, TechniqueStats), Error> {
    settings.validate()?;
    let desc = frame.desc;
    let start = std::time::Instant::now();
    // Every light that reaches the view, each integrated over its own interval of the ray
    // (docs/MODEL.md §6): L_scatt = Σ_k ∫ T·σs·p_k·L_in,k·V_k dt.
    let lights = crate::march::MarchLights::of(desc);
    let integrands: Vec<Integrand> = lights.indices.iter().map(|&k| Integrand::new(frame, k)).collect();
    let eye = desc.camera.position.as_dvec3();
    let fwd = desc.camera.forward().as_dvec3();
    let n = settings.steps;
    let sigma_mean = {
        let st = desc.medium.extinction().as_dvec3();
        (st.x + st.y + st.z) / 3.0
    };
    let done = AtomicU64::new(0);
    let w = desc.width as usize;
    // Per row: (pixels, sum of per-pixel relative half-vs-full change, count, max change).
    let rows: Vec<(Vec<[f32; 4]>, f64, u64, f64)> = (0..desc.height)
        .into_par_iter()
        .map(|y| {
            let mut row = Vec::with_capacity(w);
            let (mut sum_rel, mut count, mut max_rel) = (0.0, 0u64, 0.0f64);
            for x in 0..desc.width {
                let ndc_x = (x as f64 + 0.5) / desc.width as f64 * 2.0 - 1.0;
                let ndc_y = 1.0 - (y as f64 + 0.5) / desc.height as f64 * 2.0;
                let dir = desc.camera.ndc_ray_f64(glam::DVec2::new(ndc_x, ndc_y));
                let lin = desc.camera.view_depth_f64(frame.depth[y as usize * w + x as usize] as f64);
                let s = lin / dir.dot(fwd).max(1e-4);
                let (mut full, mut even) = (DVec3::ZERO, DVec3::ZERO);
                let mut rng = pcg_hash(x ^ pcg_hash(y ^ pcg_hash(settings.seed)));
                for (integrand, (cone, reach)) in integrands.iter().zip(lights.cones.iter().zip(&lights.reaches)) {
                    let reach = reach.map(|(c, r)| (c.as_dvec3(), r as f64));
                    // The light is zero outside a spot's cone: integrate only the ray's chord inside
                    // it (march.rs, exact-cone), widened by a margin against f32 rounding.
                    let (t_lo, t_hi) = match cone {
                        None => (0.0, s),
                        Some(c) => match cone_interval(c, eye.as_vec3(), dir.as_vec3(), s as f32) {
                            None => (0.0, 0.0),
                            Some((a, b)) => {
                                let m = 1e-3 * (b - a) as f64 + 1e-4;
                                ((a as f64 - m).max(0.0), (b as f64 + m).min(s))
                            }
                        },
                    };
                    // A local light's reach (march.rs light_reach): beyond it the light has crossed
                    // more than 13.8 optical depths in every channel.
                    let (t_lo, t_hi) = match reach {
                        Some((c, r)) if t_hi > t_lo => {
                            let v = eye - c;
                            let b = dir.dot(v);
                            let disc = b * b - (v.dot(v) - r * r);
                            if disc < 0.0 {
                                (0.0, 0.0)
                            } else {
                                (t_lo.max(-b - disc.sqrt()), t_hi.min(-b + disc.sqrt()))
                            }
                        }
                        _ => (t_lo, t_hi),
                    };
                    let len = (t_hi - t_lo).max(0.0);
                    let strata = Strata::new(integrand, eye, dir, (t_lo, t_hi), sigma_mean);
                    if len <= 0.0 {
                        rng = pcg_hash(rng); // the draw an empty interval has always consumed
                        continue;
                    }
                    for k in 0..n {
                        rng = pcg_hash(rng);
                        let u = (rng >> 8) as f64 / 16777216.0;
                        let (t, w) = strata.sample((k as f64 + u) / n as f64, n);
                        let f = integrand.density(dir, eye + dir * t) * (-integrand.sigma_t * t).exp();
                        full += f * w;
                        if k % 2 == 0 {
                            even += f * 2.0 * w;
                        }
                    }
                }
                let mag = full.max_element();
                if mag > 1e-6 {
                    let rel = (full - even).abs().max_element() / mag;
                    sum_rel += rel;
                    count += 1;
                    max_rel = max_rel.max(rel);
                }
                row.push([full.x as f32, full.y as f32, full.z as f32, 1.0]);
            }
            progress(done.fetch_add(1, Ordering::Relaxed) + 1, desc.height as u64);
            (row, sum_rel, count, max_rel)
        })
        .collect();
    let mut img = Image::new(desc.width, desc.height);
    img.pixels.clear();
    let (mut sum_rel, mut count, mut max_rel) = (0.0, 0u64, 0.0f64);
    for (row, s, c, m) in rows {
        img.pixels.extend(row);
        sum_rel += s;
        count += c;
        max_rel = max_rel.max(m);
    }
    let mut extra = std::collections::BTreeMap::new();
    extra.insert("steps".into(), n as f64);
    extra.insert(
        "convergence_mean_rel_change_half_vs_full".into(),
        if count > 0 { sum_rel / count as f64 } else { 0.0 },
    );
    extra.insert("convergence_max_rel_change_half_vs_full".into(), max_rel);
    let stats = TechniqueStats {
        technique: "reference".into(),
        backend: "cpu".into(),
        timing: "wall-clock".into(),
        passes: vec![PassTime { name: "integrate".into(), ms: start.elapsed().as_secs_f64() * 1e3 }],
        raymarched_samples: desc.width as u64 * desc.height as u64 * n as u64,
        gpu_memory_bytes: 0,
        extra,
    };
    Ok((img, stats))
}

impl crate::techniques::Technique for ReferenceSettings {
    const INFO: crate::techniques::TechniqueInfo = crate::techniques::TechniqueInfo {
        name: "reference",
        summary: "ground truth: f64, many stratified steps per pixel over the same shadow map, with a convergence estimate (CPU only)",
        paper: "the integral itself (docs/MODEL.md)",
        gpu: false,
        cpu: true,
        per_light: false,
    };
    fn validate(&self) -> Result<(), Error> {
        ReferenceSettings::validate(self)
    }
    fn render_cpu(
        &self,
        frame: &crate::CpuFrame,
        _rectified: Option<&[f32]>,
        progress: &(dyn Fn(u64, u64) + Sync),
    ) -> Result<(crate::Image, TechniqueStats), Error> {
        render(frame, self, progress)
    }
}
