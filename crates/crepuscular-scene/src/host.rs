//! The host renderer: what a game engine would already have before the effect runs — shadow
//! maps, the camera depth buffer and lit surface colour — on the GPU (this file) and on the CPU
//! (`host_cpu`), with the same conventions (see `raster.rs`).

use crate::scene::{Geometry, Vertex};
use crepuscular::frame::FrameDesc;
use crepuscular::gpu::{GpuContext, Recorder};
use crepuscular::integrand::SurfaceShading;
use crepuscular::stats::PassTime;
use crepuscular::techniques::prefiltered::raster::RectifiedRaster;
use crepuscular::{DepthConvention, Error, GpuFrame, ShadowMap};
use std::sync::OnceLock;
use wgpu::util::DeviceExt;

/// Shadow-map depth shader.
pub const SHADOW_DEPTH_WGSL: &str = include_str!("shaders/shadow_depth.wgsl");
/// Surface shader (composed with the library's common.wgsl).
pub const SURFACE_WGSL: &str = include_str!("shaders/surface.wgsl");
/// Depth shader of the rectified shadow map (`prefiltered`), with both depth-clamping paths.
pub const RECTIFIED_DEPTH_WGSL: &str = include_str!("shaders/rectified_depth.wgsl");

/// The host renderer's pipelines and the scene's vertex data on the GPU.
pub struct GpuHost {
    /// Shadow-map depth for the standard and the reversed-Z convention (their depth tests).
    shadow_pipelines: [wgpu::RenderPipeline; 2],
    shadow_layout: wgpu::BindGroupLayout,
    /// Standard and reversed-Z depth tests.
    surface_pipelines: [wgpu::RenderPipeline; 2],
    surface_layout: wgpu::BindGroupLayout,
    /// How surfaces are shaded (ambient, normal offset): the scene's ([`GpuHost::for_scene`])
    /// or the defaults ([`GpuHost::new`]).
    pub shading: SurfaceShading,
    vertices: wgpu::Buffer,
    indices: wgpu::Buffer,
    index_count: u32,
    /// Rectified shadow-map pipelines, built on first use: with `unclipped_depth` (hardware
    /// depth clamping) and with depth clamped in the fragment shader.
    rectified_unclipped: OnceLock<wgpu::RenderPipeline>,
    rectified_shader_clamp: OnceLock<wgpu::RenderPipeline>,
}

/// What the host renderer produced for a frame: the textures the effect reads.
pub struct HostTextures {
    /// Camera depth, `Depth32Float`, [0, 1].
    pub depth: wgpu::Texture,
    /// Surface radiance, `Rgba32Float`, linear.
    pub surface: wgpu::Texture,
    /// Every light's shadow map, one `Depth32Float` array (light k's layers from its
    /// `shadow_layer`, [`FrameDesc::assign_layers`]).
    pub shadow_maps: wgpu::Texture,
    /// The spot lights' projected textures, one array (1×1 white when no light has one).
    pub spot_textures: wgpu::Texture,
    /// Host pass times.
    pub passes: Vec<PassTime>,
}

impl HostTextures {
    /// `D2Array` view of the shadow maps, as the effect binds it.
    pub fn shadow_view(&self) -> wgpu::TextureView {
        shadow_array_view(&self.shadow_maps)
    }
    /// View of the depth buffer.
    pub fn depth_view(&self) -> wgpu::TextureView {
        self.depth
            .create_view(&wgpu::TextureViewDescriptor { aspect: wgpu::TextureAspect::DepthOnly, ..Default::default() })
    }
    /// The views a technique binds; [`HostViews::frame`] makes the [`GpuFrame`] of them.
    pub fn views(&self) -> HostViews {
        HostViews {
            depth: self.depth_view(),
            shadow_maps: self.shadow_view(),
            spot_textures: self.spot_textures.create_view(&wgpu::TextureViewDescriptor {
                dimension: Some(wgpu::TextureViewDimension::D2Array),
                ..Default::default()
            }),
        }
    }
}

/// Views of a frame's host textures, as a technique binds them.
pub struct HostViews {
    depth: wgpu::TextureView,
    shadow_maps: wgpu::TextureView,
    spot_textures: wgpu::TextureView,
}

impl HostViews {
    /// The frame a technique renders: these views for `desc`, with the spot textures only when
    /// a light of `desc` is a spot with a texture (the host binds a 1×1 white one otherwise).
    pub fn frame<'a>(&'a self, desc: &'a FrameDesc) -> GpuFrame<'a> {
        let textured = desc.lights.iter().any(|l| l.spot_texture().is_some());
        GpuFrame {
            desc,
            depth: &self.depth,
            shadow_maps: &self.shadow_maps,
            spot_textures: textured.then_some(&self.spot_textures),
            rectified_shadow_maps: &[],
        }
    }
}

/// All layers of a shadow map as the `D2Array` depth view that shaders bind.
fn shadow_array_view(shadow_map: &wgpu::Texture) -> wgpu::TextureView {
    shadow_map.create_view(&wgpu::TextureViewDescriptor {
        dimension: Some(wgpu::TextureViewDimension::D2Array),
        aspect: wgpu::TextureAspect::DepthOnly,
        ..Default::default()
    })
}

const VERTEX_ATTRIBUTES: [wgpu::VertexAttribute; 3] =
    wgpu::vertex_attr_array![0 => Float32x3, 1 => Float32x3, 2 => Float32x3];

/// The vertex and index buffers of `geometry` and its index count; wgpu refuses zero-sized
/// buffers, so an empty scene gets one degenerate triangle.
fn upload_geometry(device: &wgpu::Device, geometry: &Geometry) -> (wgpu::Buffer, wgpu::Buffer, u32) {
    let (verts, idx): (Vec<Vertex>, Vec<u32>) = if geometry.indices.is_empty() {
        (vec![Vertex { position: [0.0; 3], normal: [0.0, 1.0, 0.0], albedo: [0.0; 3] }; 3], vec![0, 0, 0])
    } else {
        (geometry.vertices.clone(), geometry.indices.clone())
    };
    let vertices = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: Some("scene vertices"),
        contents: bytemuck::cast_slice(&verts),
        usage: wgpu::BufferUsages::VERTEX,
    });
    let indices = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: Some("scene indices"),
        contents: bytemuck::cast_slice(&idx),
        usage: wgpu::BufferUsages::INDEX,
    });
    (vertices, indices, idx.len() as u32)
}

impl GpuHost {
    /// [`GpuHost::new`] for `scene`'s geometry, shading its surfaces as the scene says.
    pub fn for_scene(gpu: &GpuContext, scene: &crate::Scene) -> Result<Self, Error> {
        let mut host = Self::new(gpu, &scene.geometry)?;
        host.shading = scene.shading();
        Ok(host)
    }

    /// Uploads the geometry and builds the pipelines (surfaces shaded with the default
    /// [`SurfaceShading`]).
    pub fn new(gpu: &GpuContext, geometry: &Geometry) -> Result<Self, Error> {
        gpu.scoped("creating the host renderer", || {
            let device = &gpu.device;
            let vertex_layout = wgpu::VertexBufferLayout {
                array_stride: std::mem::size_of::<Vertex>() as u64,
                step_mode: wgpu::VertexStepMode::Vertex,
                attributes: &VERTEX_ATTRIBUTES,
            };
            let uniform_entry = |binding, visibility| wgpu::BindGroupLayoutEntry {
                binding,
                visibility,
                ty: wgpu::BindingType::Buffer {
                    ty: wgpu::BufferBindingType::Uniform,
                    has_dynamic_offset: false,
                    min_binding_size: None,
                },
                count: None,
            };
            let shadow_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
                label: Some("shadow layer"),
                entries: &[uniform_entry(0, wgpu::ShaderStages::VERTEX)],
            });
            let shadow_module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
                label: Some("host/shadow_depth.wgsl"),
                source: wgpu::ShaderSource::Wgsl(SHADOW_DEPTH_WGSL.into()),
            });
            let depth_state = wgpu::DepthStencilState {
                format: wgpu::TextureFormat::Depth32Float,
                depth_write_enabled: Some(true),
                depth_compare: Some(wgpu::CompareFunction::Less),
                stencil: Default::default(),
                bias: Default::default(),
            };
            let primitive = wgpu::PrimitiveState { cull_mode: None, ..Default::default() };
            let shadow_pipeline = |compare: wgpu::CompareFunction| {
                device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
                    label: Some("shadow depth"),
                    layout: Some(&device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
                        label: Some("shadow depth"),
                        bind_group_layouts: &[Some(&shadow_layout)],
                        immediate_size: 0,
                    })),
                    vertex: wgpu::VertexState {
                        module: &shadow_module,
                        entry_point: Some("vs"),
                        compilation_options: Default::default(),
                        buffers: &[wgpu::VertexBufferLayout {
                            array_stride: std::mem::size_of::<Vertex>() as u64,
                            step_mode: wgpu::VertexStepMode::Vertex,
                            attributes: &VERTEX_ATTRIBUTES[..1],
                        }],
                    },
                    primitive,
                    depth_stencil: Some(wgpu::DepthStencilState {
                        depth_compare: Some(compare),
                        ..depth_state.clone()
                    }),
                    multisample: Default::default(),
                    fragment: None,
                    multiview_mask: None,
                    cache: None,
                })
            };
            let tex_entry = |binding, dim| wgpu::BindGroupLayoutEntry {
                binding,
                visibility: wgpu::ShaderStages::FRAGMENT,
                ty: wgpu::BindingType::Texture {
                    sample_type: wgpu::TextureSampleType::Float { filterable: false },
                    view_dimension: dim,
                    multisampled: false,
                },
                count: None,
            };
            let surface_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
                label: Some("surface"),
                entries: &[
                    uniform_entry(0, wgpu::ShaderStages::VERTEX_FRAGMENT),
                    tex_entry(1, wgpu::TextureViewDimension::D2Array),
                    tex_entry(2, wgpu::TextureViewDimension::D2Array),
                    uniform_entry(3, wgpu::ShaderStages::FRAGMENT),
                    uniform_entry(crepuscular::techniques::pass::LIGHTS_BINDING, wgpu::ShaderStages::FRAGMENT),
                ],
            });
            let surface_module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
                label: Some("host/surface.wgsl"),
                source: wgpu::ShaderSource::Wgsl(crepuscular::shaders::compose(SURFACE_WGSL).into()),
            });
            // One surface pipeline per camera depth convention (its depth test).
            let surface_pipeline = |compare: wgpu::CompareFunction| {
                device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
                    label: Some("surface"),
                    layout: Some(&device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
                        label: Some("surface"),
                        bind_group_layouts: &[Some(&surface_layout)],
                        immediate_size: 0,
                    })),
                    vertex: wgpu::VertexState {
                        module: &surface_module,
                        entry_point: Some("vs"),
                        compilation_options: Default::default(),
                        buffers: std::slice::from_ref(&vertex_layout),
                    },
                    primitive,
                    depth_stencil: Some(wgpu::DepthStencilState {
                        depth_compare: Some(compare),
                        ..depth_state.clone()
                    }),
                    multisample: Default::default(),
                    fragment: Some(wgpu::FragmentState {
                        module: &surface_module,
                        entry_point: Some("fs"),
                        compilation_options: Default::default(),
                        targets: &[Some(wgpu::ColorTargetState {
                            format: wgpu::TextureFormat::Rgba32Float,
                            blend: None,
                            write_mask: wgpu::ColorWrites::ALL,
                        })],
                    }),
                    multiview_mask: None,
                    cache: None,
                })
            };
            let (vertices, indices, index_count) = upload_geometry(device, geometry);
            let surface_pipelines = [
                surface_pipeline(DepthConvention::Standard.compare()),
                surface_pipeline(DepthConvention::Reversed.compare()),
            ];
            Self {
                shadow_pipelines: [
                    shadow_pipeline(DepthConvention::Standard.compare()),
                    shadow_pipeline(DepthConvention::Reversed.compare()),
                ],
                shadow_layout,
                surface_pipelines,
                surface_layout,
                shading: SurfaceShading::default(),
                vertices,
                indices,
                index_count,
                rectified_unclipped: OnceLock::new(),
                rectified_shader_clamp: OnceLock::new(),
            }
        })
    }

    /// Replaces the scene's triangles (a moving object: `animate --occluder-jump`) with
    /// `geometry`, uploaded anew; the pipelines are kept.
    pub fn set_geometry(&mut self, gpu: &GpuContext, geometry: &Geometry) {
        (self.vertices, self.indices, self.index_count) = upload_geometry(&gpu.device, geometry);
    }

    /// Rasterizes the rectified shadow map that `prefiltered` asks for (conventions: see
    /// [`RectifiedRaster`]) into a `Depth32Float` texture of `width × height` texels (usage
    /// `TEXTURE_BINDING | COPY_SRC | RENDER_ATTACHMENT`): one render pass, cleared to 1.0, one
    /// viewport and scissor rectangle per region, depth test LESS, no culling, depth clamped to
    /// [0, 1] instead of clipped — in hardware where the device has
    /// `DEPTH_CLIP_CONTROL` ([`hardware_depth_clamp`]), in the fragment shader otherwise.
    /// [`crate::raster::rasterize_rectified`] is the CPU equivalent.
    pub fn render_rectified(&self, gpu: &GpuContext, request: &RectifiedRaster) -> Result<wgpu::Texture, Error> {
        self.render_rectified_with(gpu, request, false)
    }

    /// [`GpuHost::render_rectified`], clamping the depth in the fragment shader (the path of
    /// devices without `DEPTH_CLIP_CONTROL`) even where the device could clamp it in hardware
    /// when `force_shader_clamp` is true. Both paths give the same depths up to rounding.
    /// Region columns must satisfy `columns[0] ≤ columns[1] ≤ width` ([`Error::Invalid`]
    /// otherwise); an empty region draws nothing.
    pub fn render_rectified_with(
        &self,
        gpu: &GpuContext,
        request: &RectifiedRaster,
        force_shader_clamp: bool,
    ) -> Result<wgpu::Texture, Error> {
        let (width, height) = (request.width, request.height);
        gpu.check_texture_size("rectified shadow map size", width, height)?;
        for (i, r) in request.regions.iter().enumerate() {
            if r.columns[0] > r.columns[1] || r.columns[1] > width {
                return Err(Error::invalid(
                    format!("rectified shadow map region {i} columns"),
                    format!("{:?}", r.columns),
                    format!("needs columns[0] ≤ columns[1] ≤ width = {width}"),
                ));
            }
        }
        let pipeline = self.rectified_pipeline(gpu, force_shader_clamp || !hardware_depth_clamp(gpu))?;
        let device = &gpu.device;
        gpu.scoped("rendering the rectified shadow map", || {
            let texture = device.create_texture(&wgpu::TextureDescriptor {
                label: Some("rectified shadow map"),
                size: wgpu::Extent3d { width, height, depth_or_array_layers: 1 },
                mip_level_count: 1,
                sample_count: 1,
                dimension: wgpu::TextureDimension::D2,
                format: wgpu::TextureFormat::Depth32Float,
                usage: wgpu::TextureUsages::TEXTURE_BINDING
                    | wgpu::TextureUsages::COPY_SRC
                    | wgpu::TextureUsages::RENDER_ATTACHMENT,
                view_formats: &[],
            });
            let view = texture.create_view(&Default::default());
            let groups: Vec<wgpu::BindGroup> = request
                .regions
                .iter()
                .map(|r| {
                    let buf = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                        label: Some("rectified region matrix"),
                        contents: bytemuck::cast_slice(&r.view_proj.to_cols_array()),
                        usage: wgpu::BufferUsages::UNIFORM,
                    });
                    device.create_bind_group(&wgpu::BindGroupDescriptor {
                        label: Some("rectified region"),
                        layout: &self.shadow_layout,
                        entries: &[wgpu::BindGroupEntry { binding: 0, resource: buf.as_entire_binding() }],
                    })
                })
                .collect();
            let mut enc =
                device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("rectified shadow map") });
            {
                let mut pass = enc.begin_render_pass(&wgpu::RenderPassDescriptor {
                    label: Some("rectified shadow map"),
                    color_attachments: &[],
                    depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
                        view: &view,
                        depth_ops: Some(wgpu::Operations {
                            load: wgpu::LoadOp::Clear(1.0),
                            store: wgpu::StoreOp::Store,
                        }),
                        stencil_ops: None,
                    }),
                    timestamp_writes: None,
                    occlusion_query_set: None,
                    multiview_mask: None,
                });
                pass.set_pipeline(pipeline);
                pass.set_vertex_buffer(0, self.vertices.slice(..));
                pass.set_index_buffer(self.indices.slice(..), wgpu::IndexFormat::Uint32);
                for (r, bg) in request.regions.iter().zip(&groups) {
                    let [c0, c1] = r.columns;
                    if c1 == c0 {
                        continue;
                    }
                    pass.set_viewport(c0 as f32, 0.0, (c1 - c0) as f32, height as f32, 0.0, 1.0);
                    pass.set_scissor_rect(c0, 0, c1 - c0, height);
                    pass.set_bind_group(0, bg, &[]);
                    pass.draw_indexed(0..self.index_count, 0, 0..1);
                }
            }
            gpu.queue.submit([enc.finish()]);
            texture
        })
    }

    /// The rectified shadow-map pipeline of one depth-clamping path, built on first use.
    fn rectified_pipeline(&self, gpu: &GpuContext, shader_clamp: bool) -> Result<&wgpu::RenderPipeline, Error> {
        let cell = if shader_clamp { &self.rectified_shader_clamp } else { &self.rectified_unclipped };
        if let Some(p) = cell.get() {
            return Ok(p);
        }
        let device = &gpu.device;
        let pipeline = gpu.scoped("creating the rectified shadow-map pipeline", || {
            let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
                label: Some("host/rectified_depth.wgsl"),
                source: wgpu::ShaderSource::Wgsl(RECTIFIED_DEPTH_WGSL.into()),
            });
            let layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
                label: Some("rectified shadow map"),
                bind_group_layouts: &[Some(&self.shadow_layout)],
                immediate_size: 0,
            });
            device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
                label: Some(if shader_clamp {
                    "rectified depth (shader clamp)"
                } else {
                    "rectified depth (unclipped)"
                }),
                layout: Some(&layout),
                vertex: wgpu::VertexState {
                    module: &module,
                    entry_point: Some(if shader_clamp { "vs_clamped" } else { "vs" }),
                    compilation_options: Default::default(),
                    buffers: &[wgpu::VertexBufferLayout {
                        array_stride: std::mem::size_of::<Vertex>() as u64,
                        step_mode: wgpu::VertexStepMode::Vertex,
                        attributes: &VERTEX_ATTRIBUTES[..1],
                    }],
                },
                primitive: wgpu::PrimitiveState {
                    cull_mode: None,
                    unclipped_depth: !shader_clamp,
                    ..Default::default()
                },
                depth_stencil: Some(wgpu::DepthStencilState {
                    format: wgpu::TextureFormat::Depth32Float,
                    depth_write_enabled: Some(true),
                    depth_compare: Some(wgpu::CompareFunction::Less),
                    stencil: Default::default(),
                    bias: Default::default(),
                }),
                multisample: Default::default(),
                fragment: shader_clamp.then(|| wgpu::FragmentState {
                    module: &module,
                    entry_point: Some("fs_clamped"),
                    compilation_options: Default::default(),
                    targets: &[],
                }),
                multiview_mask: None,
                cache: None,
            })
        })?;
        Ok(cell.get_or_init(|| pipeline))
    }

    /// Renders every light's shadow map, then depth and surface radiance for `desc` (lit by
    /// all its lights, each light's `scattering` aside). Passes: `shadow map` (one render pass
    /// per light and layer, timed together) and `surface`. Each light's map goes to its
    /// `shadow_layer` of one array as large as the largest ([`FrameDesc::shadow_array_extent`]),
    /// its spot texture to its `texture_layer` ([`FrameDesc::assign_layers`] packs both).
    pub fn render(&self, gpu: &GpuContext, desc: &FrameDesc) -> Result<HostTextures, Error> {
        desc.validate_lights()?;
        if desc.lights.len() > crepuscular::MAX_LIGHTS {
            return Err(Error::invalid(
                format!("lights[{}]", crepuscular::MAX_LIGHTS),
                format!("{} lights", desc.lights.len()),
                format!("the host renderer shades surfaces with at most {} lights", crepuscular::MAX_LIGHTS),
            ));
        }
        let mut textures: Vec<(u32, &crepuscular::RgbTexture)> =
            desc.lights.iter().filter_map(|l| l.spot_texture().map(|t| (l.texture_layer, t))).collect();
        textures.sort_by_key(|(layer, _)| *layer);
        if textures.iter().enumerate().any(|(i, (layer, _))| *layer != i as u32) {
            return Err(Error::invalid(
                "lights[].texture_layer",
                format!("{:?}", textures.iter().map(|(l, _)| *l).collect::<Vec<_>>()),
                "the host packs the textured spot lights into layers 0, 1, … (FrameDesc::assign_layers)",
            ));
        }
        let (size, layers) = desc.shadow_array_extent();
        gpu.check_texture_size("shadow_map_size", size, size)?;
        gpu.check_texture_size("image size", desc.width, desc.height)?;
        let device = &gpu.device;
        let tex = |label, w, h, layers, format| {
            device.create_texture(&wgpu::TextureDescriptor {
                label: Some(label),
                size: wgpu::Extent3d { width: w, height: h, depth_or_array_layers: layers },
                mip_level_count: 1,
                sample_count: 1,
                dimension: wgpu::TextureDimension::D2,
                format,
                usage: wgpu::TextureUsages::RENDER_ATTACHMENT
                    | wgpu::TextureUsages::TEXTURE_BINDING
                    | wgpu::TextureUsages::COPY_SRC,
                view_formats: &[],
            })
        };
        let (shadow_maps, depth, surface) = gpu.scoped("allocating host textures", || {
            (
                tex("shadow maps", size, size, layers, wgpu::TextureFormat::Depth32Float),
                tex("camera depth", desc.width, desc.height, 1, wgpu::TextureFormat::Depth32Float),
                tex("surface radiance", desc.width, desc.height, 1, wgpu::TextureFormat::Rgba32Float),
            )
        })?;
        let list: Vec<&crepuscular::RgbTexture> = textures.iter().map(|(_, t)| *t).collect();
        let spot_textures = gpu.upload_spot_textures(&list);
        // The host is the tools' own renderer: its passes are submitted one by one and timed by
        // synchronised wall clock.
        let mut timer = Recorder::wall_clock(gpu);
        // (layer view, matrix, the light's map size, its convention) per light and layer.
        let layer_groups: Vec<(wgpu::TextureView, wgpu::BindGroup, u32, DepthConvention)> = desc
            .lights
            .iter()
            .flat_map(|fl| (0..fl.shadow.layers).map(move |l| (fl, l)))
            .map(|(fl, l)| {
                let sp = &fl.shadow;
                let buf = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                    label: Some("shadow layer matrix"),
                    contents: bytemuck::cast_slice(&sp.view_proj[l as usize].to_cols_array()),
                    usage: wgpu::BufferUsages::UNIFORM,
                });
                let bg = device.create_bind_group(&wgpu::BindGroupDescriptor {
                    label: Some("shadow layer"),
                    layout: &self.shadow_layout,
                    entries: &[wgpu::BindGroupEntry { binding: 0, resource: buf.as_entire_binding() }],
                });
                let view = shadow_maps.create_view(&wgpu::TextureViewDescriptor {
                    dimension: Some(wgpu::TextureViewDimension::D2),
                    base_array_layer: fl.shadow_layer + l,
                    array_layer_count: Some(1),
                    ..Default::default()
                });
                (view, bg, sp.size, sp.depth)
            })
            .collect();
        timer.pass("shadow map", |enc, _| {
            for (view, bg, n, convention) in &layer_groups {
                let mut pass = enc.begin_render_pass(&wgpu::RenderPassDescriptor {
                    label: Some("shadow map layer"),
                    color_attachments: &[],
                    depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
                        view,
                        depth_ops: Some(wgpu::Operations {
                            load: wgpu::LoadOp::Clear(convention.far_value()),
                            store: wgpu::StoreOp::Store,
                        }),
                        stencil_ops: None,
                    }),
                    timestamp_writes: None,
                    occlusion_query_set: None,
                    multiview_mask: None,
                });
                pass.set_pipeline(&self.shadow_pipelines[(*convention == DepthConvention::Reversed) as usize]);
                // The light's map in the top-left n × n texels of its layers.
                pass.set_viewport(0.0, 0.0, *n as f32, *n as f32, 0.0, 1.0);
                pass.set_bind_group(0, bg, &[]);
                pass.set_vertex_buffer(0, self.vertices.slice(..));
                pass.set_index_buffer(self.indices.slice(..), wgpu::IndexFormat::Uint32);
                pass.draw_indexed(0..self.index_count, 0, 0..1);
            }
        })?;
        // Surfaces are lit by every light as it shines (its scattering scale is the effect's).
        let mut lit = desc.clone();
        for l in &mut lit.lights {
            l.scattering = 1.0;
        }
        let all: Vec<usize> = (0..lit.lights.len()).collect();
        let lights_buf = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("surface lights"),
            contents: bytemuck::bytes_of(&lit.lights_uniforms_of(&all)),
            usage: wgpu::BufferUsages::UNIFORM,
        });
        let frame_buf = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("frame uniforms"),
            contents: bytemuck::bytes_of(&desc.uniforms()),
            usage: wgpu::BufferUsages::UNIFORM,
        });
        let shadow_view = shadow_array_view(&shadow_maps);
        let spot_view = spot_textures.create_view(&wgpu::TextureViewDescriptor {
            dimension: Some(wgpu::TextureViewDimension::D2Array),
            ..Default::default()
        });
        let shading_buf = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("surface shading"),
            contents: bytemuck::cast_slice(&self.shading.uniform()),
            usage: wgpu::BufferUsages::UNIFORM,
        });
        let bg = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("surface"),
            layout: &self.surface_layout,
            entries: &[
                wgpu::BindGroupEntry { binding: 0, resource: frame_buf.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 1, resource: wgpu::BindingResource::TextureView(&shadow_view) },
                wgpu::BindGroupEntry { binding: 2, resource: wgpu::BindingResource::TextureView(&spot_view) },
                wgpu::BindGroupEntry { binding: 3, resource: shading_buf.as_entire_binding() },
                crepuscular::techniques::pass::lights_binding(&lights_buf),
            ],
        });
        let depth_view = depth.create_view(&Default::default());
        let convention = desc.camera.depth;
        let surface_view = surface.create_view(&Default::default());
        timer.pass("surface", |enc, ts| {
            let mut pass = enc.begin_render_pass(&wgpu::RenderPassDescriptor {
                label: Some("surface"),
                color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                    view: &surface_view,
                    depth_slice: None,
                    resolve_target: None,
                    ops: wgpu::Operations {
                        load: wgpu::LoadOp::Clear(wgpu::Color::BLACK),
                        store: wgpu::StoreOp::Store,
                    },
                })],
                depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
                    view: &depth_view,
                    depth_ops: Some(wgpu::Operations {
                        load: wgpu::LoadOp::Clear(convention.far_value()),
                        store: wgpu::StoreOp::Store,
                    }),
                    stencil_ops: None,
                }),
                timestamp_writes: ts.and_then(|t| t.render()),
                occlusion_query_set: None,
                multiview_mask: None,
            });
            pass.set_pipeline(&self.surface_pipelines[(convention == DepthConvention::Reversed) as usize]);
            pass.set_bind_group(0, &bg, &[]);
            pass.set_vertex_buffer(0, self.vertices.slice(..));
            pass.set_index_buffer(self.indices.slice(..), wgpu::IndexFormat::Uint32);
            pass.draw_indexed(0..self.index_count, 0, 0..1);
        })?;
        let passes = timer.into_passes();
        Ok(HostTextures { depth, surface, shadow_maps, spot_textures, passes })
    }
}

/// Whether `gpu` clamps depth in hardware (`DEPTH_CLIP_CONTROL`, so `unclipped_depth`
/// pipelines): the path [`GpuHost::render_rectified`] takes; the shader fallback otherwise.
pub fn hardware_depth_clamp(gpu: &GpuContext) -> bool {
    gpu.device.features().contains(wgpu::Features::DEPTH_CLIP_CONTROL)
}

/// Reads every light's shadow map back to the CPU, one [`ShadowMap`] per light of `desc`.
pub fn read_shadow_maps(gpu: &GpuContext, t: &HostTextures, desc: &FrameDesc) -> Result<Vec<ShadowMap>, Error> {
    let full = t.shadow_maps.width();
    desc.lights
        .iter()
        .map(|fl| {
            let n = fl.shadow.size;
            let mut depth = Vec::with_capacity((n * n * fl.shadow.layers) as usize);
            for l in 0..fl.shadow.layers {
                let layer = gpu.read_texture_f32(&t.shadow_maps, fl.shadow_layer + l)?;
                for y in 0..n {
                    depth.extend_from_slice(&layer[(y * full) as usize..(y * full + n) as usize]);
                }
            }
            Ok(ShadowMap { projection: fl.shadow.clone(), depth })
        })
        .collect()
}
