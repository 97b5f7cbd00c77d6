//! CPU mirror of `subsampled`: the same sample placement and arithmetic (f32) as march.wgsl and
//! upsample.wgsl, function for function.

use super::{MIN_WEIGHT, SubsampledSettings, stats_extra};
use crate::error::Error;
use crate::frame::CpuFrame;
use crate::image::Image;
use crate::march::{MarchLights, cone_interval, march_pixel};
use crate::stats::{PassTime, TechniqueStats};
use glam::Vec3;
use rayon::prelude::*;

/// Mirrors `source_pixel` in march.wgsl: the full-resolution pixel (along one axis of `full`
/// pixels) whose ray grid sample `i` of `grid` takes — the centre of its footprint,
/// ⌊(i + ½)·full/grid⌋, in exact integer arithmetic.
pub fn source_pixel(i: u32, full: u32, grid: u32) -> u32 {
    ((2 * i + 1) * full) / (2 * grid)
}

/// Mirrors `march_ray` in march.wgsl and upsample.wgsl: `brute-force`'s march of pixel (x, y)
/// (Tóth & Umenhoffer 2009, eq. 1, N steps over the spot-step interval).
pub fn march_ray(
    frame: &CpuFrame,
    settings: &SubsampledSettings,
    lights: &MarchLights,
    x: u32,
    y: u32,
    dir: Vec3,
    s: f32,
) -> Vec3 {
    march_pixel(frame, lights, &settings.ray_march, settings.policy, x, y, dir, s).truncate()
}

/// Mirrors `struct Bracket` in upsample.wgsl: the grid samples i0 ≤ i1 whose source pixels
/// bracket a pixel along one axis, and the bilinear weight `t` of i1.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Bracket {
    /// Grid sample at or before the pixel.
    pub i0: u32,
    /// Grid sample after it (= i0 at the borders).
    pub i1: u32,
    /// Bilinear weight of i1, in [0, 1).
    pub t: f32,
}

/// Mirrors `bracket` in upsample.wgsl.
pub fn bracket(x: u32, full: u32, grid: u32) -> Bracket {
    // The sample whose footprint [i·full/grid, (i+1)·full/grid) holds x.
    let est = ((2 * x + 1) * grid) / (2 * full);
    let i0 = if source_pixel(est, full, grid) <= x {
        est
    } else if est == 0 {
        return Bracket { i0: 0, i1: 0, t: 0.0 };
    } else {
        est - 1
    };
    let i1 = (i0 + 1).min(grid - 1);
    let (p0, p1) = (source_pixel(i0, full, grid), source_pixel(i1, full, grid));
    let t = if p1 > p0 { (x - p0) as f32 / (p1 - p0) as f32 } else { 0.0 };
    Bracket { i0, i1, t }
}

/// Mirrors `depth_weight` in upsample.wgsl: the range kernel of the bilateral filter
/// (Engelhardt & Dachsbacher 2010, §4.3, "a radial basis function of the depth difference") on
/// r = |sᵢ − s|/s — 1 up to half the tolerance, then a smoothstep down to 0 at the tolerance.
pub fn depth_weight(r: f32, tol: f32) -> f32 {
    let t = ((r - 0.5 * tol) / (0.5 * tol)).clamp(0.0, 1.0);
    1.0 - t * t * (3.0 - 2.0 * t)
}

/// Mirrors `cone_set` in upsample.wgsl: bit k set when the ray `eye` + t·`dir`, t in [0, s],
/// meets the cone of the frame's light k, a spot (the exact ray–cone test of `exact-cone`).
/// Outside a spot's cone its light is exactly zero, so rays with different sets see different
/// lights.
pub fn cone_set(frame: &CpuFrame, lights: &MarchLights, dir: Vec3, s: f32) -> u32 {
    let eye = frame.desc.camera.position;
    let mut set = 0;
    for (&k, cone) in lights.indices.iter().zip(&lights.cones) {
        if let Some(c) = cone
            && cone_interval(c, eye, dir, s).is_some()
        {
            set |= 1 << k;
        }
    }
    set
}

/// Per-frame constants of the upsampling.
struct Ctx<'a> {
    frame: &'a CpuFrame<'a>,
    settings: &'a SubsampledSettings,
    lights: MarchLights,
    grid: &'a Image,
}

/// Mirrors `upsample_pixel` in upsample.wgsl: (radiance, re-marched).
fn upsample_pixel(c: &Ctx, x: u32, y: u32) -> (Vec3, bool) {
    let desc = c.frame.desc;
    let dir = desc.pixel_ray(x, y);
    let s = desc.view_distance(c.frame.depth[(y * desc.width + x) as usize], dir);
    let (gw, gh) = (c.grid.width, c.grid.height);
    let bx = bracket(x, desc.width, gw);
    let by = bracket(y, desc.height, gh);
    let taps = [c.grid.get(bx.i0, by.i0), c.grid.get(bx.i1, by.i0), c.grid.get(bx.i0, by.i1), c.grid.get(bx.i1, by.i1)];
    let bilinear = [(1.0 - bx.t) * (1.0 - by.t), bx.t * (1.0 - by.t), (1.0 - bx.t) * by.t, bx.t * by.t];
    // The source pixels of the four taps, in the order of `taps`.
    let (sx, sy) = (
        [source_pixel(bx.i0, desc.width, gw), source_pixel(bx.i1, desc.width, gw)],
        [source_pixel(by.i0, desc.height, gh), source_pixel(by.i1, desc.height, gh)],
    );
    let sources = [(sx[0], sy[0]), (sx[1], sy[0]), (sx[0], sy[1]), (sx[1], sy[1])];
    let cones = c.settings.cone_aware && c.lights.cones.iter().any(Option::is_some);
    let own_cones = if cones { cone_set(c.frame, &c.lights, dir, s) } else { 0 };
    let inv_s = 1.0 / s.max(1e-6);
    let mut sum = Vec3::ZERO;
    let mut wsum = 0.0f32;
    let mut nearest = 0;
    let mut nearest_diff = (taps[0][3] - s).abs();
    let mut nearest_mismatch = true;
    for k in 0..4 {
        // A tap that sees other spot cones than the pixel is as far as a depth step: it counts
        // neither in the blend nor as the nearest, unless every tap is such.
        let mismatch =
            cones && cone_set(c.frame, &c.lights, desc.pixel_ray(sources[k].0, sources[k].1), taps[k][3]) != own_cones;
        let diff = (taps[k][3] - s).abs();
        let w = if mismatch { 0.0 } else { bilinear[k] * depth_weight(diff * inv_s, c.settings.depth_tolerance) };
        sum += w * Vec3::new(taps[k][0], taps[k][1], taps[k][2]);
        wsum += w;
        if (nearest_mismatch && !mismatch) || (mismatch == nearest_mismatch && diff < nearest_diff) {
            nearest = k;
            nearest_diff = diff;
            nearest_mismatch = mismatch;
        }
    }
    if wsum >= MIN_WEIGHT {
        (sum / wsum, false)
    } else if c.settings.edge_remarch {
        // No depth-compatible neighbour: march this pixel at full resolution.
        (march_ray(c.frame, c.settings, &c.lights, x, y, dir, s), true)
    } else {
        let t = taps[nearest];
        (Vec3::new(t[0], t[1], t[2]), false)
    }
}

/// Mirrors the `march` entry point of march.wgsl: the w×h grid (in-scattering in rgb, view
/// distance s in alpha), each sample an exact `brute-force` sample of its source pixel
/// (Engelhardt & Dachsbacher 2010, §6, Fig. 9: naïve subsampling).
pub fn march(frame: &CpuFrame, settings: &SubsampledSettings) -> Result<Image, Error> {
    settings.validate()?;
    let desc = frame.desc;
    let (gw, gh) = settings.grid_size(desc.width, desc.height);
    let lights = MarchLights::of(desc);
    let mut img = Image::new(gw, gh);
    img.pixels.par_chunks_mut(gw as usize).enumerate().for_each(|(j, row)| {
        let y = source_pixel(j as u32, desc.height, gh);
        for (i, px) in row.iter_mut().enumerate() {
            let x = source_pixel(i as u32, desc.width, gw);
            let dir = desc.pixel_ray(x, y);
            let s = desc.view_distance(frame.depth[(y * desc.width + x) as usize], dir);
            let l = march_ray(frame, settings, &lights, x, y, dir, s);
            *px = [l.x, l.y, l.z, s];
        }
    });
    Ok(img)
}

/// Mirrors the `upsample` entry point of upsample.wgsl: the joint bilateral upsampling of
/// `grid` (from [`march`]) to the frame's size. Returns the in-scattering and the number of
/// pixels re-marched at full resolution.
pub fn upsample(frame: &CpuFrame, settings: &SubsampledSettings, grid: &Image) -> (Image, u64) {
    let desc = frame.desc;
    let c = Ctx { frame, settings, lights: MarchLights::of(desc), grid };
    let mut img = Image::new(desc.width, desc.height);
    let remarched: u64 = img
        .pixels
        .par_chunks_mut(desc.width as usize)
        .enumerate()
        .map(|(y, row)| {
            let mut n = 0;
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

/// Both passes, timed by wall clock, with the same stats as the GPU side.
pub fn render(frame: &CpuFrame, settings: &SubsampledSettings) -> Result<(Image, TechniqueStats), Error> {
    let start = std::time::Instant::now();
    let grid = march(frame, settings)?;
    let march_ms = start.elapsed().as_secs_f64() * 1e3;
    let start = std::time::Instant::now();
    let (img, remarched) = upsample(frame, settings, &grid);
    let upsample_ms = start.elapsed().as_secs_f64() * 1e3;
    let stats = TechniqueStats {
        technique: "subsampled".into(),
        backend: "cpu".into(),
        timing: "wall-clock".into(),
        passes: vec![
            PassTime { name: "march".into(), ms: march_ms },
            PassTime { name: "upsample".into(), ms: upsample_ms },
        ],
        raymarched_samples: (grid.width as u64 * grid.height as u64 + remarched) * settings.ray_march.steps as u64,
        gpu_memory_bytes: 0,
        extra: stats_extra(grid.width, grid.height, remarched),
    };
    Ok((img, stats))
}
