//! The host renderer on the CPU: the same shadow map, depth buffer and surface radiance as
//! `host.rs`, through the CPU rasterizer (`raster.rs`) and the library's Rust twins of the
//! surface shader (`integrand::surface_radiance`).

use crate::raster;
use crate::scene::Geometry;
use crepuscular::frame::FrameDesc;
use crepuscular::integrand::{SurfaceShading, surface_radiance};
use crepuscular::stats::PassTime;
use crepuscular::{Image, ShadowMap};
use glam::Vec3;
use rayon::prelude::*;
use std::time::Instant;

/// What the CPU host renderer produced.
pub struct CpuHost {
    /// Camera depth, [0, 1], row-major from the top-left.
    pub depth: Vec<f32>,
    /// The shadow maps, one per light of the frame.
    pub shadow_maps: Vec<ShadowMap>,
    /// Surface radiance.
    pub surface: Image,
    /// Pass times (wall clock).
    pub passes: Vec<PassTime>,
}

/// Renders every light's shadow map, depth (in the camera's depth convention) and surface
/// radiance (shaded with `shading`, lit by every light) on the CPU.
pub fn render(geometry: &Geometry, shading: &SurfaceShading, desc: &FrameDesc) -> CpuHost {
    let t0 = Instant::now();
    let shadow_maps: Vec<ShadowMap> =
        desc.lights.iter().map(|l| raster::render_shadow_map(geometry, &l.shadow)).collect();
    let frame = crepuscular::CpuFrame { desc, depth: &[], shadow_maps: &shadow_maps, surface: None };
    let t1 = Instant::now();
    let vp = desc.camera.view_proj();
    let db = raster::rasterize_with(geometry, vp, desc.width, desc.height, desc.camera.depth);
    let mut surface = Image::new(desc.width, desc.height);
    let inv = vp.inverse();
    surface.pixels.par_iter_mut().enumerate().for_each(|(i, px)| {
        let tri = db.triangle[i];
        if tri == u32::MAX {
            *px = [0.0, 0.0, 0.0, 1.0];
            return;
        }
        let b = db.bary[i];
        let idx = &geometry.indices[tri as usize * 3..tri as usize * 3 + 3];
        let v = idx.iter().map(|&k| geometry.vertices[k as usize]).collect::<Vec<_>>();
        let lerp = |f: fn(&crate::Vertex) -> [f32; 3]| {
            Vec3::from(f(&v[0])) * b[0] + Vec3::from(f(&v[1])) * b[1] + Vec3::from(f(&v[2])) * b[2]
        };
        let (x, y) = ((i as u32 % desc.width), (i as u32 / desc.width));
        // World position from the depth buffer, as the GPU's interpolated position would give.
        let p = inv.project_point3(desc.pixel_ndc(x, y).extend(db.depth[i]));
        let l = surface_radiance(&frame, shading, p, lerp(|v| v.normal), lerp(|v| v.albedo));
        *px = [l.x, l.y, l.z, 1.0];
    });
    let t2 = Instant::now();
    CpuHost {
        depth: db.depth,
        shadow_maps,
        surface,
        passes: vec![
            PassTime { name: "shadow map".into(), ms: (t1 - t0).as_secs_f64() * 1e3 },
            PassTime { name: "surface".into(), ms: (t2 - t1).as_secs_f64() * 1e3 },
        ],
    }
}
