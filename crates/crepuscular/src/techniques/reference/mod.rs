//! Technique `reference`: the ground truth every other technique is measured against.
//!
//! CPU only, f64 throughout, the same shadow map as every technique (so the visibility term is
//! identical and differences measure the technique, not the shadow map). Each pixel's integral
//! L_scatt = ∫₀ˢ T(t)·σs·p(cos θ)·L_in(x_t)·V(x_t) dt (docs/MODEL.md §1) is estimated with N
//! stratified samples: stratum k covers [kΔ, (k+1)Δ], Δ = s/N, with one uniformly jittered
//! sample in it; the estimator Σ f(t_k)·Δ is unbiased. Convergence is estimated per pixel by
//! comparing it with the N/2-stratum estimator built from the even strata alone (weight 2Δ).

use crate::error::Error;
use crate::frame::CpuFrame;
use crate::image::Image;
use crate::integrand::light_position;
use crate::march::cone_interval;
use crate::model::Light;
use crate::shaders::pcg_hash;
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
        if ndc.z < 0.0 || ndc.z > 1.0 || ndc.x.abs() > 1.0 || ndc.y.abs() > 1.0 {
            return 1.0;
        }
        let n = pr.size as f64;
        let tx = ((ndc.x * 0.5 + 0.5) * n).floor().min(n - 1.0) as u32;
        let ty = ((0.5 - ndc.y * 0.5) * n).floor().min(n - 1.0) as u32;
        let stored = pr.linear_f64(sm.texel(layer, tx, ty) as f64);
        if pr.linear_f64(ndc.z) <= stored + self.light.shadow_bias as f64 { 1.0 } else { 0.0 }
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
                    // Strata in transmittance: t = t_lo − ln(1 − ξ·(1 − e^(−σ̄·len)))/σ̄ with pdf
                    // σ̄·e^(−σ̄(t − t_lo))/(1 − e^(−σ̄·len)) (σ̄ the mean extinction of the three
                    // channels), so a dense medium's first few centimetres get the samples they
                    // need; uniform strata where σ̄·len is tiny.
                    let importance = sigma_mean * len > 1e-3;
                    let norm = if importance { -(-sigma_mean * len).exp_m1() } else { 0.0 };
                    for k in 0..n {
                        rng = pcg_hash(rng);
                        let u = (rng >> 8) as f64 / 16777216.0;
                        let xi = (k as f64 + u) / n as f64;
                        let (t, w) = if importance {
                            let dt = -(-xi * norm).ln_1p() / sigma_mean;
                            (t_lo + dt, norm / (sigma_mean * (-sigma_mean * dt).exp() * n as f64))
                        } else {
                            (t_lo + xi * len, len / n as f64)
                        };
                        if len <= 0.0 {
                            break;
                        }
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
