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

/// The camera of the wall frames: at the origin looking down −Z, 60° vertical field of view,
/// near 0.1 m, far 100 m.
pub fn wall_camera() -> Camera {
    Camera {
        position: Vec3::ZERO,
        look_at: Vec3::new(0.0, 0.0, -1.0),
        up: Vec3::Y,
        fov_y_degrees: 60.0,
        near: 0.1,
        far: 100.0,
    }
}

/// [`wall_frame`] with several lights, each with its own empty shadow map (layers packed in
/// order, [`FrameDesc::assign_layers`]).
pub fn wall_frame_lights(lights: Vec<Light>, medium: Medium, w: u32, h: u32) -> (FrameDesc, Vec<f32>, Vec<ShadowMap>) {
    let camera = wall_camera();
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
    let camera = FrameCamera::look_at(&camera, aspect).expect("the fixed test camera is valid");
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

/// The half-plane occluder of [`half_plane_frame`]: an opaque plane y = [`HalfPlane::height`]
/// over x < [`HalfPlane::edge_x`] (world metres), lit by a sun in the y–z plane. The camera of
/// the wall frame (at the origin) sits in its shadow.
#[derive(Clone, Copy, Debug)]
pub struct HalfPlane {
    /// The plane's height above the camera, metres.
    pub height: f64,
    /// Where the shadow map's edge lies in world x: the boundary between the last texel column
    /// holding the plane and the first one without it (so the discrete map and the closed form
    /// agree on where the shadow ends).
    pub edge_x: f64,
}

/// Height of the half-plane occluder above the camera, metres.
pub const HALF_PLANE_HEIGHT: f64 = 6.0;
/// The x near which the half-plane's edge is put (then moved to a texel column boundary), metres.
pub const HALF_PLANE_EDGE: f64 = 3.0;

/// The sun of [`half_plane_frame`]: in the y–z plane (so the shadow map's columns run along
/// world z and its edge is a straight line of texel boundaries), shining towards the camera
/// from above and in front (the epipole 27° above the view axis: on screen, 60° field of view).
pub fn half_plane_sun() -> Light {
    Light::Directional {
        direction: Vec3::new(0.0, -0.5, 1.0).normalize(),
        color: Vec3::new(1.0, 0.9, 0.8),
        intensity: 4.0,
    }
}

/// The wall frame ([`wall_frame`], `w × h`) with a shadowed closed form (docs/MODEL.md §4, rung
/// 2): the [`half_plane_sun`] over the [`HalfPlane`] occluder, its `size²` shadow map written
/// texel by texel (the plane's depth along each texel centre's light ray where that centre
/// lies at x < the edge; empty elsewhere). Returns the description, the depth buffer, the
/// shadow map and the occluder.
pub fn half_plane_frame(medium: Medium, w: u32, h: u32, size: u32) -> (FrameDesc, Vec<f32>, ShadowMap, HalfPlane) {
    let camera = wall_camera();
    let aspect = w as f32 / h as f32;
    // Deep in z, so every plane point that shadows a view ray is inside the depth range.
    let bounds = Bounds { min: Vec3::new(-40.0, -40.0, -100.0), max: Vec3::new(40.0, 40.0, 1.0) };
    let light = half_plane_sun();
    let shadow = ShadowProjection::fit(&light, &camera, aspect, bounds, size);
    let inv = shadow.view_proj[0].as_dmat4().inverse();
    let n = size as f64;
    let ndc = |i: u32| (i as f64 + 0.5) / n * 2.0 - 1.0;
    // A texel's column decides its world x: the light's x axis is world ±x for a sun in the
    // y–z plane (checked here, so the edge is one column boundary).
    let world_x = |u: f64, v: f64| inv.project_point3(DVec3::new(u, v, 0.5)).x;
    assert!((world_x(0.3, -0.9) - world_x(0.3, 0.9)).abs() < 1e-6, "half_plane_frame: light x is not world x");
    let mut depth = vec![1.0f32; (size * size) as usize];
    for ty in 0..size {
        for tx in 0..size {
            let (u, v) = (ndc(tx), -ndc(ty));
            let (p0, p1) = (inv.project_point3(DVec3::new(u, v, 0.0)), inv.project_point3(DVec3::new(u, v, 1.0)));
            if p0.x < HALF_PLANE_EDGE {
                // Orthographic: depth is linear along the light ray.
                // Towards the map's corners the plane lies nearer the light than the fitted
                // depth range (outside `bounds`): clamped to the near plane. That keeps every
                // shadow test's answer: the view rays lie inside `bounds`, so deeper than the
                // near plane by at least the fit's padding (0.6 m, ≫ the bias), and below the
                // plane wherever its point is nearer the light than theirs.
                let d = (HALF_PLANE_HEIGHT - p0.y) / (p1.y - p0.y);
                assert!(d < 1.0, "half_plane_frame: the plane lies beyond the depth range ({d})");
                depth[(ty * size + tx) as usize] = d.max(0.0) as f32;
            }
        }
    }
    // The column boundary where the plane ends.
    let edge = (0..size)
        .find_map(|i| {
            let (a, b) = (world_x(ndc(i), 0.0), world_x(ndc(i + 1), 0.0));
            ((a < HALF_PLANE_EDGE) != (b < HALF_PLANE_EDGE)).then(|| world_x((i + 1) as f64 / n * 2.0 - 1.0, 0.0))
        })
        .expect("half_plane_frame: the edge is inside the map");
    let map = ShadowMap { projection: shadow.clone(), depth };
    let camera = FrameCamera::look_at(&camera, aspect).expect("the fixed test camera is valid");
    let depth = vec![camera.depth_of(WALL_DISTANCE); (w * h) as usize];
    let mut desc = FrameDesc { camera, lights: vec![FrameLight::new(light, shadow)], medium, width: w, height: h };
    desc.assign_layers();
    (desc, depth, map, HalfPlane { height: HALF_PLANE_HEIGHT, edge_x: edge })
}

/// [`half_plane_frame`] with the sun's map cut as an engine's cascade leaves it: its far plane
/// (the side away from the light) moved to `behind` metres of light depth *in front of* the
/// eye, so the first stretch of every view ray lies beyond the map's depth range, inside its
/// footprint. The map is re-encoded for the shorter range (texels whose occluder lies beyond
/// it are emptied: none of them shadows a view ray, which all lie nearer the light than the
/// eye). The closed form is unchanged — the eye is in the plane's shadow — so a technique that
/// reads the points beyond the far plane as lit gains a lit stretch at the start of each ray
/// (docs/MODEL.md §1 "Visibility").
pub fn half_plane_frame_cut(
    medium: Medium,
    w: u32,
    h: u32,
    size: u32,
    behind: f32,
) -> (FrameDesc, Vec<f32>, ShadowMap, HalfPlane) {
    let (mut desc, depth, mut map, plane) = half_plane_frame(medium, w, h, size);
    let pr = map.projection.clone();
    assert!(pr.orthographic && pr.depth == crate::camera::DepthConvention::Standard, "a standard orthographic fit");
    let eye = desc.camera.inv_view().w_axis;
    let eye_depth = pr.linear((pr.view_proj[0] * eye).z);
    let far = eye_depth - behind;
    assert!(far > pr.near + 1.0, "half_plane_frame_cut: the cut leaves no depth range ({far} m)");
    // Orthographic, standard: ndc z = (z − near)/(far − near), so the new range scales z.
    let k = (pr.far - pr.near) / (far - pr.near);
    let scale = glam::Mat4::from_scale(Vec3::new(1.0, 1.0, k));
    let mut cut = pr.clone();
    cut.view_proj = pr.view_proj.map(|m| scale * m);
    cut.far = far;
    map.depth = map.depth.iter().map(|&d| if d >= 1.0 || d * k > 1.0 { 1.0 } else { d * k }).collect();
    map.projection = cut.clone();
    desc.lights[0].shadow = cut;
    (desc, depth, map, plane)
}

impl HalfPlane {
    /// The in-scattering at pixel (x, y) of a [`half_plane_frame`], in f64. The camera sits in
    /// the shadow, which is {x < edge, y < height − bias·|d_y|} (a point is shadowed where the
    /// light ray from it meets the plane more than the light's bias away); a view ray
    /// t·r leaves it at t₁ = min(edge/r_x if r_x > 0, (height − bias·|d_y|)/r_y if r_y > 0, s)
    /// and is lit on [t₁, s]: σs·p·E·(e^(−σt·t₁) − e^(−σt·s))/σt (σs·p·E·(s − t₁) where σt = 0).
    pub fn closed_form(&self, desc: &FrameDesc, x: u32, y: u32) -> DVec3 {
        let inv = desc.camera.view_proj().as_dmat4().inverse();
        let (w, h) = (desc.width as f64, desc.height as f64);
        let ndc = DVec3::new((x as f64 + 0.5) / w * 2.0 - 1.0, 1.0 - (y as f64 + 0.5) / h * 2.0, 1.0);
        let r = inv.project_point3(ndc).normalize();
        let s = WALL_DISTANCE as f64 / r.dot(DVec3::NEG_Z);
        let fl = &desc.lights[0];
        let Light::Directional { direction, color, intensity } = &fl.light else { unreachable!() };
        let d = direction.as_dvec3().normalize();
        let top = self.height - fl.shadow_bias as f64 * d.y.abs();
        let leave = |a: f64, c: f64| if a > 0.0 { c / a } else { f64::INFINITY };
        let t1 = leave(r.x, self.edge_x).min(leave(r.y, top)).min(s);
        let st = desc.medium.extinction().as_dvec3();
        let f = |st: f64| if st > 0.0 { ((-st * t1).exp() - (-st * s).exp()) / st } else { s - t1 };
        let p = DVec3::from(desc.medium.phase.eval_f64(-d.dot(r)));
        desc.medium.scattering.as_dvec3()
            * p
            * color.as_dvec3()
            * (*intensity as f64 * fl.scattering as f64)
            * DVec3::new(f(st.x), f(st.y), f(st.z))
    }
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
