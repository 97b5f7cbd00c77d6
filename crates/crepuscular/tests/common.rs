//! Shared helpers for the library's integration tests.
#![allow(dead_code)]

use crepuscular::gpu::{GpuContext, UploadedFrame};
use crepuscular::techniques::brute_force::BruteForceSettings;
use crepuscular::testing::gpu_render;
use crepuscular::{CpuFrame, Image, TechniqueSettings};

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
