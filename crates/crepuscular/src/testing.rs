//! Fixtures shared by the test suites of this workspace (not part of the supported API): the
//! occluder-free "wall frame" and its closed form, docs/MODEL.md §4 rung 2, and a technique's GPU
//! frame as the tests run it.

use crate::frame::FrameDesc;
use crate::stats::TechniqueStats;
use crate::{
    Bounds, Camera, Error, FrameCamera, FrameLight, GpuContext, GpuFrame, Light, Medium, Phase, Scattering, ShadowMap,
    ShadowProjection, StatsMode, TechniqueSettings,
};
use glam::{DVec3, Vec3};

/// Distance of the wall from the camera, metres.
pub const WALL_DISTANCE: f32 = 30.0;

/// A frame looking down −Z from the origin at a wall [`WALL_DISTANCE`] away (constant depth),
/// `w × h` pixels, with an empty 64² shadow map (nothing casts shadows, V = 1). Returns the
/// description, the depth buffer and the shadow map.
pub fn wall_frame(light: Light, medium: Medium, w: u32, h: u32) -> (FrameDesc, Vec<f32>, ShadowMap) {
    let (desc, depth, mut maps) = wall_frame_lights(vec![light], medium, w, h);
    (desc, depth, maps.remove(0))
}

/// [`wall_frame`] with several lights, each with its own empty shadow map (layers packed in
/// order, [`FrameDesc::assign_layers`]).
pub fn wall_frame_lights(lights: Vec<Light>, medium: Medium, w: u32, h: u32) -> (FrameDesc, Vec<f32>, Vec<ShadowMap>) {
    let camera = Camera {
        position: Vec3::ZERO,
        look_at: Vec3::new(0.0, 0.0, -1.0),
        up: Vec3::Y,
        fov_y_degrees: 60.0,
        near: 0.1,
        far: 100.0,
    };
    let aspect = w as f32 / h as f32;
    let bounds = Bounds { min: Vec3::splat(-40.0), max: Vec3::new(40.0, 40.0, 1.0) };
    let lights: Vec<FrameLight> = lights
        .into_iter()
        .map(|light| {
            let shadow = ShadowProjection::fit(&light, &camera, aspect, bounds, 64);
            FrameLight::new(light, shadow)
        })
        .collect();
    let maps = lights
        .iter()
        .map(|l| ShadowMap { projection: l.shadow.clone(), depth: vec![1.0; l.shadow.layers as usize * 64 * 64] })
        .collect();
    // The wall's depth-buffer value at its view depth.
    let camera = FrameCamera::look_at(&camera, aspect);
    let depth = vec![camera.depth_of(WALL_DISTANCE); (w * h) as usize];
    let mut desc = FrameDesc { camera, lights, medium, width: w, height: h };
    desc.assign_layers();
    (desc, depth, maps)
}

/// The in-scattering of the frame's suns at pixel (x, y) of a [`wall_frame`], in f64: the sum
/// over the lights of σs·p·E·(1 − e^(−σt·s))/σt (σs·p·E·s where a channel's σt is 0), each
/// scaled by its `scattering`. Panics for a light that is not directional.
pub fn wall_closed_form(desc: &FrameDesc, x: u32, y: u32) -> DVec3 {
    let inv = desc.camera.view_proj().as_dmat4().inverse();
    let (w, h) = (desc.width as f64, desc.height as f64);
    let ndc = DVec3::new((x as f64 + 0.5) / w * 2.0 - 1.0, 1.0 - (y as f64 + 0.5) / h * 2.0, 1.0);
    let dir = inv.project_point3(ndc).normalize();
    let s = WALL_DISTANCE as f64 / dir.dot(DVec3::NEG_Z);
    let st = desc.medium.extinction().as_dvec3();
    let f = |st: f64| if st > 0.0 { (1.0 - (-st * s).exp()) / st } else { s };
    let mut sum = DVec3::ZERO;
    for fl in &desc.lights {
        let Light::Directional { direction, color, intensity } = &fl.light else {
            panic!("wall_closed_form: the closed form is for directional lights")
        };
        let p = DVec3::from(desc.medium.phase.eval_f64(-direction.as_dvec3().normalize().dot(dir)));
        sum += desc.medium.scattering.as_dvec3()
            * p
            * color.as_dvec3()
            * (*intensity as f64 * fl.scattering as f64)
            * DVec3::new(f(st.x), f(st.y), f(st.z));
    }
    sum
}

/// The media the closed-form tests sweep: each phase function, coloured and grey σs, with and
/// without absorption, and σt = 0 in one channel.
pub fn wall_media() -> Vec<Medium> {
    vec![
        Medium {
            scattering: Vec3::new(0.02, 0.03, 0.05),
            absorption: Vec3::splat(0.01),
            phase: Phase::HenyeyGreenstein { g: 0.7 },
        },
        Medium { scattering: Vec3::splat(0.1), absorption: Vec3::ZERO, phase: Phase::Isotropic },
        Medium { scattering: Vec3::new(0.05, 0.08, 0.12), absorption: Vec3::splat(0.02), phase: Phase::Rayleigh },
        Medium {
            scattering: Vec3::splat(0.04),
            absorption: Vec3::ZERO,
            phase: Phase::HoffmanPreetham { g: 0.76, rayleigh_fraction: Vec3::new(0.2, 0.4, 0.6) },
        },
        // σt = 0 in one channel: the closed form's limit σs·p·E·s.
        Medium {
            scattering: Vec3::new(0.0, 0.05, 0.05),
            absorption: Vec3::ZERO,
            phase: Phase::HenyeyGreenstein { g: -0.3 },
        },
    ]
}

/// `settings`' technique on `gpu` as the tests run it: [`StatsMode::WallClock`], so every frame
/// of [`Scattering::render`] has its passes timed and the GPU's counters read at once (complete
/// stats on any adapter, software ones included).
pub fn gpu_scattering(gpu: &GpuContext, settings: TechniqueSettings) -> Result<Scattering, Error> {
    Scattering::from_gpu(gpu, settings)?.with_stats(StatsMode::WallClock)
}

/// One frame of `settings`' technique on `gpu` ([`gpu_scattering`]) into `output`, waited for:
/// the [`Scattering`] (for the technique's intermediates and debug readbacks) and the stats.
pub fn gpu_render(
    gpu: &GpuContext,
    settings: TechniqueSettings,
    frame: &GpuFrame,
    output: &wgpu::TextureView,
) -> Result<(Scattering, TechniqueStats), Error> {
    let mut scattering = gpu_scattering(gpu, settings)?;
    let stats = scattering.render(frame, output)?;
    Ok((scattering, stats))
}
