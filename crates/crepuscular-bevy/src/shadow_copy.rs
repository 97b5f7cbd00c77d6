//! The plugin's shadow array: the marked lights' layers of Bevy's two shadow textures copied
//! into one `R32Float` array (`shadow_copy.wgsl`; docs/BEVY.md "Shadow maps").

use bevy::pbr::ViewShadowBindings;
use wgpu::util::DeviceExt;

/// One layer to copy: from layer `src_layer` of a Bevy shadow texture into layer `dst_layer`
/// of the plugin's array, `size × size` texels from the top-left corner.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Eq, bytemuck::Pod, bytemuck::Zeroable)]
pub(crate) struct Job {
    pub src_layer: u32,
    pub dst_layer: u32,
    pub size: u32,
    pub _pad: u32,
}

/// Which layers of which Bevy texture go where, and the array they fill.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub(crate) struct CopyJobs {
    /// Layers of Bevy's directional/spot texture (`directional_light_depth_texture`).
    pub directional: Vec<Job>,
    /// Layers of Bevy's point-light cube texture (`point_light_depth_texture`).
    pub point: Vec<Job>,
    /// Layers of the plugin's array.
    pub layers: u32,
    /// Side of the plugin's array (the largest map copied).
    pub size: u32,
}

struct Source {
    jobs: Vec<Job>,
    texture: wgpu::Texture,
    dst: wgpu::Texture,
    bind_group: wgpu::BindGroup,
}

pub(crate) struct ShadowCopy {
    pipeline: wgpu::ComputePipeline,
    layout: wgpu::BindGroupLayout,
    array: Option<wgpu::Texture>,
    /// Bind groups of the two sources, kept while the jobs and textures stay the same.
    sources: [Option<Source>; 2],
}

impl ShadowCopy {
    pub fn new(device: &wgpu::Device) -> Self {
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("crepuscular-bevy shadow_copy.wgsl"),
            source: wgpu::ShaderSource::Wgsl(include_str!("shadow_copy.wgsl").into()),
        });
        let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("crepuscular-bevy shadow copy"),
            entries: &[
                wgpu::BindGroupLayoutEntry {
                    binding: 0,
                    visibility: wgpu::ShaderStages::COMPUTE,
                    ty: wgpu::BindingType::Texture {
                        sample_type: wgpu::TextureSampleType::Depth,
                        view_dimension: wgpu::TextureViewDimension::D2Array,
                        multisampled: false,
                    },
                    count: None,
                },
                wgpu::BindGroupLayoutEntry {
                    binding: 1,
                    visibility: wgpu::ShaderStages::COMPUTE,
                    ty: wgpu::BindingType::StorageTexture {
                        access: wgpu::StorageTextureAccess::WriteOnly,
                        format: wgpu::TextureFormat::R32Float,
                        view_dimension: wgpu::TextureViewDimension::D2Array,
                    },
                    count: None,
                },
                wgpu::BindGroupLayoutEntry {
                    binding: 2,
                    visibility: wgpu::ShaderStages::COMPUTE,
                    ty: wgpu::BindingType::Buffer {
                        ty: wgpu::BufferBindingType::Storage { read_only: true },
                        has_dynamic_offset: false,
                        min_binding_size: None,
                    },
                    count: None,
                },
            ],
        });
        let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("crepuscular-bevy shadow copy"),
            bind_group_layouts: &[Some(&layout)],
            immediate_size: 0,
        });
        let pipeline = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
            label: Some("crepuscular-bevy shadow copy"),
            layout: Some(&pipeline_layout),
            module: &module,
            entry_point: Some("copy_layers"),
            compilation_options: Default::default(),
            cache: None,
        });
        Self { pipeline, layout, array: None, sources: [None, None] }
    }

    /// Records the copies into `encoder` and returns the array they fill.
    pub fn encode(
        &mut self,
        device: &wgpu::Device,
        encoder: &mut wgpu::CommandEncoder,
        shadows: &ViewShadowBindings,
        jobs: &CopyJobs,
    ) -> Result<wgpu::Texture, String> {
        let limits = device.limits();
        if jobs.layers > limits.max_texture_array_layers || jobs.size > limits.max_texture_dimension_2d {
            return Err(format!(
                "the shadow array ({} layers of {}²) exceeds the device's limits ({} layers, {} texels)",
                jobs.layers, jobs.size, limits.max_texture_array_layers, limits.max_texture_dimension_2d
            ));
        }
        let array = match &self.array {
            Some(t) if t.depth_or_array_layers() == jobs.layers.max(1) && t.width() == jobs.size.max(1) => t.clone(),
            _ => {
                let t = device.create_texture(&wgpu::TextureDescriptor {
                    label: Some("crepuscular-bevy shadow array"),
                    size: wgpu::Extent3d {
                        width: jobs.size.max(1),
                        height: jobs.size.max(1),
                        depth_or_array_layers: jobs.layers.max(1),
                    },
                    mip_level_count: 1,
                    sample_count: 1,
                    dimension: wgpu::TextureDimension::D2,
                    format: wgpu::TextureFormat::R32Float,
                    usage: wgpu::TextureUsages::STORAGE_BINDING
                        | wgpu::TextureUsages::TEXTURE_BINDING
                        | wgpu::TextureUsages::COPY_SRC,
                    view_formats: &[],
                });
                self.array = Some(t.clone());
                self.sources = [None, None];
                t
            }
        };
        let sources: [(&[Job], &wgpu::Texture); 2] = [
            (&jobs.directional, &shadows.directional_light_depth_texture),
            (&jobs.point, &shadows.point_light_depth_texture),
        ];
        let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: Some("crepuscular-bevy shadow copy"),
            timestamp_writes: None,
        });
        pass.set_pipeline(&self.pipeline);
        for (k, (list, texture)) in sources.into_iter().enumerate() {
            if list.is_empty() {
                continue;
            }
            let fresh = match &self.sources[k] {
                Some(s) => s.jobs != list || s.texture != *texture || s.dst != array,
                None => true,
            };
            if fresh {
                let buffer = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                    label: Some("crepuscular-bevy shadow copy jobs"),
                    contents: bytemuck::cast_slice(list),
                    usage: wgpu::BufferUsages::STORAGE,
                });
                let src = texture.create_view(&wgpu::TextureViewDescriptor {
                    dimension: Some(wgpu::TextureViewDimension::D2Array),
                    aspect: wgpu::TextureAspect::DepthOnly,
                    ..Default::default()
                });
                let dst = array.create_view(&wgpu::TextureViewDescriptor {
                    dimension: Some(wgpu::TextureViewDimension::D2Array),
                    ..Default::default()
                });
                let bind_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
                    label: Some("crepuscular-bevy shadow copy"),
                    layout: &self.layout,
                    entries: &[
                        wgpu::BindGroupEntry { binding: 0, resource: wgpu::BindingResource::TextureView(&src) },
                        wgpu::BindGroupEntry { binding: 1, resource: wgpu::BindingResource::TextureView(&dst) },
                        wgpu::BindGroupEntry { binding: 2, resource: buffer.as_entire_binding() },
                    ],
                });
                self.sources[k] =
                    Some(Source { jobs: list.to_vec(), texture: (*texture).clone(), dst: array.clone(), bind_group });
            }
            let source = self.sources[k].as_ref().expect("built above");
            let size = list.iter().map(|j| j.size).max().unwrap_or(0);
            pass.set_bind_group(0, &source.bind_group, &[]);
            pass.dispatch_workgroups(size.div_ceil(8), size.div_ceil(8), list.len() as u32);
        }
        drop(pass);
        Ok(array)
    }
}
