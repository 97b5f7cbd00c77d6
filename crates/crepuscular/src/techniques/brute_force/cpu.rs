//! CPU mirror of `brute-force`: the same sample placement and arithmetic (f32) as march.wgsl,
//! function for function.

use super::BruteForceSettings;
use crate::error::Error;
use crate::frame::CpuFrame;
use crate::image::Image;
use crate::march::{MarchLights, march_pixel};
use crate::stats::{PassTime, TechniqueStats};
use glam::{Vec3, Vec4};
use rayon::prelude::*;

/// Mirrors `march_ray` in march.wgsl: the in-scattering in xyz, and in w the ray's
/// [`crate::march::scattering_distance`]. `lights` is [`MarchLights::of`] the frame.
pub fn march_ray(
    frame: &CpuFrame,
    settings: &BruteForceSettings,
    lights: &MarchLights,
    x: u32,
    y: u32,
    dir: Vec3,
    s: f32,
) -> Vec4 {
    march_pixel(frame, lights, &settings.ray_march, settings.policy, x, y, dir, s)
}

/// Mirrors the `march` entry point over the whole image.
pub fn march(frame: &CpuFrame, settings: &BruteForceSettings) -> Result<(Image, TechniqueStats), Error> {
    settings.validate()?;
    let desc = frame.desc;
    let start = std::time::Instant::now();
    let lights = MarchLights::of(desc);
    let mut img = Image::new(desc.width, desc.height);
    img.pixels.par_chunks_mut(desc.width as usize).enumerate().for_each(|(y, row)| {
        for (x, px) in row.iter_mut().enumerate() {
            let (x, y) = (x as u32, y as u32);
            let dir = desc.pixel_ray(x, y);
            let s = desc.view_distance(frame.depth[(y * desc.width + x) as usize], dir);
            let l = march_ray(frame, settings, &lights, x, y, dir, s);
            // alpha: minus the ray's scattering distance (0 where it has none), for the temporal
            // stage (temporal.rs TemporalSettings::scattering_distance).
            *px = [l.x, l.y, l.z, -l.w];
        }
    });
    let stats = TechniqueStats {
        technique: "brute-force".into(),
        backend: "cpu".into(),
        timing: "wall-clock".into(),
        passes: vec![PassTime { name: "march".into(), ms: start.elapsed().as_secs_f64() * 1e3 }],
        raymarched_samples: desc.width as u64 * desc.height as u64 * settings.ray_march.steps as u64,
        gpu_memory_bytes: 0,
        extra: Default::default(),
    };
    Ok((img, stats))
}
