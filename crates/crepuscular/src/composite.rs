//! The final composite on the GPU: L = T(s)·L_surface + L_scatt (docs/MODEL.md §1) applied to
//! the caller's HDR colour, with the display transform of [`crate::tonemap`] optional and
//! separate. One fullscreen render pass recorded into the caller's encoder. Its CPU mirror is
//! [`crate::tonemap::composite`] over [`crate::frame::surface_transmittance`] (and
//! [`ToneMap::apply`] for the display transform), tested pixel by pixel against it.

use crate::error::Error;
use crate::frame::FrameDesc;
use crate::techniques::pass::{self, BindCache, Bindings, Bound};
use crate::tonemap::ToneMap;
use std::collections::HashMap;

/// The composite pass shader (composed with common.wgsl).
pub const COMPOSITE_WGSL: &str = include_str!("composite.wgsl");

/// Where the composite writes.
#[derive(Clone, Copy, Debug)]
pub enum CompositeTarget<'a> {
    /// Into another render target (any colour format the device can render to: `Rgba16Float`
    /// or `Rgba32Float` for linear HDR, `Rgba8Unorm`/`Rgba8UnormSrgb`/`Bgra8Unorm…` with the
    /// display transform). The surface colour is read from [`CompositeInputs::surface`].
    Into(&'a wgpu::TextureView),
    /// Back into the caller's HDR colour texture itself (which must have `COPY_SRC` and
    /// `RENDER_ATTACHMENT` usage, and be the frame's size): the pass first copies it into a
    /// scratch texture it keeps (allocated on the first frame and on resize), then draws from
    /// that. Cost: one texture copy. [`CompositeInputs::surface`] is ignored.
    InPlace(&'a wgpu::Texture),
}

/// What the composite reads: views of the caller's textures for one frame.
#[derive(Clone, Copy, Debug)]
pub struct CompositeInputs<'a> {
    /// The frame (camera, medium, size): T(s) is rebuilt from `depth` with its camera.
    pub desc: &'a FrameDesc,
    /// Camera depth, as given to the technique ([`crate::GpuFrame::depth`]).
    pub depth: &'a wgpu::TextureView,
    /// The technique's in-scattering (its output texture).
    pub inscatter: &'a wgpu::TextureView,
    /// The engine's lit surface colour (linear HDR, a float format), for
    /// [`CompositeTarget::Into`].
    pub surface: &'a wgpu::TextureView,
}

#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct Params {
    tone: [f32; 4],
}

/// The composite pass, built once per device; pipelines are made per target format as they
/// are first used.
pub struct Composite {
    device: wgpu::Device,
    module: wgpu::ShaderModule,
    bindings: Bindings,
    pipeline_layout: wgpu::PipelineLayout,
    pipelines: HashMap<wgpu::TextureFormat, wgpu::RenderPipeline>,
    /// The in-place copy of the target, with its view (kept, so the bind group stays valid).
    scratch: Option<(wgpu::Texture, wgpu::TextureView)>,
    /// The frame's uniforms and the tone parameters, written through the caller's encoder.
    frame_buffer: wgpu::Buffer,
    params_buffer: wgpu::Buffer,
    /// The bind group, rebuilt only when a view it binds changes.
    bind: BindCache<wgpu::BindGroup>,
}

impl Composite {
    /// How many times the bind group was built (on new views or a resize, not per frame).
    pub fn bind_group_builds(&self) -> u64 {
        self.bind.builds()
    }

    /// Builds the shader and layout on the caller's device (the layout read from the
    /// shader's own declarations, [`crate::techniques::pass::Bindings`]).
    pub fn new(device: &wgpu::Device) -> Result<Self, crate::Error> {
        let source = crate::shaders::compose(COMPOSITE_WGSL);
        let (bindings, _, _) = Bindings::new(device, "composite", &source, "fs", naga::ShaderStage::Fragment)?;
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("composite.wgsl"),
            source: wgpu::ShaderSource::Wgsl(source.into()),
        });
        let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("composite"),
            bind_group_layouts: &[Some(bindings.layout())],
            immediate_size: 0,
        });
        let uniform = |label, size: usize| pass::uniform_buffer(device, label, size as u64);
        Ok(Self {
            device: device.clone(),
            module,
            bindings,
            pipeline_layout,
            pipelines: HashMap::new(),
            scratch: None,
            frame_buffer: uniform("composite frame uniforms", std::mem::size_of::<crate::FrameUniforms>()),
            params_buffer: uniform("composite params", std::mem::size_of::<Params>()),
            bind: BindCache::default(),
        })
    }

    fn pipeline(&mut self, format: wgpu::TextureFormat) -> &wgpu::RenderPipeline {
        let (device, module, layout) = (&self.device, &self.module, &self.pipeline_layout);
        self.pipelines.entry(format).or_insert_with(|| {
            device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
                label: Some("composite"),
                layout: Some(layout),
                vertex: wgpu::VertexState {
                    module,
                    entry_point: Some("vs"),
                    compilation_options: Default::default(),
                    buffers: &[],
                },
                primitive: Default::default(),
                depth_stencil: None,
                multisample: Default::default(),
                fragment: Some(wgpu::FragmentState {
                    module,
                    entry_point: Some("fs"),
                    compilation_options: Default::default(),
                    targets: &[Some(format.into())],
                }),
                multiview_mask: None,
                cache: None,
            })
        })
    }

    /// Records the composite into `encoder`. `tone`: `None` writes linear HDR radiance (for a
    /// float target, before the engine's own tone mapping); `Some` applies exposure and the
    /// filmic curve, and the sRGB encoding unless the target's format is itself sRGB. Errors
    /// name a target or input whose size or format does not fit.
    pub fn encode(
        &mut self,
        encoder: &mut wgpu::CommandEncoder,
        inputs: &CompositeInputs,
        target: CompositeTarget,
        tone: Option<ToneMap>,
    ) -> Result<(), Error> {
        let d = inputs.desc;
        let (w, h) = (d.width, d.height);
        let size = |t: &wgpu::Texture| (t.width(), t.height());
        let mut read = vec![("depth", inputs.depth.texture()), ("inscatter", inputs.inscatter.texture())];
        if let CompositeTarget::Into(_) = target {
            read.push(("surface", inputs.surface.texture()));
        }
        for (key, t) in read {
            if size(t) != (w, h) {
                return Err(Error::invalid(key, format!("{}×{}", t.width(), t.height()), format!("must be {w}×{h}")));
            }
            if !t.usage().contains(wgpu::TextureUsages::TEXTURE_BINDING) {
                return Err(Error::invalid(key, format!("{:?}", t.usage()), "needs TEXTURE_BINDING usage"));
            }
            let float = matches!(t.format().sample_type(None, None), Some(wgpu::TextureSampleType::Float { .. }))
                || matches!(t.format(), wgpu::TextureFormat::Depth32Float);
            if !float {
                return Err(Error::invalid(
                    key,
                    format!("{:?}", t.format()),
                    "must be a float (or Depth32Float) format",
                ));
            }
        }
        let target_texture = match target {
            CompositeTarget::Into(v) => v.texture().clone(),
            CompositeTarget::InPlace(t) => t.clone(),
        };
        if size(&target_texture) != (w, h) {
            let s = format!("{}×{}", target_texture.width(), target_texture.height());
            return Err(Error::invalid("composite target", s, format!("must be {w}×{h}")));
        }
        let format = target_texture.format();
        if !target_texture.usage().contains(wgpu::TextureUsages::RENDER_ATTACHMENT) {
            return Err(Error::invalid("composite target", format!("{format:?}"), "needs RENDER_ATTACHMENT usage"));
        }
        let surface_view = match target {
            CompositeTarget::Into(_) => inputs.surface.clone(),
            CompositeTarget::InPlace(t) => {
                if !t.usage().contains(wgpu::TextureUsages::COPY_SRC) {
                    return Err(Error::invalid(
                        "composite target",
                        format!("{format:?}"),
                        "in place needs COPY_SRC usage",
                    ));
                }
                if self.scratch.as_ref().is_none_or(|(s, _)| size(s) != (w, h) || s.format() != format) {
                    let texture = self.device.create_texture(&wgpu::TextureDescriptor {
                        label: Some("composite scratch"),
                        size: wgpu::Extent3d { width: w, height: h, depth_or_array_layers: 1 },
                        mip_level_count: 1,
                        sample_count: 1,
                        dimension: wgpu::TextureDimension::D2,
                        format,
                        usage: wgpu::TextureUsages::COPY_DST | wgpu::TextureUsages::TEXTURE_BINDING,
                        view_formats: &[],
                    });
                    let view = texture.create_view(&Default::default());
                    self.scratch = Some((texture, view));
                }
                let (scratch, scratch_view) = self.scratch.as_ref().expect("allocated above");
                encoder.copy_texture_to_texture(
                    t.as_image_copy(),
                    scratch.as_image_copy(),
                    wgpu::Extent3d { width: w, height: h, depth_or_array_layers: 1 },
                );
                scratch_view.clone()
            }
        };
        let tone_params = match tone {
            Some(t) => [t.exposure, 1.0, if format.is_srgb() { 0.0 } else { 1.0 }, 0.0],
            None => [1.0, 0.0, 0.0, 0.0],
        };
        // This frame's uniforms, copied through the encoder from staging buffers of their own
        // (so composites of different frames in one encoder each read their own values).
        for (dst, bytes) in [
            (&self.frame_buffer, bytemuck::bytes_of(&d.uniforms())),
            (&self.params_buffer, bytemuck::bytes_of(&Params { tone: tone_params })),
        ] {
            pass::write_in_encoder(&self.device, encoder, dst, bytes);
        }
        let key = vec![
            Bound::View(surface_view.clone()),
            Bound::View(inputs.inscatter.clone()),
            Bound::View(inputs.depth.clone()),
        ];
        if !self.bind.is_current(&key) {
            let view = wgpu::BindingResource::TextureView;
            let bind = self.bindings.bind(
                &self.device,
                &[
                    ("f", self.frame_buffer.as_entire_binding()),
                    ("params", self.params_buffer.as_entire_binding()),
                    ("surface_tex", view(&surface_view)),
                    ("inscatter_tex", view(inputs.inscatter)),
                    ("depth_tex", view(inputs.depth)),
                ],
            )?;
            self.bind.store(key, bind);
        }
        let bind = self.bind.value().clone();
        let target_view = match target {
            CompositeTarget::Into(v) => v.clone(),
            CompositeTarget::InPlace(t) => t.create_view(&Default::default()),
        };
        let pipeline = self.pipeline(format).clone();
        let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
            label: Some("composite"),
            color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                view: &target_view,
                depth_slice: None,
                resolve_target: None,
                ops: wgpu::Operations { load: wgpu::LoadOp::Clear(wgpu::Color::BLACK), store: wgpu::StoreOp::Store },
            })],
            depth_stencil_attachment: None,
            timestamp_writes: None,
            occlusion_query_set: None,
            multiview_mask: None,
        });
        pass.set_pipeline(&pipeline);
        pass.set_bind_group(0, &bind, &[]);
        pass.draw(0..3, 0..1);
        Ok(())
    }
}
