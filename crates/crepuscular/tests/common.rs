//! Shared helpers for the library's integration tests.
#![allow(dead_code)]

use crepuscular::frame::FrameDesc;
use crepuscular::gpu::GpuContext;
use crepuscular::techniques::brute_force::{BruteForce, BruteForceSettings};
use crepuscular::{CpuFrame, GpuFrame, Image};

/// Runs `brute-force` on the GPU over exactly the CPU frame's depth and shadow map (uploaded as
/// `R32Float` textures), so GPU and CPU see identical inputs.
pub fn gpu_brute_force(gpu: &GpuContext, frame: &CpuFrame, settings: &BruteForceSettings) -> Image {
    let d = frame.desc;
    let depth = gpu.upload_texture("depth", wgpu::TextureFormat::R32Float, d.width, d.height, 1, 4, bytemuck::cast_slice(frame.depth));
    let sp = &frame.shadow_map.projection;
    let shadow = gpu.upload_texture(
        "shadow",
        wgpu::TextureFormat::R32Float,
        sp.size,
        sp.size,
        sp.layers,
        4,
        bytemuck::cast_slice(&frame.shadow_map.depth),
    );
    let spot = frame.spot_texture().map(|t| gpu.upload_rgb_texture(Some(t)));
    let spot_view = spot.as_ref().map(|t| t.create_view(&Default::default()));
    let out = gpu.create_output_texture(d.width, d.height);
    let depth_view = depth.create_view(&Default::default());
    let shadow_view = shadow.create_view(&wgpu::TextureViewDescriptor {
        dimension: Some(wgpu::TextureViewDimension::D2Array),
        ..Default::default()
    });
    let gframe = GpuFrame { desc: d, depth: &depth_view, shadow_map: &shadow_view, spot_texture: spot_view.as_ref() };
    let mut bf = BruteForce::new(gpu, settings.clone()).expect("pipeline");
    bf.render(gpu, &gframe, &out.create_view(&Default::default())).expect("render");
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

/// Unused-desc guard so `FrameDesc` stays imported for helpers that need it.
pub fn pixels(d: &FrameDesc) -> usize {
    (d.width * d.height) as usize
}
