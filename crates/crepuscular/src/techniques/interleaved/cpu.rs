//! CPU mirror of `interleaved`: the same sample placement and arithmetic (f32) as march.wgsl,
//! sum_rows.wgsl and sum_columns.wgsl, function for function.

use super::{InterleavedSettings, PhaseLut};
use crate::error::Error;
use crate::frame::CpuFrame;
use crate::image::Image;
use crate::integrand::lit_incident;
use crate::march::{LightSet, MarchLights, Steps, march_light_groups, march_lights, march_samples};
use crate::shaders::pixel_jitter;
use crate::stats::{PassTime, TechniqueStats};
use glam::Vec3;
use rayon::prelude::*;
use std::time::Instant;

/// Mirrors `block_offset` in march.wgsl: k = (y mod M)·M + (x mod M) (Tóth & Umenhoffer 2009,
/// §4.1: "the N terms are distributed in them in a periodic way").
pub fn block_offset(s: &InterleavedSettings, x: u32, y: u32) -> u32 {
    s.block_offset(x, y)
}

/// Mirrors `phase_lut` in march.wgsl: linear interpolation of the table at
/// u = √((1 − σ·cos θ)/2) (§4: the phase function "stored in a lookup table").
pub fn phase_lut(lut: &PhaseLut, c: f32) -> Vec3 {
    let n = lut.size();
    let u = (0.5 - 0.5 * (lut.sign * c)).clamp(0.0, 1.0).sqrt();
    let x = u * (n - 1) as f32;
    let i0 = (x as u32).min(n - 2);
    let f = x - i0 as f32;
    let a = lut.entries[i0 as usize];
    let b = lut.entries[i0 as usize + 1];
    Vec3::new(a[0], a[1], a[2]) * (1.0 - f) + Vec3::new(b[0], b[1], b[2]) * f
}

/// Mirrors `density_lut` in march.wgsl: σs·lut(cos θ)·L_in·V of light `k` of the frame at `p`.
fn density_lut(frame: &CpuFrame, lut: &PhaseLut, k: usize, dir: Vec3, p: Vec3) -> Vec3 {
    let desc = frame.desc;
    let (l_in, wl) = lit_incident(&desc.lights[k], &desc.medium, &frame.shadow_maps[k], p);
    if l_in == Vec3::ZERO {
        return Vec3::ZERO;
    }
    desc.medium.scattering * phase_lut(lut, -wl.dot(dir)) * l_in
}

/// Mirrors `march_steps_lut` in march.wgsl: [`crate::march::march_steps`] (eq. 1 over the
/// steps i = first, first + stride, … < N of `steps`) with σs·lut(cos θ) for σs·p(cos θ).
#[allow(clippy::too_many_arguments)]
pub fn march_steps_lut(
    frame: &CpuFrame,
    lights: &MarchLights,
    which: LightSet,
    lut: &PhaseLut,
    dir: Vec3,
    steps: &Steps,
    first: u32,
    stride: u32,
    j: f32,
) -> Vec3 {
    let o = frame.desc.camera.position;
    march_samples(frame.desc, steps, first, stride, j, |t| {
        which.iter().map(|l| density_lut(frame, lut, lights.indices[l], dir, o + dir * t)).sum()
    })
    .truncate()
}

/// Mirrors `march_lights_lut` in march.wgsl: [`crate::march::march_lights`] with the phase table.
#[allow(clippy::too_many_arguments)]
fn march_lights_lut(
    frame: &CpuFrame,
    lights: &MarchLights,
    s: &InterleavedSettings,
    lut: &PhaseLut,
    dir: Vec3,
    dist: f32,
    first: u32,
    stride: u32,
    j: f32,
) -> Vec3 {
    let o = frame.desc.camera.position;
    march_light_groups(o, lights, dir, dist, s.ray_march.steps, s.policy, |set, steps, _| {
        march_steps_lut(frame, lights, set, lut, dir, steps, first, stride, j)
    })
}

/// Mirrors `march_ray` in march.wgsl: the terms k, k + M², … of eq. 1 on this pixel's own ray
/// (§4.1: "in a particular pixel we evaluate just N/M² terms"). `lights` is
/// [`MarchLights::of`] the frame; `lut` the phase table when `phase_lut` is on.
#[allow(clippy::too_many_arguments)]
pub fn march_ray(
    frame: &CpuFrame,
    s: &InterleavedSettings,
    lights: &MarchLights,
    lut: Option<&PhaseLut>,
    x: u32,
    y: u32,
    dir: Vec3,
    dist: f32,
) -> Vec3 {
    let j = if s.ray_march.jitter { pixel_jitter(x / s.block, y / s.block, s.ray_march.frame_index) } else { 0.5 };
    let stride = s.block * s.block;
    let k = block_offset(s, x, y);
    match lut {
        Some(lut) => march_lights_lut(frame, lights, s, lut, dir, dist, k, stride, j),
        None => march_lights(frame, lights, dir, dist, s.ray_march.steps, k, stride, j, s.policy).truncate(),
    }
}

fn march_with(frame: &CpuFrame, s: &InterleavedSettings, lut: Option<&PhaseLut>) -> Image {
    let desc = frame.desc;
    let lights = MarchLights::of(desc);
    let mut img = Image::new(desc.width, desc.height);
    img.pixels.par_chunks_mut(desc.width as usize).enumerate().for_each(|(y, row)| {
        for (x, px) in row.iter_mut().enumerate() {
            let (x, y) = (x as u32, y as u32);
            let dir = desc.pixel_ray(x, y);
            let dist = desc.view_distance(frame.depth[(y * desc.width + x) as usize], dir);
            let l = march_ray(frame, s, &lights, lut, x, y, dir, dist);
            *px = [l.x, l.y, l.z, dist];
        }
    });
    img
}

/// Mirrors the `march` entry point over the whole image: rgb = the pixel's own terms,
/// alpha = its view distance s. Builds the phase table when `phase_lut` is on.
pub fn march(frame: &CpuFrame, s: &InterleavedSettings) -> Result<Image, Error> {
    s.validate()?;
    let lut = s.phase_lut.then(|| PhaseLut::new(&frame.desc.medium.phase, s.phase_lut_size));
    Ok(march_with(frame, s, lut.as_ref()))
}

/// Mirrors `offset_terms` in sum_rows.wgsl: the eq.-1 terms pixel (x, y) evaluated.
pub fn offset_terms(s: &InterleavedSettings, x: u32, y: u32) -> u32 {
    s.terms_of_offset(block_offset(s, x, y))
}

/// Mirrors `window_start` in sum_rows.wgsl / sum_columns.wgsl: clamp(c − ⌊M/2⌋, 0, size − M),
/// 0 when the image is no larger than M.
pub fn window_start(s: &InterleavedSettings, c: u32, size: u32) -> u32 {
    let m = s.block;
    if size <= m {
        return 0;
    }
    let lo = c.saturating_sub(m / 2);
    lo.min(size - m)
}

/// Mirrors `accept` in sum_rows.wgsl / sum_columns.wgsl: whether a neighbour at view distance
/// `sn` joins a centre at `sc`.
pub fn accept(s: &InterleavedSettings, sn: f32, sc: f32) -> bool {
    !s.depth_aware || (sn - sc).abs() <= s.depth_tolerance * sc
}

/// Mirrors the `sum_rows` entry point: the horizontal half of §4.1's separable addition.
/// `march` is [`march`]'s output; returns rgb = the row window's sum, alpha = the number of
/// eq.-1 terms in it.
pub fn sum_rows(frame: &CpuFrame, s: &InterleavedSettings, march: &Image) -> Image {
    let (w, h) = (frame.desc.width, frame.desc.height);
    let mut img = Image::new(w, h);
    img.pixels.par_chunks_mut(w as usize).enumerate().for_each(|(y, row)| {
        let y = y as u32;
        for (x, px) in row.iter_mut().enumerate() {
            let x = x as u32;
            let sc = march.get(x, y)[3];
            let x0 = window_start(s, x, w);
            let x1 = (x0 + s.block).min(w);
            let mut sum = Vec3::ZERO;
            let mut terms = 0u32;
            for qx in x0..x1 {
                let v = march.get(qx, y);
                if accept(s, v[3], sc) {
                    sum += Vec3::new(v[0], v[1], v[2]);
                    terms += offset_terms(s, qx, y);
                }
            }
            *px = [sum.x, sum.y, sum.z, terms as f32];
        }
    });
    img
}

/// Mirrors the `sum_columns` entry point: the vertical half of §4.1's separable addition over
/// `rows` ([`sum_rows`]'s output), comparing view distances from `march` ([`march`]'s alpha),
/// renormalised by N / (terms added); 0 where no term was added.
pub fn sum_columns(frame: &CpuFrame, s: &InterleavedSettings, march: &Image, rows: &Image) -> Image {
    let (w, h) = (frame.desc.width, frame.desc.height);
    let mut img = Image::new(w, h);
    img.pixels.par_chunks_mut(w as usize).enumerate().for_each(|(y, row)| {
        let y = y as u32;
        let y0 = window_start(s, y, h);
        let y1 = (y0 + s.block).min(h);
        for (x, px) in row.iter_mut().enumerate() {
            let x = x as u32;
            let sc = march.get(x, y)[3];
            let mut sum = Vec3::ZERO;
            let mut terms = 0.0f32;
            for qy in y0..y1 {
                if accept(s, march.get(x, qy)[3], sc) {
                    let r = rows.get(x, qy);
                    sum += Vec3::new(r[0], r[1], r[2]);
                    terms += r[3];
                }
            }
            let l = if terms > 0.0 { sum * (s.ray_march.steps as f32 / terms) } else { Vec3::ZERO };
            *px = [l.x, l.y, l.z, 1.0];
        }
    });
    img
}

/// Runs the three passes (`march`, `sum_rows`, `sum_columns`) with per-pass wall-clock times.
pub fn render(frame: &CpuFrame, s: &InterleavedSettings) -> Result<(Image, TechniqueStats), Error> {
    s.validate()?;
    let desc = frame.desc;
    let ms = |t: Instant| t.elapsed().as_secs_f64() * 1e3;
    let t = Instant::now();
    let lut = s.phase_lut.then(|| PhaseLut::new(&desc.medium.phase, s.phase_lut_size));
    let marched = march_with(frame, s, lut.as_ref());
    let march_ms = ms(t);
    let t = Instant::now();
    let rows = sum_rows(frame, s, &marched);
    let rows_ms = ms(t);
    let t = Instant::now();
    let out = sum_columns(frame, s, &marched, &rows);
    let columns_ms = ms(t);
    let pass = |name: &str, ms| PassTime { name: name.into(), ms };
    let stats = TechniqueStats {
        technique: "interleaved".into(),
        backend: "cpu".into(),
        timing: "wall-clock".into(),
        passes: vec![pass("march", march_ms), pass("sum_rows", rows_ms), pass("sum_columns", columns_ms)],
        raymarched_samples: s.raymarched_samples(desc.width, desc.height),
        gpu_memory_bytes: 0,
        extra: s.extra_stats(lut.as_ref().map(|l| l.max_rel_error)),
    };
    Ok((out, stats))
}
