//! The frame boundary: everything the effect reads, in one place. A host renderer (ours in
//! `crepuscular-scene`, or a user's own) fills a [`GpuFrame`] with its camera, light, medium,
//! shadow-map projection and its own depth and shadow-map textures; the CPU backend fills a
//! [`CpuFrame`] with the same data as arrays.

use crate::camera::FrameCamera;
use crate::image::Image;
use crate::integrand::light_position;
use crate::model::{Light, Medium, RgbTexture};
use crate::shadow::{ShadowMap, ShadowProjection};
use glam::Vec3;

/// [`FrameUniforms::light_kind`] of a directional light (a sun); `LIGHT_DIRECTIONAL` in WGSL.
pub const LIGHT_DIRECTIONAL: u32 = 0;
/// [`FrameUniforms::light_kind`] of a spot light; `LIGHT_SPOT` in WGSL.
pub const LIGHT_SPOT: u32 = 1;
/// [`FrameUniforms::light_kind`] of a point light; `LIGHT_POINT` in WGSL.
pub const LIGHT_POINT: u32 = 2;
/// [`FrameUniforms::phase_kind`] of the isotropic phase function; `PHASE_ISOTROPIC` in WGSL.
pub const PHASE_ISOTROPIC: u32 = 0;
/// Henyey–Greenstein; `PHASE_HENYEY_GREENSTEIN` in WGSL.
pub const PHASE_HENYEY_GREENSTEIN: u32 = 1;
/// Rayleigh; `PHASE_RAYLEIGH` in WGSL.
pub const PHASE_RAYLEIGH: u32 = 2;
/// Hoffman–Preetham; `PHASE_HOFFMAN_PREETHAM` in WGSL.
pub const PHASE_HOFFMAN_PREETHAM: u32 = 3;

/// The per-frame uniform block shared by every shader (`struct Frame` in common.wgsl).
/// Layout is asserted against naga's view of the WGSL struct in a test.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct FrameUniforms {
    /// Clip → world of the camera.
    pub inv_view_proj: [[f32; 4]; 4],
    /// Clip → view of the camera (view rays are unprojected in view space: `ndc_ray`).
    pub inv_projection: [[f32; 4]; 4],
    /// View → world of the camera.
    pub inv_view: [[f32; 4]; 4],
    /// World → clip of the camera.
    pub view_proj: [[f32; 4]; 4],
    /// World → clip per shadow-map layer.
    pub shadow_view_proj: [[[f32; 4]; 4]; 6],
    /// Camera position (xyz), near plane (w).
    pub camera_pos: [f32; 4],
    /// Camera forward unit vector (xyz), far plane (w).
    pub camera_fwd: [f32; 4],
    /// Light position (xyz; unused for directional lights), 0 (w).
    pub light_pos: [f32; 4],
    /// Light travel direction (directional) or spot axis (xyz); cos of the spot's outer angle (w).
    pub light_dir: [f32; 4],
    /// Light colour × intensity (rgb); cos of the spot's inner angle (w).
    pub light_color: [f32; 4],
    /// σs (rgb); phase asymmetry g (w).
    pub sigma_s: [f32; 4],
    /// σa (rgb); 0 (w).
    pub sigma_a: [f32; 4],
    /// Hoffman–Preetham Rayleigh fraction per channel (rgb); 0 (w).
    pub rayleigh_fraction: [f32; 4],
    /// The shadow projection's near plane (world units).
    pub shadow_near: f32,
    /// The shadow projection's far plane (world units).
    pub shadow_far: f32,
    /// The volume shadow bias (world units, [`crate::ShadowSettings::bias`]).
    pub shadow_bias: f32,
    /// The world size of one shadow texel (at unit distance for a perspective projection).
    pub shadow_texel: f32,
    /// View depth from NDC depth d, lin = y / (d + x); z: the depth buffer's far (clear)
    /// value, 1 standard or 0 reversed-Z ([`crate::camera::FrameCamera::view_depth`]); w: the
    /// shadow map's clear value, 1 standard or 0 reversed-Z ([`ShadowProjection::depth`]).
    pub depth_params: [f32; 4],
    /// Image width, pixels.
    pub width: u32,
    /// Image height, pixels.
    pub height: u32,
    /// [`LIGHT_DIRECTIONAL`], [`LIGHT_SPOT`] or [`LIGHT_POINT`].
    pub light_kind: u32,
    /// [`PHASE_ISOTROPIC`], [`PHASE_HENYEY_GREENSTEIN`], [`PHASE_RAYLEIGH`] or
    /// [`PHASE_HOFFMAN_PREETHAM`].
    pub phase_kind: u32,
    /// Shadow-map layers (1, or 6 cube faces).
    pub shadow_layers: u32,
    /// Shadow-map side, texels.
    pub shadow_size: u32,
    /// 1 for an orthographic shadow projection (a sun), 0 for a perspective one.
    pub shadow_orthographic: u32,
    /// 1 when the spot light has a projected texture.
    pub spot_textured: u32,
}

const _: () = assert!(std::mem::size_of::<FrameUniforms>() == 832);

/// Describes a frame independently of where its textures live.
#[derive(Clone, Debug)]
pub struct FrameDesc {
    /// The camera: the engine's view and projection matrices and depth convention.
    pub camera: FrameCamera,
    /// Light.
    pub light: Light,
    /// Medium.
    pub medium: Medium,
    /// Shadow-map projection (matrices and depth range) the shadow map was rendered with.
    pub shadow: ShadowProjection,
    /// Volume shadow bias, world units (see [`crate::ShadowSettings::bias`]).
    pub shadow_bias: f32,
    /// Image width, pixels.
    pub width: u32,
    /// Image height, pixels.
    pub height: u32,
}

impl FrameDesc {
    /// Width / height.
    pub fn aspect(&self) -> f32 {
        self.width as f32 / self.height as f32
    }

    /// The uniform block for the GPU.
    pub fn uniforms(&self) -> FrameUniforms {
        let vp = self.camera.view_proj();
        let (depth_a, depth_b) = self.camera.depth_params();
        let (light_dir, cos_outer, cos_inner) = match &self.light {
            Light::Directional { direction, .. } => (direction.normalize(), 0.0, 0.0),
            Light::Spot { direction, outer_angle_degrees, inner_angle_degrees, .. } => {
                (direction.normalize(), outer_angle_degrees.to_radians().cos(), inner_angle_degrees.to_radians().cos())
            }
            Light::Point { .. } => (Vec3::ZERO, 0.0, 0.0),
        };
        let color = match &self.light {
            Light::Directional { color, intensity, .. }
            | Light::Spot { color, intensity, .. }
            | Light::Point { color, intensity, .. } => *color * *intensity,
        };
        let has_tex = matches!(&self.light, Light::Spot { texture: Some(_), .. });
        let (phase_kind, g, rf) = self.medium.phase.gpu_params();
        let v4 = |v: Vec3, w: f32| [v.x, v.y, v.z, w];
        let s = &self.shadow;
        FrameUniforms {
            inv_view_proj: vp.inverse().to_cols_array_2d(),
            inv_projection: self.camera.inv_projection().to_cols_array_2d(),
            inv_view: self.camera.inv_view().to_cols_array_2d(),
            view_proj: vp.to_cols_array_2d(),
            shadow_view_proj: s.view_proj.map(|m| m.to_cols_array_2d()),
            camera_pos: v4(self.camera.position, self.camera.near),
            camera_fwd: v4(self.camera.forward(), self.camera.far),
            light_pos: v4(light_position(&self.light), 0.0),
            light_dir: v4(light_dir, cos_outer),
            light_color: v4(color, cos_inner),
            sigma_s: v4(self.medium.scattering, g),
            sigma_a: v4(self.medium.absorption, 0.0),
            rayleigh_fraction: v4(rf, 0.0),
            shadow_near: s.near,
            shadow_far: s.far,
            shadow_bias: self.shadow_bias,
            shadow_texel: s.texel_world,
            depth_params: [depth_a, depth_b, self.camera.depth.far_value(), s.depth.far_value()],
            width: self.width,
            height: self.height,
            light_kind: self.light.kind_code(),
            phase_kind,
            shadow_layers: s.layers,
            shadow_size: s.size,
            shadow_orthographic: s.orthographic as u32,
            spot_textured: has_tex as u32,
        }
    }

    /// NDC x, y of the centre of pixel (x, y) (row 0 at the top, y up in NDC).
    pub fn pixel_ndc(&self, x: u32, y: u32) -> glam::Vec2 {
        glam::Vec2::new(
            (x as f32 + 0.5) / self.width as f32 * 2.0 - 1.0,
            1.0 - (y as f32 + 0.5) / self.height as f32 * 2.0,
        )
    }

    /// Unit direction of the view ray through the centre of pixel (x, y), computed as the
    /// shaders do (`pixel_ray` in common.wgsl; [`FrameCamera::ndc_ray`]).
    pub fn pixel_ray(&self, x: u32, y: u32) -> Vec3 {
        self.camera.ndc_ray(self.pixel_ndc(x, y))
    }

    /// Distance s along the unit view ray `dir` to the visible surface for a depth-buffer
    /// value `d` (the far distance where nothing was drawn, [`FrameCamera::view_depth`]).
    /// Mirrors `view_distance` in common.wgsl.
    pub fn view_distance(&self, d: f32, dir: Vec3) -> f32 {
        self.camera.view_depth(d) / dir.dot(self.camera.forward()).max(1e-4)
    }

    /// Distance along the unit view ray `dir` to the far distance (where the rays of empty
    /// pixels end). Mirrors `far_distance` in common.wgsl.
    pub fn far_distance(&self, dir: Vec3) -> f32 {
        self.camera.far / dir.dot(self.camera.forward()).max(1e-4)
    }
}

/// A frame on the CPU: the description plus the host renderer's images.
#[derive(Clone, Copy, Debug)]
pub struct CpuFrame<'a> {
    /// Camera, light, medium, shadow projection, size.
    pub desc: &'a FrameDesc,
    /// Camera depth buffer, [0, 1] per pixel, `width * height`, row-major from the top-left.
    pub depth: &'a [f32],
    /// The shadow map.
    pub shadow_map: &'a ShadowMap,
    /// Surface radiance (for compositing), if any.
    pub surface: Option<&'a Image>,
}

impl CpuFrame<'_> {
    /// The spot light's projected texture, if any.
    pub fn spot_texture(&self) -> Option<&RgbTexture> {
        match &self.desc.light {
            Light::Spot { texture: Some(t), .. } => Some(t),
            _ => None,
        }
    }
}

/// A frame on the GPU: the description plus views of the host renderer's textures. This is
/// what a user's own wgpu renderer passes to a technique.
#[derive(Clone, Copy, Debug)]
pub struct GpuFrame<'a> {
    /// Camera, light, medium, shadow projection, size.
    pub desc: &'a FrameDesc,
    /// Camera depth: a `D2` view of a `Depth32Float` (or `R32Float`) texture of [0, 1] depths,
    /// `width × height`. Bound as an unfilterable float texture.
    pub depth: &'a wgpu::TextureView,
    /// Shadow map: a `D2Array` view of a `Depth32Float` (or `R32Float`) texture with
    /// `shadow.layers` layers of `shadow.size²` texels.
    pub shadow_map: &'a wgpu::TextureView,
    /// The spot light's projected texture (`Rgba8UnormSrgb`/`Rgba16Float`/`Rgba32Float`, read
    /// with `textureLoad`), if the light has one.
    pub spot_texture: Option<&'a wgpu::TextureView>,
    /// A shadow map the host rasterized from the matrices of
    /// [`crate::Scattering::raster_request`] (a `D2` view of a `Depth32Float` or `R32Float`
    /// texture of the request's size): `prefiltered`'s projective rectified map (Klehm et al.
    /// 2014, §4.2). `None` (the default for a host that does not offer it): the technique
    /// resamples the ordinary shadow map instead. Other techniques ignore it.
    pub rectified_shadow_map: Option<&'a wgpu::TextureView>,
}

/// Transmittance T(s) = exp(−σt·s) to the visible surface per pixel, computed from the depth
/// buffer exactly as the composite uses it.
pub fn surface_transmittance(desc: &FrameDesc, depth: &[f32]) -> Vec<[f32; 3]> {
    let st = desc.medium.extinction();
    (0..desc.height)
        .flat_map(|y| (0..desc.width).map(move |x| (x, y)))
        .map(|(x, y)| {
            let dir = desc.pixel_ray(x, y);
            let s = desc.view_distance(depth[(y * desc.width + x) as usize], dir);
            (-st * s).exp().to_array()
        })
        .collect()
}
