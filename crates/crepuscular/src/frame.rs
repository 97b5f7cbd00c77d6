//! The frame boundary: everything the effect reads, in one place. A host renderer (ours in
//! `crepuscular-scene`, or a user's own) fills a [`GpuFrame`] with its camera, its lights (each
//! with its shadow-map projection), the medium and its own depth and shadow-map textures; the
//! CPU backend fills a [`CpuFrame`] with the same data as arrays.
//!
//! A frame holds any number of lights, any mix of directional, spot and point lights
//! (docs/MODEL.md §6). Every technique sums their in-scattering, L_scatt = Σ_k ∫ T·σs·p_k·L_in,k·V_k dt;
//! [`FrameDesc::scattering_lights`] says which of them reach the view at all.

use crate::camera::FrameCamera;
use crate::error::Error;
use crate::image::Image;
use crate::integrand::light_position;
use crate::march::REACH_OPTICAL_DEPTH;
use crate::model::{Light, Medium, RgbTexture};
use crate::shadow::{ShadowFilter, ShadowMap, ShadowProjection};
use glam::Vec3;

/// [`LightUniforms::kind`] of a directional light (a sun); `LIGHT_DIRECTIONAL` in WGSL.
pub const LIGHT_DIRECTIONAL: u32 = 0;
/// [`LightUniforms::kind`] of a spot light; `LIGHT_SPOT` in WGSL.
pub const LIGHT_SPOT: u32 = 1;
/// [`LightUniforms::kind`] of a point light; `LIGHT_POINT` in WGSL.
pub const LIGHT_POINT: u32 = 2;
/// [`FrameUniforms::phase_kind`] of the isotropic phase function; `PHASE_ISOTROPIC` in WGSL.
pub const PHASE_ISOTROPIC: u32 = 0;
/// Henyey–Greenstein; `PHASE_HENYEY_GREENSTEIN` in WGSL.
pub const PHASE_HENYEY_GREENSTEIN: u32 = 1;
/// Rayleigh; `PHASE_RAYLEIGH` in WGSL.
pub const PHASE_RAYLEIGH: u32 = 2;
/// Hoffman–Preetham; `PHASE_HOFFMAN_PREETHAM` in WGSL.
pub const PHASE_HOFFMAN_PREETHAM: u32 = 3;
/// The most lights one frame's uniforms hold (`MAX_LIGHTS` in WGSL): 16 lights are 7.9 KiB of
/// uniforms, inside the 16 KiB a downlevel device may bind. More is an error naming the light.
pub const MAX_LIGHTS: usize = 16;
/// [`LightUniforms::texture_layer`] of a light without a projected texture.
pub const NO_TEXTURE: u32 = u32::MAX;

/// The per-frame uniform block shared by every shader (`struct Frame` in common.wgsl): the
/// camera, the medium and the image size. The lights are in [`LightsUniforms`].
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
    /// Camera position (xyz), near plane (w).
    pub camera_pos: [f32; 4],
    /// Camera forward unit vector (xyz), far plane (w).
    pub camera_fwd: [f32; 4],
    /// σs (rgb); phase asymmetry g (w).
    pub sigma_s: [f32; 4],
    /// σa (rgb); 0 (w).
    pub sigma_a: [f32; 4],
    /// Hoffman–Preetham Rayleigh fraction per channel (rgb); 0 (w).
    pub rayleigh_fraction: [f32; 4],
    /// View depth from NDC depth d, lin = y / (d + x); z: the depth buffer's far (clear)
    /// value, 1 standard or 0 reversed-Z ([`crate::camera::FrameCamera::view_depth`]); w: 0.
    pub depth_params: [f32; 4],
    /// Image width, pixels.
    pub width: u32,
    /// Image height, pixels.
    pub height: u32,
    /// [`PHASE_ISOTROPIC`], [`PHASE_HENYEY_GREENSTEIN`], [`PHASE_RAYLEIGH`] or
    /// [`PHASE_HOFFMAN_PREETHAM`].
    pub phase_kind: u32,
    /// Padding.
    pub _pad: u32,
}

const _: () = assert!(std::mem::size_of::<FrameUniforms>() == 368);

/// One light as the shaders read it (`struct Light` in common.wgsl).
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct LightUniforms {
    /// World → clip per shadow-map layer of this light.
    pub shadow_view_proj: [[[f32; 4]; 4]; 6],
    /// Light position (xyz; unused for directional lights), 0 (w).
    pub position: [f32; 4],
    /// Light travel direction (directional) or spot axis (xyz); cos of the spot's outer angle (w).
    pub direction: [f32; 4],
    /// Light colour × intensity × [`FrameLight::scattering`] (rgb); cos of the spot's inner angle (w).
    pub color: [f32; 4],
    /// The shadow projection's near plane (world units).
    pub shadow_near: f32,
    /// The shadow projection's far plane (world units).
    pub shadow_far: f32,
    /// The volume shadow bias (world units, [`FrameLight::shadow_bias`]).
    pub shadow_bias: f32,
    /// The world size of one shadow texel (at unit distance for a perspective projection).
    pub shadow_texel: f32,
    /// [`LIGHT_DIRECTIONAL`], [`LIGHT_SPOT`] or [`LIGHT_POINT`].
    pub kind: u32,
    /// Shadow-map layers (1, or 6 cube faces).
    pub shadow_layers: u32,
    /// Shadow-map side, texels (the map sits in the top-left corner of its array layers).
    pub shadow_size: u32,
    /// 1 for an orthographic shadow projection (a sun), 0 for a perspective one.
    pub shadow_orthographic: u32,
    /// First layer of this light's shadow map in the frame's shadow-map array.
    pub shadow_first_layer: u32,
    /// The shadow map's clear value: 1 standard, 0 reversed-Z ([`ShadowProjection::depth`]).
    pub shadow_clear: f32,
    /// Layer of this spot light's projected texture in the frame's texture array, or
    /// [`NO_TEXTURE`].
    pub texture_layer: u32,
    /// This light's own index in the `Lights` block it is bound in (written by
    /// [`FrameDesc::lights_uniforms_of`]): shaders read the shadow matrix of a run-time layer
    /// through `lights.items[slot]` instead of indexing a by-value copy (common.wgsl
    /// `light_view_proj`).
    pub slot: u32,
    /// Width and height of the projected texture (texels; it sits in the top-left corner of
    /// its layer).
    pub texture_size: [u32; 2],
    /// How the volume lookups read the shadow map: [`ShadowFilter::code`].
    pub shadow_filter: u32,
    /// Padding.
    pub _pad1: u32,
}

const _: () = assert!(std::mem::size_of::<LightUniforms>() == 496);

/// The lights of a frame as the shaders read them (`struct Lights` in common.wgsl, binding
/// [`crate::techniques::pass::LIGHTS_BINDING`] of group 0): the lights that reach the view.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct LightsUniforms {
    /// How many of `items` are used.
    pub count: u32,
    /// Padding.
    pub _pad: [u32; 3],
    /// The lights, `count` of them first.
    pub items: [LightUniforms; MAX_LIGHTS],
}

/// One light of a frame: the light, the projection its shadow map was rendered with, where the
/// map's layers are in the frame's shadow-map array, and how much it scatters.
#[derive(Clone, Debug, PartialEq)]
pub struct FrameLight {
    /// The light.
    pub light: Light,
    /// Its shadow map's projection (matrices, depth range, convention, size).
    pub shadow: ShadowProjection,
    /// Volume shadow bias of this light, world units along its depth axis (see
    /// [`crate::ShadowSettings::bias`]). Default 0.02.
    pub shadow_bias: f32,
    /// How the in-scattering reads this light's shadow map: the nearest texel (binary
    /// visibility) or a 2×2 bilinear percentage-closer filter (four reads per sample instead
    /// of one; docs/MODEL.md §1 "Visibility"). Read by the reference and every step-by-step
    /// march ([`ShadowFilter`] lists them) and by `minmax`'s walk; `prefiltered`'s filtered
    /// maps keep their own visibility outside the epipole disc. Default [`ShadowFilter::Bilinear`].
    pub shadow_filter: ShadowFilter,
    /// First layer of this light's shadow map in the frame's shadow-map array
    /// ([`GpuFrame::shadow_maps`]); the map takes `shadow.layers` layers from there. Default 0.
    pub shadow_layer: u32,
    /// Layer of this spot light's projected texture in [`GpuFrame::spot_textures`] (ignored
    /// for a light without one). Default 0.
    pub texture_layer: u32,
    /// Scale of this light's in-scattering, as engines offer per light ("volumetric scattering
    /// intensity"): 1 scatters as the light shines, 0 opts the light out (it still lights the
    /// host's surfaces, and costs the effect nothing). Must be finite and ≥ 0. Default 1.
    pub scattering: f32,
}

impl FrameLight {
    /// `light` with its shadow projection, bias 0.02, the bilinear filter, layers 0,
    /// scattering 1.
    pub fn new(light: Light, shadow: ShadowProjection) -> Self {
        Self {
            light,
            shadow,
            shadow_bias: 0.02,
            shadow_filter: ShadowFilter::Bilinear,
            shadow_layer: 0,
            texture_layer: 0,
            scattering: 1.0,
        }
    }

    /// The spot light's projected texture, if any.
    pub fn spot_texture(&self) -> Option<&RgbTexture> {
        match &self.light {
            Light::Spot { texture: Some(t), .. } => Some(t),
            _ => None,
        }
    }

    /// As the shaders read it.
    pub fn uniforms(&self) -> LightUniforms {
        let v4 = |v: Vec3, w: f32| [v.x, v.y, v.z, w];
        let (dir, cos_outer, cos_inner) = match &self.light {
            Light::Directional { direction, .. } => (direction.normalize(), 0.0, 0.0),
            Light::Spot { direction, outer_angle_degrees, inner_angle_degrees, .. } => {
                (direction.normalize(), outer_angle_degrees.to_radians().cos(), inner_angle_degrees.to_radians().cos())
            }
            Light::Point { .. } => (Vec3::ZERO, 0.0, 0.0),
        };
        let color = self.light.radiance_scale() * self.scattering;
        let s = &self.shadow;
        let tex = self.spot_texture();
        LightUniforms {
            shadow_view_proj: s.view_proj.map(|m| m.to_cols_array_2d()),
            position: v4(light_position(&self.light), 0.0),
            direction: v4(dir, cos_outer),
            color: v4(color, cos_inner),
            shadow_near: s.near,
            shadow_far: s.far,
            shadow_bias: self.shadow_bias,
            shadow_texel: s.texel_world,
            kind: self.light.kind_code(),
            shadow_layers: s.layers,
            shadow_size: s.size,
            shadow_orthographic: s.orthographic as u32,
            shadow_first_layer: self.shadow_layer,
            shadow_clear: s.depth.far_value(),
            texture_layer: if tex.is_some() { self.texture_layer } else { NO_TEXTURE },
            slot: 0,
            texture_size: tex.map_or([0, 0], |t| [t.width, t.height]),
            shadow_filter: self.shadow_filter.code(),
            _pad1: 0,
        }
    }
}

/// Describes a frame independently of where its textures live.
#[derive(Clone, Debug)]
pub struct FrameDesc {
    /// The camera: the engine's view and projection matrices and depth convention.
    pub camera: FrameCamera,
    /// The lights, each with its shadow map (at least one; at most [`MAX_LIGHTS`] that scatter).
    pub lights: Vec<FrameLight>,
    /// Medium.
    pub medium: Medium,
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

    /// The camera, medium and size uniform block for the GPU.
    pub fn uniforms(&self) -> FrameUniforms {
        let vp = self.camera.view_proj();
        let (depth_a, depth_b) = self.camera.depth_params();
        let (phase_kind, g, rf) = self.medium.phase.gpu_params();
        let v4 = |v: Vec3, w: f32| [v.x, v.y, v.z, w];
        FrameUniforms {
            inv_view_proj: vp.inverse().to_cols_array_2d(),
            inv_projection: self.camera.inv_projection().to_cols_array_2d(),
            inv_view: self.camera.inv_view().to_cols_array_2d(),
            view_proj: vp.to_cols_array_2d(),
            camera_pos: v4(self.camera.position, self.camera.near),
            camera_fwd: v4(self.camera.forward(), self.camera.far),
            sigma_s: v4(self.medium.scattering, g),
            sigma_a: v4(self.medium.absorption, 0.0),
            rayleigh_fraction: v4(rf, 0.0),
            depth_params: [depth_a, depth_b, self.camera.depth.far_value(), 0.0],
            width: self.width,
            height: self.height,
            phase_kind,
            _pad: 0,
        }
    }

    /// The lights that reach the view ([`FrameDesc::scattering_lights`]) as the shaders read
    /// them. Call [`FrameDesc::validate_lights`] first: more than [`MAX_LIGHTS`] are cut.
    pub fn lights_uniforms(&self) -> LightsUniforms {
        self.lights_uniforms_of(&self.scattering_lights())
    }

    /// The lights `indices` of [`FrameDesc::lights`] as the shaders read them (the host's
    /// surface shading reads every light, the effect only those that scatter).
    pub fn lights_uniforms_of(&self, indices: &[usize]) -> LightsUniforms {
        let mut u = LightsUniforms::zeroed_lights();
        for (slot, &k) in indices.iter().take(MAX_LIGHTS).enumerate() {
            u.items[slot] = self.lights[k].uniforms();
            u.items[slot].slot = slot as u32;
        }
        u.count = indices.len().min(MAX_LIGHTS) as u32;
        u
    }

    /// The indices of the lights whose in-scattering can reach a view ray, in order: a light
    /// with [`FrameLight::scattering`] 0 or no radiance costs nothing, nor does a local light
    /// whose reach (the distance where its light path's transmittance falls below 1e-6,
    /// [`crate::march::light_reach`]) or spot cone lies wholly outside the view frustum
    /// between the camera's near and far planes. Culling is conservative: a light left out
    /// adds exactly nothing to any ray the techniques march (their march intervals already end
    /// at the reach).
    pub fn scattering_lights(&self) -> Vec<usize> {
        (0..self.lights.len()).filter(|&k| self.reaches_view(k)).collect()
    }

    /// True when light `k` may scatter into the view (see [`FrameDesc::scattering_lights`]).
    pub fn reaches_view(&self, k: usize) -> bool {
        let fl = &self.lights[k];
        if fl.scattering <= 0.0 || fl.light.radiance_scale().max_element() <= 0.0 {
            return false;
        }
        if self.medium.scattering.max_element() <= 0.0 {
            return false;
        }
        let (position, cone) = match &fl.light {
            Light::Directional { .. } => return true,
            Light::Point { position, .. } => (*position, None),
            Light::Spot { position, direction, outer_angle_degrees, .. } => {
                (*position, Some((direction.normalize(), outer_angle_degrees.to_radians())))
            }
        };
        let corners = self.camera.frustum_corners(self.camera.near, self.camera.far);
        if corners.iter().any(|c| !c.is_finite()) {
            return true;
        }
        let sigma = self.medium.extinction().min_element();
        let reach = if sigma > 0.0 { REACH_OPTICAL_DEPTH / sigma } else { f32::INFINITY };
        // The view frustum's six planes, normals pointing inwards (towards the centroid).
        let centroid = corners.iter().copied().sum::<Vec3>() / 8.0;
        let faces = [[0, 1, 2], [4, 6, 5], [0, 4, 1], [1, 5, 2], [2, 6, 3], [3, 7, 0]];
        let planes = faces.map(|[a, b, c]| {
            let n = (corners[b] - corners[a]).cross(corners[c] - corners[a]).normalize_or_zero();
            let n = if n.dot(centroid - corners[a]) < 0.0 { -n } else { n };
            (n, -n.dot(corners[a]))
        });
        let outside = |dist_max: f32| dist_max < 0.0;
        match cone {
            None => !planes.iter().any(|(n, d)| outside(n.dot(position) + d + reach)),
            Some((axis, half)) => {
                // The cone up to the farthest point of the frustum (or the reach, if nearer) lies
                // in the convex hull of its apex and the disc where it ends.
                let far = corners.iter().map(|c| (*c - position).length()).fold(0.0f32, f32::max);
                let len = far.min(reach);
                let disc = position + axis * len;
                let radius = len * half.tan();
                !planes.iter().any(|(n, d)| {
                    let apex = n.dot(position) + d;
                    let rim = n.dot(disc) + d + radius * (1.0 - n.dot(axis).powi(2)).max(0.0).sqrt();
                    outside(apex.max(rim))
                })
            }
        }
    }

    /// Packs the lights' shadow maps and spot textures into arrays, in light order: light k's
    /// shadow map starts after the layers of lights 0..k, the i-th textured spot light's
    /// texture is layer i. What this repository's hosts do; an engine with its own arrays sets
    /// [`FrameLight::shadow_layer`] and [`FrameLight::texture_layer`] itself.
    pub fn assign_layers(&mut self) {
        let (mut layer, mut texture) = (0, 0);
        for fl in &mut self.lights {
            fl.shadow_layer = layer;
            layer += fl.shadow.layers;
            if fl.spot_texture().is_some() {
                fl.texture_layer = texture;
                texture += 1;
            }
        }
    }

    /// The shadow-map array the lights' layers need: (side, layers).
    pub fn shadow_array_extent(&self) -> (u32, u32) {
        let size = self.lights.iter().map(|l| l.shadow.size).max().unwrap_or(1);
        let layers = self.lights.iter().map(|l| l.shadow_layer + l.shadow.layers).max().unwrap_or(1);
        (size, layers)
    }

    /// This frame with only light `k` (what a technique that runs once per light renders).
    pub fn with_light(&self, k: usize) -> FrameDesc {
        FrameDesc { lights: vec![self.lights[k].clone()], ..self.clone() }
    }

    /// The only light of a one-light frame ([`FrameDesc::with_light`]): what the techniques
    /// that run once per light read. An error naming the count otherwise.
    pub fn single_light(&self) -> Result<&FrameLight, Error> {
        match self.lights.as_slice() {
            [one] => Ok(one),
            many => Err(Error::invalid(
                "lights",
                many.len(),
                "this technique renders one light per call (crate::Scattering sums several)",
            )),
        }
    }

    /// Checks the medium ([`Medium::validate`](crate::Medium::validate)) and the light list:
    /// not empty, every light's own fields ([`Light::validate`](crate::Light::validate)) and
    /// shadow projection ([`ShadowProjection::validate`](crate::ShadowProjection::validate))
    /// sound and matching its kind (one layer, six for a point light), scattering finite and
    /// ≥ 0, bias finite and ≥ 0, at most [`MAX_LIGHTS`] reaching the view. The error names the
    /// field (`medium.scattering`, `lights[k].…`). NaN or a negative coefficient never reaches
    /// the passes.
    pub fn validate_lights(&self) -> Result<(), Error> {
        self.medium.validate()?;
        if self.lights.is_empty() {
            return Err(Error::invalid("lights", "[]", "a frame needs at least one light"));
        }
        for (k, fl) in self.lights.iter().enumerate() {
            fl.light.validate(&format!("lights[{k}]"))?;
            fl.shadow.validate(&format!("lights[{k}].shadow"))?;
            let layers = fl.light.shadow_layers();
            if fl.shadow.layers != layers {
                return Err(Error::invalid(
                    format!("lights[{k}].shadow.layers"),
                    fl.shadow.layers,
                    format!("a {} light's shadow map has {layers} layer(s)", fl.light.kind_name()),
                ));
            }
            if !(fl.scattering.is_finite() && fl.scattering >= 0.0) {
                return Err(Error::invalid(format!("lights[{k}].scattering"), fl.scattering, "must be finite and ≥ 0"));
            }
            if !(fl.shadow_bias.is_finite() && fl.shadow_bias >= 0.0) {
                return Err(Error::invalid(
                    format!("lights[{k}].shadow_bias"),
                    fl.shadow_bias,
                    "must be finite and ≥ 0",
                ));
            }
            if fl.shadow.size == 0 {
                return Err(Error::invalid(format!("lights[{k}].shadow.size"), 0, "must be at least 1"));
            }
        }
        let n = self.scattering_lights().len();
        if n > MAX_LIGHTS {
            let k = self.scattering_lights()[MAX_LIGHTS];
            return Err(Error::invalid(
                format!("lights[{k}]"),
                format!("{n} lights reach the view"),
                format!("at most {MAX_LIGHTS} lights can scatter in one frame (opt the others out: scattering = 0)"),
            ));
        }
        Ok(())
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

impl LightsUniforms {
    /// No lights.
    pub fn zeroed_lights() -> Self {
        bytemuck::Zeroable::zeroed()
    }
}

/// A frame on the CPU: the description plus the host renderer's images.
#[derive(Clone, Copy, Debug)]
pub struct CpuFrame<'a> {
    /// Camera, lights, medium, size.
    pub desc: &'a FrameDesc,
    /// Camera depth buffer, [0, 1] per pixel, `width * height`, row-major from the top-left.
    pub depth: &'a [f32],
    /// The shadow maps, one per light of `desc.lights`, in the same order.
    pub shadow_maps: &'a [ShadowMap],
    /// Surface radiance (for compositing), if any.
    pub surface: Option<&'a Image>,
}

impl CpuFrame<'_> {
    /// Checks the lights ([`FrameDesc::validate_lights`]) and that there is one shadow map per
    /// light, made with that light's projection.
    pub fn validate(&self) -> Result<(), Error> {
        self.desc.validate_lights()?;
        if self.shadow_maps.len() != self.desc.lights.len() {
            return Err(Error::invalid(
                "shadow_maps",
                self.shadow_maps.len(),
                format!("one shadow map per light: the frame has {} light(s)", self.desc.lights.len()),
            ));
        }
        for (k, (sm, fl)) in self.shadow_maps.iter().zip(&self.desc.lights).enumerate() {
            let p = &sm.projection;
            let n = p.layers as usize * p.size as usize * p.size as usize;
            if p != &fl.shadow || sm.depth.len() != n {
                return Err(Error::invalid(
                    format!("shadow_maps[{k}]"),
                    format!("{} layer(s) of {}² texels, {} depths", p.layers, p.size, sm.depth.len()),
                    format!(
                        "must be rendered with lights[{k}]'s shadow projection ({} layer(s) of {}²)",
                        fl.shadow.layers, fl.shadow.size
                    ),
                ));
            }
        }
        Ok(())
    }

    /// Light `k`'s own frame: `desc` (from [`FrameDesc::with_light`]) with its shadow map.
    pub fn with_light<'b>(&'b self, desc: &'b FrameDesc, k: usize) -> CpuFrame<'b> {
        CpuFrame { desc, depth: self.depth, shadow_maps: &self.shadow_maps[k..k + 1], surface: self.surface }
    }
}

/// A frame on the GPU: the description plus views of the host renderer's textures. This is
/// what a user's own wgpu renderer passes to a technique.
#[derive(Clone, Copy, Debug)]
pub struct GpuFrame<'a> {
    /// Camera, lights, medium, size.
    pub desc: &'a FrameDesc,
    /// Camera depth: a `D2` view of a `Depth32Float` (or `R32Float`) texture of [0, 1] depths,
    /// `width × height`. Bound as an unfilterable float texture.
    pub depth: &'a wgpu::TextureView,
    /// Every light's shadow map in one `D2Array` view of a `Depth32Float` (or `R32Float`)
    /// texture: light k's map in layers `shadow_layer .. shadow_layer + shadow.layers`, in the
    /// top-left `shadow.size²` texels of each (so lights may differ in size up to the
    /// texture's).
    pub shadow_maps: &'a wgpu::TextureView,
    /// The spot lights' projected textures in one `D2Array` view (`Rgba8UnormSrgb`,
    /// `Rgba16Float` or `Rgba32Float`, read with `textureLoad`): a light's in layer
    /// `texture_layer`, in the top-left corner of its size. None when no light has one.
    pub spot_textures: Option<&'a wgpu::TextureView>,
    /// Shadow maps the host rasterized from the matrices of
    /// [`crate::Scattering::raster_requests`], one per light of `desc.lights` (a `D2` view of a
    /// `Depth32Float` or `R32Float` texture of the request's size, or None): `prefiltered`'s
    /// projective rectified maps (Klehm et al. 2014, §4.2). Empty (the default for a host that
    /// does not offer it): the technique resamples the ordinary shadow maps instead. Other
    /// techniques ignore it.
    pub rectified_shadow_maps: &'a [Option<&'a wgpu::TextureView>],
}

impl<'a> GpuFrame<'a> {
    /// The pipelines' variant for this frame's lights ([`crate::techniques::pass::ShaderVariant::of`]).
    pub fn shader_variant(&self) -> crate::techniques::pass::ShaderVariant {
        crate::techniques::pass::ShaderVariant::of(self.desc)
    }

    /// Light `k`'s own frame: `desc` (from [`FrameDesc::with_light`]) over the same textures.
    pub fn with_light<'b>(&'b self, desc: &'b FrameDesc, k: usize) -> GpuFrame<'b> {
        GpuFrame { desc, rectified_shadow_maps: self.rectified_shadow_maps.get(k..k + 1).unwrap_or(&[]), ..*self }
    }

    /// The host's rectified raster of this frame's only light, if it gave one.
    pub fn rectified_shadow_map(&self) -> Option<&'a wgpu::TextureView> {
        self.rectified_shadow_maps.first().copied().flatten()
    }
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
