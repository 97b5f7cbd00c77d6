//! CPU mirror of `epipolar`: the same line placement, classification, interpolation and
//! upsampling, with the same f32 arithmetic, function for function with geometry.wgsl and the
//! pass shaders (lines.wgsl, refine.wgsl, march.wgsl, interpolate.wgsl, upsample.wgsl,
//! prefilter.wgsl). Line textures are row-major `Vec`s, row k (line) × column t (texel):
//! index k·S + t.

use super::{EpipolarDebug, EpipolarLine, EpipolarParams, EpipolarSettings, MIN_LINE_LENGTH, MIN_WEIGHT, stats_extra};
use crate::error::Error;
use crate::frame::{CpuFrame, FrameDesc};
use crate::image::Image;
use crate::march::{MarchLights, MarchSettings, SpotCone, StepPolicy, cone_interval, march_pixel};
use crate::model::{Light, RgbTexture};
use crate::stats::{PassTime, TechniqueStats};
use glam::{Vec2, Vec3, Vec4};
use rayon::prelude::*;
use std::sync::Arc;

/// The epipole of `desc` in homogeneous pixel coordinates (x, y, w, 0), scaled so that the
/// largest |component| is 1, and whether the camera coincides with the light.
///
/// The light's direction from the camera, v = light − camera (point, spot) or −direction
/// (directional: the sun is at −direction), is projected as a direction, clip = VP·(v, 0): for
/// a perspective projection x, y and w of VP·(camera + v, 1) depend on v alone, so this is the
/// projection of the light without the cancellation of large translations. Pixel coordinates:
/// ((x + w)·W/2, (w − y)·H/2, w) (`FrameDesc::pixel_ndc` inverted). w < 0 (the light behind
/// the camera) gives the vanishing point of the anti-crepuscular rays, which §4.1 treats
/// exactly like a light in front; w = 0 (a light direction parallel to the image plane) is a
/// point at infinity, and every line is parallel to (x, y).
///
/// Degenerate (§4.1, the camera at the light): |v| ≤ [`super::DEGENERATE_DISTANCE`]·max(1,
/// |camera|, |light|) (or a non-finite projection); the epipole is then (−1, 0, 0), infinitely
/// far left, and the border points lie on the right edge: horizontal lines, naïve
/// screen-space subsampling.
pub fn epipole(desc: &FrameDesc) -> ([f32; 4], bool) {
    const DEGENERATE: ([f32; 4], bool) = ([-1.0, 0.0, 0.0, 0.0], true);
    let cam = desc.camera.position;
    let (v, scale) = match &desc.lights[0].light {
        Light::Directional { direction, .. } => (-direction.normalize(), 1.0f32),
        Light::Spot { position, .. } | Light::Point { position, .. } => {
            (*position - cam, 1.0f32.max(cam.abs().max_element()).max(position.abs().max_element()))
        }
    };
    // (NaN-safe: a non-finite direction is degenerate too.)
    if v.length().partial_cmp(&(super::DEGENERATE_DISTANCE * scale)) != Some(std::cmp::Ordering::Greater) {
        return DEGENERATE;
    }
    let c = desc.camera.view_proj() * Vec4::new(v.x, v.y, v.z, 0.0);
    let (w, h) = (desc.width as f32, desc.height as f32);
    let e = Vec3::new((c.x + c.w) * 0.5 * w, (c.w - c.y) * 0.5 * h, c.w);
    let m = e.abs().max_element();
    if !(m > 0.0 && m.is_finite()) {
        return DEGENERATE;
    }
    let e = e / m;
    ([e.x, e.y, e.z, 0.0], false)
}

/// Mirrors `rect_min` in geometry.wgsl: the top-left pixel centre.
pub fn rect_min() -> Vec2 {
    Vec2::splat(0.5)
}

/// Mirrors `rect_max`: the bottom-right pixel centre.
pub fn rect_max(desc: &FrameDesc) -> Vec2 {
    Vec2::new(desc.width as f32 - 0.5, desc.height as f32 - 0.5)
}

/// Mirrors `perimeter`: the perimeter of the sample rect, pixels.
pub fn perimeter(desc: &FrameDesc) -> f32 {
    let d = rect_max(desc) - rect_min();
    2.0 * (d.x + d.y)
}

/// Mirrors `border_point`: the point at perimeter parameter u (clockwise from the top-left
/// corner: top edge left to right, right edge down, bottom edge right to left, left edge up).
pub fn border_point(desc: &FrameDesc, u: f32) -> Vec2 {
    let (lo, hi) = (rect_min(), rect_max(desc));
    let wr = hi.x - lo.x;
    let hr = hi.y - lo.y;
    if u < wr {
        return Vec2::new(lo.x + u, lo.y);
    }
    if u < wr + hr {
        return Vec2::new(hi.x, lo.y + (u - wr));
    }
    if u < 2.0 * wr + hr {
        return Vec2::new(hi.x - (u - wr - hr), hi.y);
    }
    Vec2::new(lo.x, hi.y - (u - 2.0 * wr - hr))
}

/// Mirrors `border_param`: the perimeter parameter of a border point (nearest edge).
pub fn border_param(desc: &FrameDesc, b: Vec2) -> f32 {
    let (lo, hi) = (rect_min(), rect_max(desc));
    let wr = hi.x - lo.x;
    let hr = hi.y - lo.y;
    let dt = (b.y - lo.y).abs();
    let dr = (b.x - hi.x).abs();
    let db = (b.y - hi.y).abs();
    let dl = (b.x - lo.x).abs();
    let m = dt.min(dr).min(db.min(dl));
    if dt == m {
        return (b.x - lo.x).clamp(0.0, wr);
    }
    if dr == m {
        return wr + (b.y - lo.y).clamp(0.0, hr);
    }
    if db == m {
        return wr + hr + (hi.x - b.x).clamp(0.0, wr);
    }
    2.0 * wr + hr + (hi.y - b.y).clamp(0.0, hr)
}

/// Mirrors `line_border_point`: b_k at perimeter parameter (k + ½)·P/slices (degenerate: on
/// the right edge at y = ½ + (k + ½)·(H − 1)/slices).
pub fn line_border_point(desc: &FrameDesc, p: &EpipolarParams, k: u32) -> Vec2 {
    let n = p.slices as f32;
    if p.degenerate == 1 {
        let hr = rect_max(desc).y - rect_min().y;
        return Vec2::new(rect_max(desc).x, rect_min().y + (k as f32 + 0.5) * hr / n);
    }
    border_point(desc, (k as f32 + 0.5) * perimeter(desc) / n)
}

/// Mirrors `towards_epipole`: (unit direction from q towards the epipole, distance to it;
/// 1e30 at infinity), or zero at the epipole.
pub fn towards_epipole(p: &EpipolarParams, q: Vec2) -> Vec3 {
    let e = Vec3::new(p.epipole[0], p.epipole[1], p.epipole[2]);
    let v = Vec2::new(e.x, e.y) - q * e.z;
    let n = v.length();
    if n <= 0.0 {
        return Vec3::ZERO;
    }
    let sg = if e.z >= 0.0 { 1.0 } else { -1.0 };
    let dir = v / n * sg;
    let mut dist = 1e30f32;
    if e.z.abs() * 1e30 > n {
        dist = n / e.z.abs();
    }
    dir.extend(dist)
}

/// Mirrors `clip_ray`: [u0, u1] of q + u·d, u in [0, umax], inside the sample rect.
pub fn clip_ray(desc: &FrameDesc, q: Vec2, d: Vec2, umax: f32) -> Vec2 {
    let (lo, hi) = (rect_min(), rect_max(desc));
    let mut u0 = 0.0f32;
    let mut u1 = umax;
    for a in 0..2 {
        if d[a].abs() < 1e-12 {
            if q[a] < lo[a] || q[a] > hi[a] {
                return Vec2::new(1.0, 0.0);
            }
        } else {
            let t1 = (lo[a] - q[a]) / d[a];
            let t2 = (hi[a] - q[a]) / d[a];
            u0 = u0.max(t1.min(t2));
            u1 = u1.min(t1.max(t2));
        }
    }
    Vec2::new(u0, u1)
}

/// Mirrors `point_ray`: the view ray through a continuous pixel-space point.
pub fn point_ray(desc: &FrameDesc, q: Vec2) -> Vec3 {
    let ndc = Vec2::new(q.x / desc.width as f32 * 2.0 - 1.0, 1.0 - q.y / desc.height as f32 * 2.0);
    desc.camera.ndc_ray(ndc)
}

/// Mirrors `texel_point`: the point of texel t of a line.
pub fn texel_point(p: &EpipolarParams, line: &EpipolarLine, t: u32) -> Vec2 {
    let n1 = p.samples - 1;
    let a = line.length * ((n1 - t) as f32 / n1 as f32);
    Vec2::from(line.end) + Vec2::from(line.dir) * a
}

/// Mirrors `texel_pixel`: the pixel ⌊q⌋ a sample at q takes, clamped to the image.
pub fn texel_pixel(desc: &FrameDesc, q: Vec2) -> (u32, u32) {
    let hi = Vec2::new(desc.width as f32 - 1.0, desc.height as f32 - 1.0);
    let c = q.floor().clamp(Vec2::ZERO, hi);
    (c.x as u32, c.y as u32)
}

/// Mirrors `initial_count`: K, or with length-proportional initial samples
/// clamp(⌈K·len/diagonal⌉, 2, K), the diagonal being that of the sample rect.
pub fn initial_count(desc: &FrameDesc, p: &EpipolarParams, len: f32) -> u32 {
    let k = p.initial_samples;
    if p.length_proportional == 0 {
        return k;
    }
    let diag = (rect_max(desc) - rect_min()).length().max(1.0);
    ((k as f32 * len / diag).ceil() as u32).clamp(2, k)
}

/// Mirrors `initial_index`: texel round(i·(S − 1)/(n_init − 1)) of initial sample i.
pub fn initial_index(p: &EpipolarParams, i: u32, n_init: u32) -> u32 {
    let s1 = p.samples - 1;
    let k1 = n_init - 1;
    (2 * i * s1 + k1) / (2 * k1)
}

/// Mirrors `segment_index`: the index i of the initial segment that holds texel t (a texel on
/// the boundary of two segments belongs to one of them).
pub fn segment_index(p: &EpipolarParams, t: u32, n_init: u32) -> u32 {
    let s1 = p.samples - 1;
    let k1 = n_init - 1;
    (t * k1 / s1).min(k1 - 1)
}

/// The initial segment (a, b) holding texel t: initial samples i and i + 1 of
/// [`segment_index`].
pub fn segment(p: &EpipolarParams, t: u32, n_init: u32) -> (u32, u32) {
    let i = segment_index(p, t, n_init);
    (initial_index(p, i, n_init), initial_index(p, i + 1, n_init))
}

/// Mirrors `discontinuity`: |s_a − s_b| > depth_threshold + threshold_growth·min(s_a, s_b).
pub fn discontinuity(p: &EpipolarParams, sa: f32, sb: f32) -> bool {
    (sa - sb).abs() > p.depth_threshold + p.threshold_growth * sa.min(sb)
}

/// Mirrors `line_position`: k + f for the point q between lines k and k + 1 (unwrapped).
pub fn line_position(desc: &FrameDesc, p: &EpipolarParams, q: Vec2) -> f32 {
    let n = p.slices as f32;
    let (lo, hi) = (rect_min(), rect_max(desc));
    if p.degenerate == 1 {
        let hr = hi.y - lo.y;
        if hr <= 0.0 {
            return 0.0;
        }
        return (q.y - lo.y) * n / hr - 0.5;
    }
    let te = towards_epipole(p, q);
    if te.z < 0.5 || (te.x == 0.0 && te.y == 0.0) {
        return 0.0;
    }
    let d = -Vec2::new(te.x, te.y);
    let mut v = 1e30f32;
    for a in 0..2 {
        if d[a] > 0.0 {
            v = v.min((hi[a] - q[a]) / d[a]);
        } else if d[a] < 0.0 {
            v = v.min((lo[a] - q[a]) / d[a]);
        }
    }
    let b = (q + d * v).clamp(lo, hi);
    let per = perimeter(desc);
    if per <= 0.0 {
        return 0.0;
    }
    border_param(desc, b) * n / per - 0.5
}

/// Mirrors `line_row`: the row of line index k (wrapping around the border), or −1 when there
/// is none (degenerate case, outside 0..slices).
pub fn line_row(p: &EpipolarParams, k: i32) -> i32 {
    let n = p.slices as i32;
    if p.degenerate == 1 {
        return if (0..n).contains(&k) { k } else { -1 };
    }
    k.rem_euclid(n)
}

/// Mirrors `spatial_weight`: the spatial kernel at x = |j|/σ.
pub fn spatial_weight(p: &EpipolarParams, x: f32) -> f32 {
    if p.weighting == 1 { 1.0 / (1.0 + x * x) } else { (-x * x).exp() }
}

/// Mirrors `depth_weight`: the depth kernel at x = |sᵢ − s|/s/σ.
pub fn depth_weight(p: &EpipolarParams, x: f32) -> f32 {
    match p.weighting {
        1 => 1.0 / (1.0 + x * x),
        2 => {
            if x <= 1.0 {
                1.0
            } else {
                0.0
            }
        }
        _ => (-x * x).exp(),
    }
}

/// Mirrors `near_epipole`: a pixel within `epipole_radius` pixels of the epipole (re-marched by
/// the upsampling instead of interpolated).
pub fn near_epipole(p: &EpipolarParams, q: Vec2) -> bool {
    p.degenerate == 0 && towards_epipole(p, q).z < p.epipole_radius
}

// ---- pass 1: lines ----

/// Mirrors `spot_clip` in lines.wgsl.
pub fn spot_clip(desc: &FrameDesc, cone: &SpotCone, p: &EpipolarParams, line: EpipolarLine) -> EpipolarLine {
    let mut line = line;
    let n = p.samples;
    let mut first = n;
    let mut last = 0;
    for i in 0..n {
        let dir = point_ray(desc, texel_point(p, &line, i));
        if cone_interval(cone, desc.camera.position, dir, desc.far_distance(dir)).is_some() {
            if first == n {
                first = i;
            }
            last = i;
        }
    }
    if first == n {
        line.valid = 0;
        return line;
    }
    let i0 = first.max(1) - 1;
    let i1 = (last + 1).min(n - 1);
    let end = texel_point(p, &line, i1);
    line.length *= (i1 - i0) as f32 / (n - 1) as f32;
    line.end = end.to_array();
    if line.length < MIN_LINE_LENGTH {
        line.valid = 0;
    }
    line
}

/// Mirrors `setup_line` in lines.wgsl: line k (§4.1).
pub fn setup_line(desc: &FrameDesc, cone: Option<&SpotCone>, p: &EpipolarParams, k: u32) -> EpipolarLine {
    let b = line_border_point(desc, p, k);
    let te = towards_epipole(p, b);
    let d = Vec2::new(te.x, te.y);
    let mut line = EpipolarLine { end: b.to_array(), dir: d.to_array(), ..Default::default() };
    if d == Vec2::ZERO {
        return line;
    }
    let c = clip_ray(desc, b, d, te.z);
    let u0 = c.x.max(0.0);
    if c.y - u0 < MIN_LINE_LENGTH {
        return line;
    }
    line.end = (b + d * u0).to_array();
    line.length = c.y - u0;
    line.valid = 1;
    if let Some(cone) = cone {
        line = spot_clip(desc, cone, p, line);
    }
    if line.valid == 1 {
        line.initial = initial_count(desc, p, line.length);
    } else {
        line.length = 0.0;
    }
    line
}

/// Mirrors the `lines` entry point: every line.
pub fn lines(desc: &FrameDesc, p: &EpipolarParams) -> Vec<EpipolarLine> {
    let cone = SpotCone::of(&desc.lights[0].light);
    (0..p.slices).into_par_iter().map(|k| setup_line(desc, cone.as_ref(), p, k)).collect()
}

/// Mirrors the `coordinates` entry point: the coordinate texture (p.x, p.y, s of pixel ⌊p⌋,
/// valid), row-major k·S + t.
pub fn coordinates(frame: &CpuFrame, p: &EpipolarParams, lines: &[EpipolarLine]) -> Vec<[f32; 4]> {
    let desc = frame.desc;
    let s = p.samples as usize;
    let mut out = vec![[0.0f32; 4]; s * lines.len()];
    out.par_chunks_mut(s).zip(lines.par_iter()).for_each(|(row, line)| {
        if line.valid == 0 {
            return;
        }
        for (t, texel) in row.iter_mut().enumerate() {
            let q = texel_point(p, line, t as u32);
            let (x, y) = texel_pixel(desc, q);
            let dir = desc.pixel_ray(x, y);
            let sd = desc.view_distance(frame.depth[(y * desc.width + x) as usize], dir);
            *texel = [q.x, q.y, sd, 1.0];
        }
    });
    out
}

// ---- pass 2: refine ----

/// Mirrors the `refine` entry point's walk for one line: every texel's left | right << 16 over
/// the view distances `s` of the line (left = right = t for a ray-march sample). `near[t]`:
/// texel t lies within `epipole_radius` of the epipole ([`near_epipole`]).
///
/// The paper's search (§5.2) walks from texel t to the left and to the right until a depth
/// discontinuity or the end of t's initial segment ([`segment`]); so left and right are the
/// ends of the run of texels around t with no break inside, clipped to the segment. Each
/// segment is walked once to find those runs (S texel reads per line, not S × the texels per
/// segment); a unit test holds it to the per-texel search on every texel.
///
/// The disc's edge breaks the search as a depth discontinuity does: the texels on either side
/// of it become ray-march samples, so no texel outside the disc interpolates from one inside it
/// (the disc's pixels are re-marched instead). Every line's first texel sits on the epipole,
/// where the in-scattering is least like the rest of the line: a point or spot light seen
/// directly peaks like 1/r there (the ray through it passes the light at distance 0); under a
/// sun the ray runs along the light, so an occluder's edge through the epipole lets that one
/// ray read the edge's partial light over its whole length. Interpolating from it smeared
/// either over the line's whole first initial segment: for the sun, a starburst from the
/// epipole over the dark occluder (docs/RESULTS.md, the Bevy comparison: epipolar's fast preset
/// 28.5 → 37.8 dB with the disc's break under the sun).
pub fn refine_line(p: &EpipolarParams, s: &[f32], near: &[bool], n_init: u32) -> Vec<u32> {
    let breaks = |u: usize| discontinuity(p, s[u - 1], s[u]) || near[u - 1] != near[u];
    let mut interp = vec![0u32; s.len()];
    for i in 0..n_init - 1 {
        let (a, b) = (initial_index(p, i, n_init), initial_index(p, i + 1, n_init));
        // The texels of the run [l, r] that segment i owns ([`segment_index`]).
        let mut write_run = |l: u32, r: u32| {
            for u in l..=r {
                if segment_index(p, u, n_init) == i {
                    let (lu, ru) = if u == l || u == r { (u, u) } else { (l, r) };
                    interp[u as usize] = lu | (ru << 16);
                }
            }
        };
        let mut start = a;
        for t in a + 1..=b {
            if breaks(t as usize) {
                write_run(start, t - 1);
                start = t;
            }
        }
        write_run(start, b);
    }
    interp
}

/// What the refine pass produces.
#[derive(Clone, Debug, PartialEq)]
pub struct Refined {
    /// The interpolation texture: left | right << 16 (0 on culled lines).
    pub interp: Vec<u32>,
    /// The pixels to ray-march (y·W + x), each once, in the order their first ray-march texel
    /// comes in (k, t) (the GPU's order is whatever its atomics give).
    pub list: Vec<u32>,
    /// Texels classified as ray-march samples (≥ `list.len()`).
    pub sample_texels: u64,
}

/// Mirrors the `refine` entry point: the classification of every texel and the compacted list
/// of the pixels of the ray-march samples.
pub fn refine(desc: &FrameDesc, p: &EpipolarParams, lines: &[EpipolarLine], coords: &[[f32; 4]]) -> Refined {
    let n = p.samples as usize;
    let rows: Vec<(Vec<u32>, Vec<u32>)> = coords
        .par_chunks(n)
        .zip(lines.par_iter())
        .map(|(row, line)| {
            if line.valid == 0 {
                return (vec![0; n], Vec::new());
            }
            let s: Vec<f32> = row.iter().map(|c| c[2]).collect();
            let near: Vec<bool> = row.iter().map(|c| near_epipole(p, Vec2::new(c[0], c[1]))).collect();
            let interp = refine_line(p, &s, &near, line.initial);
            let pixels = (0..n as u32)
                .filter(|&t| interp[t as usize] == t | (t << 16))
                .map(|t| {
                    let c = row[t as usize];
                    let (x, y) = texel_pixel(desc, Vec2::new(c[0], c[1]));
                    y * desc.width + x
                })
                .collect();
            (interp, pixels)
        })
        .collect();
    let mut out = Refined { interp: Vec::with_capacity(n * lines.len()), list: Vec::new(), sample_texels: 0 };
    let mut claimed = vec![false; (desc.width * desc.height) as usize];
    for (interp, pixels) in rows {
        out.interp.extend(interp);
        out.sample_texels += pixels.len() as u64;
        for px in pixels {
            if !std::mem::replace(&mut claimed[px as usize], true) {
                out.list.push(px);
            }
        }
    }
    out
}

/// Mirrors the `args` entry point: the march's indirect dispatch for `count` samples.
pub fn march_dispatch(p: &EpipolarParams, count: u32) -> [u32; 3] {
    let groups = count.div_ceil(64);
    let x = groups.min(p.max_workgroups);
    let y = if x > 0 { groups.div_ceil(x) } else { 1 };
    [x, y, 1]
}

// ---- pass 3: march ----

/// The march of `p` (what `march_pixel` needs).
pub fn pixel_march(p: &EpipolarParams) -> (MarchSettings, StepPolicy) {
    let m = MarchSettings { steps: p.steps, jitter: p.jitter == 1, frame_index: p.frame_index };
    (m, StepPolicy::from_code(p.spot_steps, p.spot_denominator))
}

/// Mirrors march.wgsl: every pixel of `list` marches its own ray (brute-force's
/// `march_pixel`) into the marched texture (in-scattering, s), indexed by pixel; other pixels
/// stay 0. `frame` carries the spot texture the samples read (the prefiltered one when it runs,
/// [`prefiltered_desc`]).
pub fn march(frame: &CpuFrame, p: &EpipolarParams, list: &[u32]) -> Image {
    let desc = frame.desc;
    let lights = MarchLights::of(desc);
    let (m, policy) = pixel_march(p);
    let values: Vec<(usize, [f32; 4])> = list
        .par_iter()
        .map(|&pixel| {
            let (x, y) = (pixel % desc.width, pixel / desc.width);
            let dir = desc.pixel_ray(x, y);
            let s = desc.view_distance(frame.depth[pixel as usize], dir);
            let l = march_pixel(frame, &lights, &m, policy, x, y, dir, s);
            (pixel as usize, [l.x, l.y, l.z, s])
        })
        .collect();
    let mut out =
        Image { width: desc.width, height: desc.height, pixels: vec![[0.0; 4]; (desc.width * desc.height) as usize] };
    for (i, v) in values {
        out.pixels[i] = v;
    }
    out
}

// ---- pass 4: interpolate ----

/// Mirrors `marched_at` in interpolate.wgsl: the marched in-scattering of a texel, at its pixel.
pub fn marched_at(desc: &FrameDesc, coord: [f32; 4], marched: &Image) -> Vec3 {
    let (x, y) = texel_pixel(desc, Vec2::new(coord[0], coord[1]));
    let m = marched.get(x, y);
    Vec3::new(m[0], m[1], m[2])
}

/// Mirrors interpolate.wgsl for texel t of a line (its row of coordinates and interpolation
/// texels): between its ray-march samples, (in-scattering, s); 0 on culled lines.
pub fn interpolate_texel(desc: &FrameDesc, coords_row: &[[f32; 4]], interp: u32, marched: &Image, t: u32) -> [f32; 4] {
    let coord = coords_row[t as usize];
    if coord[3] == 0.0 {
        return [0.0; 4];
    }
    let (left, right) = (interp & 0xffff, interp >> 16);
    let a = marched_at(desc, coords_row[left as usize], marched);
    let mut l = a;
    if right != left {
        let b = marched_at(desc, coords_row[right as usize], marched);
        let w = (t - left) as f32 / (right - left) as f32;
        l = a * (1.0 - w) + b * w;
    }
    [l.x, l.y, l.z, coord[2]]
}

/// Mirrors the `interpolate` entry point: the radiance texture.
pub fn interpolate(
    desc: &FrameDesc,
    p: &EpipolarParams,
    coords: &[[f32; 4]],
    interp: &[u32],
    marched: &Image,
) -> Vec<[f32; 4]> {
    let n = p.samples as usize;
    let mut out = vec![[0.0f32; 4]; coords.len()];
    out.par_chunks_mut(n).enumerate().for_each(|(k, row)| {
        let coords_row = &coords[k * n..(k + 1) * n];
        for (t, texel) in row.iter_mut().enumerate() {
            *texel = interpolate_texel(desc, coords_row, interp[k * n + t], marched, t as u32);
        }
    });
    out
}

// ---- pass 5: upsample ----

/// Mirrors `projection` in upsample.wgsl: q projected onto the (unclipped) line.
pub fn projection(line: &EpipolarLine, q: Vec2) -> Vec2 {
    let (end, dir) = (Vec2::from(line.end), Vec2::from(line.dir));
    end + dir * (q - end).dot(dir)
}

/// Mirrors `struct Taps`: one line's bilateral taps for a pixel.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Taps {
    /// Σ w·L.
    pub sum: Vec3,
    /// Σ w.
    pub w: f32,
    /// The tap nearest in depth.
    pub nearest: Vec3,
    /// Its |sᵢ − s| (3e38 when there was no tap).
    pub nearest_diff: f32,
}

impl Taps {
    /// No taps.
    pub const NONE: Taps = Taps { sum: Vec3::ZERO, w: 0.0, nearest: Vec3::ZERO, nearest_diff: 3.0e38 };
}

/// Mirrors `line_taps`: the bilateral filter along line `row` for the pixel at q with view
/// distance s and tap spacing l (pixels), over the radiance texture.
pub fn line_taps(p: &EpipolarParams, line: &EpipolarLine, radiance_row: &[[f32; 4]], q: Vec2, s: f32, l: f32) -> Taps {
    let mut r = Taps::NONE;
    // A line on which q's own point lies inside the re-marched disc has no estimate near q:
    // its texels there are skipped (below), and the taps left, j·l further out, would
    // extrapolate the in-scattering from farther from the light (darker where it peaks at the
    // epipole); the line is passed over as a culled one is.
    if line.valid == 0 || near_epipole(p, projection(line, q)) {
        return r;
    }
    let last = p.samples - 1;
    let n1 = last as f32;
    let u = (q - Vec2::from(line.end)).dot(Vec2::from(line.dir));
    let tc = n1 * (1.0 - u / line.length);
    let spacing = (l * n1 / line.length).max(1.0);
    let m = (p.taps / 2) as i32;
    let inv_s = 1.0 / s.max(1e-6);
    for j in -m..=m {
        let mut tj = tc + j as f32 * spacing;
        if j == 0 {
            tj = tj.clamp(0.0, n1);
        } else if tj < 0.0 || tj > n1 {
            continue;
        }
        let i0 = (tj.floor() as u32).min(last);
        let i1 = (i0 + 1).min(last);
        let fr = tj - i0 as f32;
        let ws = spatial_weight(p, j.unsigned_abs() as f32 / p.spatial_scale);
        for (i, wl) in [(i0, 1.0 - fr), (i1, fr)] {
            // A texel inside the re-marched disc holds no estimate: the refinement let it
            // interpolate from the line's first texel, on the epipole, where the in-scattering
            // peaks or is singular ([`refine_line`]); a pixel outside the disc whose taps
            // reach in (towards the light, or the bilinear pair across the disc's edge) skips
            // it.
            if near_epipole(p, texel_point(p, line, i)) {
                continue;
            }
            let v = radiance_row[i as usize];
            let diff = (v[3] - s).abs();
            let w = ws * wl * depth_weight(p, diff * inv_s / p.depth_scale);
            let rgb = Vec3::new(v[0], v[1], v[2]);
            r.sum += w * rgb;
            r.w += w;
            if diff < r.nearest_diff {
                r.nearest = rgb;
                r.nearest_diff = diff;
            }
        }
    }
    r
}

/// The lines the upsampling settles on for a point q (the search of `upsample_pixel`): on
/// side a the first of lines k₀, k₀ − 1, … (`outer_lines` more) and on side b the first of
/// k₀ + 1, k₀ + 2, … whose taps weigh at least [`MIN_WEIGHT`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LineChoice {
    /// q's continuous line position k₀ + f.
    pub pos: f32,
    /// k₀ = ⌊pos⌋ (unwrapped).
    pub k0: i32,
    /// Side a: (unwrapped line index, its taps).
    pub a: Option<(i32, Taps)>,
    /// Side b.
    pub b: Option<(i32, Taps)>,
    /// The tap nearest in depth over every line examined.
    pub nearest: Vec3,
    /// Its depth difference.
    pub nearest_diff: f32,
}

/// The search of `upsample_pixel` for the point q, with `taps(row)` the taps of a line row.
pub fn choose_lines(desc: &FrameDesc, p: &EpipolarParams, q: Vec2, taps: &dyn Fn(u32) -> Taps) -> LineChoice {
    let pos = line_position(desc, p, q);
    let k0 = pos.floor() as i32;
    let mut c = LineChoice { pos, k0, a: None, b: None, nearest: Vec3::ZERO, nearest_diff: 3.0e38 };
    for (side, start, step) in [(0, k0, -1), (1, k0 + 1, 1)] {
        for o in 0..=p.outer_lines as i32 {
            let k = start + step * o;
            let row = line_row(p, k);
            if row < 0 {
                break;
            }
            let t = taps(row as u32);
            if t.nearest_diff < c.nearest_diff {
                c.nearest = t.nearest;
                c.nearest_diff = t.nearest_diff;
            }
            if t.w >= MIN_WEIGHT {
                if side == 0 {
                    c.a = Some((k, t));
                } else {
                    c.b = Some((k, t));
                }
                break;
            }
        }
    }
    c
}

/// Per-frame constants of the upsampling.
struct Ctx<'a> {
    frame: &'a CpuFrame<'a>,
    p: &'a EpipolarParams,
    cone: Option<SpotCone>,
    lights: MarchLights,
    lines: &'a [EpipolarLine],
    radiance: &'a [[f32; 4]],
}

/// Mirrors `upsample_pixel`: (in-scattering, re-marched).
fn upsample_pixel(c: &Ctx, x: u32, y: u32) -> (Vec3, bool) {
    let desc = c.frame.desc;
    let p = c.p;
    let dir = desc.pixel_ray(x, y);
    let s = desc.view_distance(c.frame.depth[(y * desc.width + x) as usize], dir);
    if let Some(cone) = &c.cone
        && cone_interval(cone, desc.camera.position, dir, s).is_none()
    {
        return (Vec3::ZERO, false);
    }
    let q = Vec2::new(x as f32, y as f32) + 0.5;
    let k0 = line_position(desc, p, q).floor() as i32;
    // q's points on the lines around it, k₀ and k₀ + 1: their distance is the tap spacing l.
    // The pixel is re-marched, not interpolated, when it lies within `epipole_radius` of the
    // epipole ([`near_epipole`]) or both those points do. Near the epipole the lines fan out
    // (an epipole a few pixels inside the border sends the lines through that border radians
    // apart), so a pixel just outside the disc can have both points inside it: those lines
    // offer no taps there ([`line_taps`]), and the lines further out only taps farther from
    // the light. (The disc is a special case: a projection is never farther from the epipole
    // than the pixel.)
    let (l, remarch) = if p.degenerate == 1 {
        ((rect_max(desc).y - rect_min().y) / p.slices as f32, false)
    } else {
        let pr = |k: i32| projection(&c.lines[line_row(p, k) as usize], q);
        let (pa, pb) = (pr(k0), pr(k0 + 1));
        ((pa - pb).length(), near_epipole(p, q) || (near_epipole(p, pa) && near_epipole(p, pb)))
    };
    if remarch {
        return (
            {
                let (m, policy) = pixel_march(p);
                march_pixel(c.frame, &c.lights, &m, policy, x, y, dir, s).truncate()
            },
            true,
        );
    }
    let n = p.samples as usize;
    let taps = |row: u32| {
        let r = row as usize;
        line_taps(p, &c.lines[r], &c.radiance[r * n..(r + 1) * n], q, s, l)
    };
    let ch = choose_lines(desc, p, q, &taps);
    match (ch.a, ch.b) {
        (Some((ka, a)), Some((kb, b))) => {
            let f = (ch.pos - ka as f32) / (kb - ka) as f32;
            (((1.0 - f) * a.sum + f * b.sum) / ((1.0 - f) * a.w + f * b.w), false)
        }
        (Some((_, a)), None) => (a.sum / a.w, false),
        (None, Some((_, b))) => (b.sum / b.w, false),
        (None, None) if p.fallback_remarch == 1 => (
            {
                let (m, policy) = pixel_march(p);
                march_pixel(c.frame, &c.lights, &m, policy, x, y, dir, s).truncate()
            },
            true,
        ),
        (None, None) => (ch.nearest, false),
    }
}

/// Mirrors the `upsample` entry point: the in-scattering of every pixel from the radiance
/// texture, and the number of pixels re-marched at full resolution. `frame` carries the
/// original spot texture (re-marched pixels are full-resolution samples).
pub fn upsample(frame: &CpuFrame, p: &EpipolarParams, lines: &[EpipolarLine], radiance: &[[f32; 4]]) -> (Image, u64) {
    let desc = frame.desc;
    let c = Ctx { frame, p, cone: SpotCone::of(&desc.lights[0].light), lights: MarchLights::of(desc), lines, radiance };
    let mut img = Image::new(desc.width, desc.height);
    let remarched = img
        .pixels
        .par_chunks_mut(desc.width as usize)
        .enumerate()
        .map(|(y, row)| {
            let mut n = 0u64;
            for (x, px) in row.iter_mut().enumerate() {
                let (l, re) = upsample_pixel(&c, x as u32, y as u32);
                *px = [l.x, l.y, l.z, 1.0];
                n += re as u64;
            }
            n
        })
        .sum();
    (img, remarched)
}

// ---- pass 0: the spot texture prefilter ----

/// Mirrors prefilter.wgsl: the mean of each 2^level × 2^level block (fewer texels at the right
/// and bottom edges), ⌈w/2^level⌉ × ⌈h/2^level⌉ texels.
pub fn prefilter_spot_texture(tex: &RgbTexture, level: u32) -> RgbTexture {
    let n = 1u32 << level;
    let (w, h) = (tex.width.div_ceil(n), tex.height.div_ceil(n));
    let mut texels = vec![[0.0f32; 4]; (w * h) as usize];
    for (i, out) in texels.iter_mut().enumerate() {
        let (ox, oy) = (i as u32 % w, i as u32 / w);
        let mut sum = Vec3::ZERO;
        let mut count = 0u32;
        for y in 0..n {
            for x in 0..n {
                let (px, py) = (ox * n + x, oy * n + y);
                if px < tex.width && py < tex.height {
                    let t = tex.texels[(py * tex.width + px) as usize];
                    sum += Vec3::new(t[0], t[1], t[2]);
                    count += 1;
                }
            }
        }
        let m = sum / count.max(1) as f32;
        *out = [m.x, m.y, m.z, 1.0];
    }
    RgbTexture { width: w, height: h, texels }
}

/// The frame description whose spot light carries the texture prefiltered at `level`; None
/// when there is nothing to prefilter (level 0, or no textured spot light).
pub fn prefiltered_desc(desc: &FrameDesc, level: u32) -> Option<FrameDesc> {
    match &desc.lights[0].light {
        Light::Spot { texture: Some(t), .. } if level > 0 => {
            let mut d = desc.clone();
            if let Light::Spot { texture, .. } = &mut d.lights[0].light {
                *texture = Some(Arc::new(prefilter_spot_texture(t, level)));
            }
            Some(d)
        }
        _ => None,
    }
}

// ---- the frame ----

/// Mirrors march_minmax.wgsl (`march = "minmax"`): every pixel of `list` walks its ray through
/// the min-max tree `tree` of rectification `rect` (`minmax`'s `shade`) into the marched
/// texture, as [`march`] does with steps.
pub fn march_minmax(
    frame: &CpuFrame,
    settings: &crate::techniques::minmax::MinmaxSettings,
    rect: &crate::techniques::prefiltered::Rectification,
    tree: &[[f32; 2]],
    list: &[u32],
) -> Image {
    let desc = frame.desc;
    let values: Vec<(usize, [f32; 4])> = list
        .par_iter()
        .map(|&pixel| {
            let (x, y) = (pixel % desc.width, pixel / desc.width);
            let dir = desc.pixel_ray(x, y);
            let s = desc.view_distance(frame.depth[pixel as usize], dir);
            let (l, _) = crate::techniques::minmax::cpu::shade(frame, settings, rect, tree, dir, s);
            (pixel as usize, [l.x, l.y, l.z, s])
        })
        .collect();
    let mut out =
        Image { width: desc.width, height: desc.height, pixels: vec![[0.0; 4]; (desc.width * desc.height) as usize] };
    for (i, v) in values {
        out.pixels[i] = v;
    }
    out
}

/// Every pass, timed by wall clock, with the same stats as the GPU side.
pub fn render(frame: &CpuFrame, settings: &EpipolarSettings) -> Result<(Image, TechniqueStats), Error> {
    render_with_debug(frame, settings).map(|(img, stats, _)| (img, stats))
}

/// [`render`], also returning the lines and line textures for the debug views.
pub fn render_with_debug(
    frame: &CpuFrame,
    settings: &EpipolarSettings,
) -> Result<(Image, TechniqueStats, EpipolarDebug), Error> {
    settings.validate()?;
    frame.desc.single_light()?;
    let desc = frame.desc;
    let p = EpipolarParams::new(settings, desc, 65535);
    let mut passes = Vec::new();
    let mut timed = |name: &str, start: std::time::Instant| {
        passes.push(PassTime { name: name.into(), ms: start.elapsed().as_secs_f64() * 1e3 });
    };
    let start = std::time::Instant::now();
    let pre = prefiltered_desc(desc, p.prefilter_level);
    if pre.is_some() {
        timed("prefilter", start);
    }
    let march_frame = CpuFrame { desc: pre.as_ref().unwrap_or(desc), ..*frame };
    let start = std::time::Instant::now();
    let lines = lines(desc, &p);
    let coords = coordinates(frame, &p, &lines);
    timed("lines", start);
    let start = std::time::Instant::now();
    let refined = refine(desc, &p, &lines, &coords);
    timed("refine", start);
    let minmax = settings.march == super::EpipolarMarch::Minmax;
    let marched = if minmax {
        // The tree (minmax's pass `build`), then the walk per sample.
        let mm = settings.minmax();
        let start = std::time::Instant::now();
        let rect = crate::techniques::prefiltered::Rectification::new(desc, &mm.rectify_options());
        let tree = crate::techniques::minmax::cpu::build(frame, &rect, None, mm.tree_levels());
        timed("build", start);
        let start = std::time::Instant::now();
        let marched = march_minmax(&march_frame, &mm, &rect, &tree, &refined.list);
        timed("march", start);
        marched
    } else {
        let start = std::time::Instant::now();
        let marched = march(&march_frame, &p, &refined.list);
        timed("march", start);
        marched
    };
    let start = std::time::Instant::now();
    let radiance = interpolate(desc, &p, &coords, &refined.interp, &marched);
    timed("interpolate", start);
    let start = std::time::Instant::now();
    let (img, remarched) = upsample(frame, &p, &lines, &radiance);
    timed("upsample", start);
    let valid = lines.iter().filter(|l| l.valid == 1).count() as u64;
    let marched_n = refined.list.len() as u64;
    let stats = TechniqueStats {
        technique: "epipolar".into(),
        backend: "cpu".into(),
        timing: "wall-clock".into(),
        passes,
        raymarched_samples: (if minmax { remarched } else { marched_n + remarched }) * p.steps as u64,
        gpu_memory_bytes: 0,
        extra: stats_extra(&p, (desc.width, desc.height), valid, marched_n, remarched, refined.sample_texels),
    };
    let interp = refined.interp;
    Ok((img, stats, EpipolarDebug { params: p, lines, coords, interp, radiance }))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The paper's search for one texel (§5.2 pseudo-code, restricted to t's initial segment):
    /// walk left and right from t until a break or the segment's end.
    fn paper_search(p: &EpipolarParams, s: &[f32], near: &[bool], t: u32, n_init: u32) -> u32 {
        let (a, b) = segment(p, t, n_init);
        let breaks =
            |u: u32| discontinuity(p, s[u as usize - 1], s[u as usize]) || near[u as usize - 1] != near[u as usize];
        let mut left = t;
        while left > a && !breaks(left) {
            left -= 1;
        }
        let mut right = t;
        while right < b && !breaks(right + 1) {
            right += 1;
        }
        if left == t || right == t { t | (t << 16) } else { left | (right << 16) }
    }

    /// `refine_line`'s one walk per segment gives every texel the paper's per-texel search's
    /// (left, right), on rows of steps, ramps, disc edges and noise, for S and K from 2 to the
    /// largest ratios the settings allow.
    #[test]
    fn the_walk_per_segment_equals_the_papers_search_on_every_texel() {
        let mut p: EpipolarParams = bytemuck::Zeroable::zeroed();
        p.depth_threshold = 0.5;
        p.threshold_growth = 0.05;
        // A small deterministic generator (xorshift), so the rows are the same on every run.
        let mut state = 0x9e37_79b9_u32;
        let mut next = move || {
            state ^= state << 13;
            state ^= state >> 17;
            state ^= state << 5;
            state
        };
        let (mut rows, mut samples_seen, mut interpolated_seen) = (0, 0u64, 0u64);
        for &n in &[2u32, 3, 5, 17, 64, 245, 1469] {
            p.samples = n;
            for &k in &[2u32, 3, 4, 16, 32, 64, 1469] {
                let k = k.min(n);
                for pattern in 0..4 {
                    let mut depth = 10.0f32;
                    let (mut s, mut near) = (Vec::new(), Vec::new());
                    for t in 0..n {
                        let r = next();
                        // 0: smooth ramps with rare steps; 1: frequent steps; 2: constant with
                        // the disc's edge at a few texels; 3: steps just above and below the
                        // threshold.
                        depth = match pattern {
                            0 if r % 50 == 0 => depth + 5.0,
                            0 => depth + 0.01,
                            1 if r % 3 == 0 => 5.0 + (r % 1000) as f32 * 0.05,
                            3 if r % 4 == 0 => depth + if r % 8 == 0 { 1.01 } else { 0.99 } * (0.5 + 0.05 * depth),
                            _ => depth,
                        };
                        s.push(depth);
                        near.push(pattern == 2 && (t < n / 7 || (t / 13) % 5 == 0));
                    }
                    let interp = refine_line(&p, &s, &near, k);
                    for t in 0..n {
                        let want = paper_search(&p, &s, &near, t, k);
                        assert_eq!(interp[t as usize], want, "S {n}, K {k}, pattern {pattern}, texel {t}");
                        if want == t | (t << 16) {
                            samples_seen += 1;
                        } else {
                            interpolated_seen += 1;
                        }
                    }
                    rows += 1;
                }
            }
        }
        // Both kinds of texel were compared, in quantity.
        assert!(
            rows > 150 && samples_seen > 1000 && interpolated_seen > 10_000,
            "{rows} {samples_seen} {interpolated_seen}"
        );
    }
}
