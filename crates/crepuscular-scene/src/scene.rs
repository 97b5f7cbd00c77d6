//! The scene: what the host renderer draws and the effect lights.

use crepuscular::{Bounds, Camera, FrameDesc, FrameLight, Light, Medium, ShadowProjection, ShadowSettings};
use glam::Vec3;
use std::collections::BTreeMap;

/// One vertex as the GPU host renderer reads it (triangle lists, 36 bytes).
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct Vertex {
    /// World-space position.
    pub position: [f32; 3],
    /// World-space unit normal.
    pub normal: [f32; 3],
    /// Lambert albedo, linear RGB in [0, 1].
    pub albedo: [f32; 3],
}

/// All geometry of a scene, already in world space, as one indexed triangle list.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Geometry {
    /// Vertices.
    pub vertices: Vec<Vertex>,
    /// Three indices per triangle.
    pub indices: Vec<u32>,
}

impl Geometry {
    /// Number of triangles.
    pub fn triangle_count(&self) -> usize {
        self.indices.len() / 3
    }
    /// Appends another geometry.
    pub fn append(&mut self, other: &Geometry) {
        let base = self.vertices.len() as u32;
        self.vertices.extend_from_slice(&other.vertices);
        self.indices.extend(other.indices.iter().map(|i| i + base));
    }
    /// World-space bounds (a unit box at the origin when empty).
    pub fn bounds(&self) -> Bounds {
        if self.vertices.is_empty() {
            return Bounds { min: Vec3::splat(-1.0), max: Vec3::splat(1.0) };
        }
        let mut min = Vec3::splat(f32::MAX);
        let mut max = Vec3::splat(f32::MIN);
        for v in &self.vertices {
            let p = Vec3::from(v.position);
            min = min.min(p);
            max = max.max(p);
        }
        Bounds { min, max }
    }
}

/// Host-renderer and output settings of a scene (`[render]` in a scene file).
#[derive(Clone, Debug, PartialEq)]
pub struct RenderSettings {
    /// Output width in pixels. Default 960.
    pub width: u32,
    /// Output height in pixels. Default 540.
    pub height: u32,
    /// Shadow-map settings (`shadow_map_size`, `shadow_bias`, `shadow_filter`).
    pub shadow: ShadowSettings,
    /// Ambient radiance added to surfaces (times albedo), linear RGB. Default 0.03.
    pub ambient: Vec3,
    /// Exposure multiplier applied before the tone curve. Default 1.
    pub exposure: f32,
    /// Technique-specific tables, e.g. `[render.brute-force]`, keyed by technique name; each
    /// technique parses its own with serde.
    pub techniques: BTreeMap<String, toml::Table>,
}

impl Default for RenderSettings {
    fn default() -> Self {
        Self {
            width: 960,
            height: 540,
            shadow: ShadowSettings::default(),
            ambient: Vec3::splat(0.03),
            exposure: 1.0,
            techniques: BTreeMap::new(),
        }
    }
}

/// A complete scene.
#[derive(Clone, Debug)]
pub struct Scene {
    /// Short name (built-in name or file stem).
    pub name: String,
    /// One line describing it.
    pub description: String,
    /// Camera.
    pub camera: Camera,
    /// Medium.
    pub medium: Medium,
    /// The lights (at least one): a scene file's `[[lights]]` (or its one `[light]`).
    pub lights: Vec<SceneLight>,
    /// World-space triangles.
    pub geometry: Geometry,
    /// Render settings.
    pub render: RenderSettings,
}

/// One light of a scene and how much it scatters.
#[derive(Clone, Debug, PartialEq)]
pub struct SceneLight {
    /// The light.
    pub light: Light,
    /// Scale of its in-scattering (`scattering` in its `[[lights]]` table): 1 as it shines,
    /// 0 opts it out of the effect (it still lights surfaces). Finite, ≥ 0. Default 1.
    pub scattering: f32,
}

impl SceneLight {
    /// `light`, scattering as it shines.
    pub fn new(light: Light) -> Self {
        Self { light, scattering: 1.0 }
    }
}

impl From<Light> for SceneLight {
    fn from(light: Light) -> Self {
        Self::new(light)
    }
}

impl Scene {
    /// The frame description of the scene at its render size: its camera, each light with
    /// its shadow projection fitted to the geometry ([`ShadowProjection::fit`], the scene's
    /// shadow size and bias), layers packed in light order. Errors: a camera that fails
    /// [`crepuscular::Camera::validate`] or a zero render size (a scene built in code; scene
    /// files are checked when loaded).
    pub fn frame_desc(&self) -> Result<FrameDesc, crepuscular::Error> {
        let r = &self.render;
        if r.width == 0 || r.height == 0 {
            return Err(crepuscular::Error::invalid("render size", format!("{}x{}", r.width, r.height), "must be > 0"));
        }
        let aspect = r.width as f32 / r.height as f32;
        let camera = crepuscular::FrameCamera::look_at(&self.camera, aspect)?;
        let bounds = self.geometry.bounds();
        let lights = self
            .lights
            .iter()
            .map(|l| {
                let shadow = ShadowProjection::fit(&l.light, &self.camera, aspect, bounds, r.shadow.size);
                FrameLight {
                    shadow_bias: r.shadow.bias,
                    shadow_filter: r.shadow.filter,
                    scattering: l.scattering,
                    ..FrameLight::new(l.light.clone(), shadow)
                }
            })
            .collect();
        let mut desc = FrameDesc { camera, lights, medium: self.medium.clone(), width: r.width, height: r.height };
        desc.assign_layers();
        Ok(desc)
    }

    /// How the host renderer shades the scene's surfaces (`render.ambient`,
    /// `render.shadow_normal_offset_texels`).
    pub fn shading(&self) -> crepuscular::integrand::SurfaceShading {
        crepuscular::integrand::SurfaceShading {
            ambient: self.render.ambient,
            normal_offset_texels: self.render.shadow.normal_offset_texels,
        }
    }
}
