//! Shared helpers for the library's integration tests.
#![allow(dead_code)]

use crepuscular::frame::FrameDesc;
use crepuscular::gpu::{GpuContext, UploadedFrame};
use crepuscular::techniques::brute_force::BruteForceSettings;
use crepuscular::testing::gpu_render;
use crepuscular::{CpuFrame, Image, Light, ShadowMap, TechniqueSettings};
use glam::{DVec3, Vec3};

/// Runs `brute-force` on the GPU over exactly the CPU frame's depth and shadow map.
pub fn gpu_brute_force(gpu: &GpuContext, frame: &CpuFrame, settings: &BruteForceSettings) -> Image {
    gpu_technique(gpu, frame, TechniqueSettings::BruteForce(settings.clone()))
}

/// Runs a GPU technique over exactly the CPU frame's depth and shadow maps.
pub fn gpu_technique(gpu: &GpuContext, frame: &CpuFrame, settings: TechniqueSettings) -> Image {
    let up = UploadedFrame::new(gpu, frame).expect("upload");
    let out = gpu.create_output_texture(frame.desc.width, frame.desc.height);
    gpu_render(gpu, settings, &up.frame(frame.desc), &out.create_view(&Default::default())).expect("render");
    gpu.read_image(&out).expect("readback")
}

/// Largest relative difference per pixel (max over RGB of |a − b| / max(|b|, floor)).
pub fn max_rel(a: &Image, b: &Image, floor: f32) -> f32 {
    a.pixels
        .iter()
        .zip(&b.pixels)
        .map(|(p, q)| (0..3).map(|c| (p[c] - q[c]).abs() / q[c].abs().max(floor)).fold(0.0, f32::max))
        .fold(0.0, f32::max)
}

/// The `w`×`h` image whose pixel (x, y) is `f(x, y)` (rgb, alpha 1): a closed form drawn.
pub fn image_of(w: u32, h: u32, f: impl Fn(u32, u32) -> DVec3) -> Image {
    let mut img = Image::new(w, h);
    for y in 0..h {
        for x in 0..w {
            let l = f(x, y);
            img.pixels[(y * w + x) as usize] = [l.x as f32, l.y as f32, l.z as f32, 1.0];
        }
    }
    img
}

/// The sun of the closed-form tests (off the view axis, coloured).
pub fn sun() -> Light {
    Light::Directional {
        direction: Vec3::new(0.3, -0.2, 1.0).normalize(),
        color: Vec3::new(1.0, 0.9, 0.8),
        intensity: 4.0,
    }
}

/// The CPU frame of one light with its shadow map.
pub fn cpu_frame<'a>(d: &'a FrameDesc, depth: &'a [f32], sm: &'a ShadowMap) -> CpuFrame<'a> {
    CpuFrame { desc: d, depth, shadow_maps: std::slice::from_ref(sm), surface: None }
}
