//! What every technique's compute passes share: bind-group layout entries, the frame-pass
//! layout and its bindings (frame uniforms, pass uniforms, depth, shadow maps, spot textures,
//! output, lights), pipeline creation from a pass shader, and uniform buffers.

use crate::frame::GpuFrame;

/// A uniform buffer at `binding`, visible to compute.
pub fn uniform_entry(binding: u32) -> wgpu::BindGroupLayoutEntry {
    wgpu::BindGroupLayoutEntry {
        binding,
        visibility: wgpu::ShaderStages::COMPUTE,
        ty: wgpu::BindingType::Buffer {
            ty: wgpu::BufferBindingType::Uniform,
            has_dynamic_offset: false,
            min_binding_size: None,
        },
        count: None,
    }
}

/// An unfilterable float texture (read with `textureLoad`) at `binding`.
pub fn texture_entry(binding: u32, dim: wgpu::TextureViewDimension) -> wgpu::BindGroupLayoutEntry {
    wgpu::BindGroupLayoutEntry {
        binding,
        visibility: wgpu::ShaderStages::COMPUTE,
        ty: wgpu::BindingType::Texture {
            sample_type: wgpu::TextureSampleType::Float { filterable: false },
            view_dimension: dim,
            multisampled: false,
        },
        count: None,
    }
}

/// A write-only `Rgba32Float` 2D storage texture at `binding`.
pub fn storage_texture_entry(binding: u32) -> wgpu::BindGroupLayoutEntry {
    storage_texture_entry_of(binding, wgpu::TextureFormat::Rgba32Float)
}

/// A write-only 2D storage texture of `format` at `binding`.
pub fn storage_texture_entry_of(binding: u32, format: wgpu::TextureFormat) -> wgpu::BindGroupLayoutEntry {
    wgpu::BindGroupLayoutEntry {
        binding,
        visibility: wgpu::ShaderStages::COMPUTE,
        ty: wgpu::BindingType::StorageTexture {
            access: wgpu::StorageTextureAccess::WriteOnly,
            format,
            view_dimension: wgpu::TextureViewDimension::D2,
        },
        count: None,
    }
}

/// The in-scattering formats a caller may choose ([`crate::Scattering::with_output_format`]).
pub const OUTPUT_FORMATS: [wgpu::TextureFormat; 2] =
    [wgpu::TextureFormat::Rgba32Float, wgpu::TextureFormat::Rgba16Float];

/// A final pass's source with its output (`out_tex`) declared in `output`'s storage format.
pub fn with_output(src: &str, output: wgpu::TextureFormat) -> String {
    with_storage_format(src, "out_tex", output)
}

/// `src` with its storage texture `var` (declared `texture_storage_2d<rgba32float, write>` in
/// the shader) declared in `format`'s storage format, `Rgba32Float` or `Rgba16Float`.
pub fn with_storage_format(src: &str, var: &str, format: wgpu::TextureFormat) -> String {
    let name = match format {
        wgpu::TextureFormat::Rgba16Float => "rgba16float",
        _ => "rgba32float",
    };
    let declared = format!("var {var}: texture_storage_2d<rgba32float, write>;");
    debug_assert!(src.contains(&declared), "the shader declares no `{declared}`");
    src.replace(&declared, &format!("var {var}: texture_storage_2d<{name}, write>;"))
}

/// The format of a technique's radiance intermediates (interleaved's partial sums,
/// subsampled's grid, epipolar's marched and interpolated samples): the output's, so a caller
/// who chooses `Rgba16Float` halves their memory and bandwidth too. Intermediates that hold
/// positions or depths (epipolar's coordinates, prefiltered's and minmax's maps) stay 32-bit.
/// The cost in PSNR, measured: README, "Rgba16Float".
pub fn intermediate_format(output: wgpu::TextureFormat) -> wgpu::TextureFormat {
    output
}

/// Bytes per texel of an `Rgba32Float` or `Rgba16Float` texture.
pub fn texel_bytes(format: wgpu::TextureFormat) -> u64 {
    format.block_copy_size(None).unwrap_or(16) as u64
}

/// A storage buffer at `binding` of at least `min_size` bytes (None: any).
pub fn storage_buffer_entry(binding: u32, read_only: bool, min_size: Option<u64>) -> wgpu::BindGroupLayoutEntry {
    wgpu::BindGroupLayoutEntry {
        binding,
        visibility: wgpu::ShaderStages::COMPUTE,
        ty: wgpu::BindingType::Buffer {
            ty: wgpu::BufferBindingType::Storage { read_only },
            has_dynamic_offset: false,
            min_binding_size: min_size.and_then(wgpu::BufferSize::new),
        },
        count: None,
    }
}

/// The binding of the frame's lights (`lights` in common.wgsl, [`crate::LightsUniforms`]) in
/// group 0 of every pass that evaluates a light.
pub const LIGHTS_BINDING: u32 = 15;

/// The lights' uniform buffer entry ([`LIGHTS_BINDING`]).
pub fn lights_entry() -> wgpu::BindGroupLayoutEntry {
    uniform_entry(LIGHTS_BINDING)
}

/// The bind group entry of the lights' uniform buffer.
pub fn lights_binding(lights: &wgpu::Buffer) -> wgpu::BindGroupEntry<'_> {
    wgpu::BindGroupEntry { binding: LIGHTS_BINDING, resource: lights.as_entire_binding() }
}

/// Bindings 0–5 and the lights of every per-pixel pass over the frame: frame uniforms, pass
/// uniforms, depth, shadow maps (array), spot textures (array), the output in `output`'s
/// format, the lights ([`LIGHTS_BINDING`]).
pub fn frame_pass_entries(output: wgpu::TextureFormat) -> [wgpu::BindGroupLayoutEntry; 7] {
    use wgpu::TextureViewDimension as D;
    [
        uniform_entry(0),
        uniform_entry(1),
        texture_entry(2, D::D2),
        texture_entry(3, D::D2Array),
        texture_entry(4, D::D2Array),
        storage_texture_entry_of(5, output),
        lights_entry(),
    ]
}

/// The frame-pass layout ([`frame_pass_entries`], an `Rgba32Float` output) followed by a pass's
/// own `extra` bindings.
pub fn frame_pass_layout(
    device: &wgpu::Device,
    label: &str,
    extra: &[wgpu::BindGroupLayoutEntry],
) -> wgpu::BindGroupLayout {
    frame_pass_layout_to(device, label, extra, wgpu::TextureFormat::Rgba32Float)
}

/// [`frame_pass_layout`] with the output in `output`'s format (a technique's final pass).
pub fn frame_pass_layout_to(
    device: &wgpu::Device,
    label: &str,
    extra: &[wgpu::BindGroupLayoutEntry],
    output: wgpu::TextureFormat,
) -> wgpu::BindGroupLayout {
    let mut entries = frame_pass_entries(output).to_vec();
    entries.extend_from_slice(extra);
    device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor { label: Some(label), entries: &entries })
}

/// The resources of [`frame_pass_entries`]: `white` (a one-layer array) stands in for missing
/// spot textures.
pub fn frame_pass_bindings<'a>(
    buffers: &'a FrameBuffers,
    params: &'a wgpu::Buffer,
    frame: &GpuFrame<'a>,
    white: &'a wgpu::TextureView,
    output: &'a wgpu::TextureView,
) -> [wgpu::BindGroupEntry<'a>; 7] {
    let view = wgpu::BindingResource::TextureView;
    [
        wgpu::BindGroupEntry { binding: 0, resource: buffers.frame.as_entire_binding() },
        wgpu::BindGroupEntry { binding: 1, resource: params.as_entire_binding() },
        wgpu::BindGroupEntry { binding: 2, resource: view(frame.depth) },
        wgpu::BindGroupEntry { binding: 3, resource: view(frame.shadow_maps) },
        wgpu::BindGroupEntry { binding: 4, resource: view(frame.spot_textures.unwrap_or(white)) },
        wgpu::BindGroupEntry { binding: 5, resource: view(output) },
        lights_binding(&buffers.lights),
    ]
}

/// A technique's frame uniforms and lights uniforms, written once per frame.
pub struct FrameBuffers {
    /// [`crate::FrameUniforms`].
    pub frame: wgpu::Buffer,
    /// [`crate::LightsUniforms`].
    pub lights: wgpu::Buffer,
}

impl FrameBuffers {
    /// Both buffers, uninitialised.
    pub fn new(device: &wgpu::Device) -> Self {
        Self {
            frame: uniform_buffer(device, "frame uniforms", std::mem::size_of::<crate::FrameUniforms>() as u64),
            lights: uniform_buffer(device, "lights uniforms", std::mem::size_of::<crate::LightsUniforms>() as u64),
        }
    }

    /// Writes `desc`'s camera, medium and the lights that reach the view, in order before the
    /// passes recorded next.
    pub fn write(&self, rec: &mut crate::gpu::Recorder, desc: &crate::FrameDesc) {
        rec.write_buffer(&self.frame, bytemuck::bytes_of(&desc.uniforms()));
        rec.write_buffer(&self.lights, bytemuck::bytes_of(&desc.lights_uniforms()));
    }

    /// Bytes of GPU memory.
    pub fn size(&self) -> u64 {
        self.frame.size() + self.lights.size()
    }
}

/// A 1×1 white one-layer texture array: what a pass binds for the spot textures when no light
/// has one.
pub fn white_array(gpu: &crate::GpuContext) -> wgpu::TextureView {
    gpu.upload_spot_textures(&[]).create_view(&wgpu::TextureViewDescriptor {
        dimension: Some(wgpu::TextureViewDimension::D2Array),
        ..Default::default()
    })
}

/// A compute pipeline from a pass shader (composed with common.wgsl), with one bind group.
pub fn compute_pipeline(
    device: &wgpu::Device,
    label: &str,
    pass_wgsl: &str,
    entry: &str,
    layout: &wgpu::BindGroupLayout,
) -> wgpu::ComputePipeline {
    let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
        label: Some(label),
        source: wgpu::ShaderSource::Wgsl(crate::shaders::compose(pass_wgsl).into()),
    });
    let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
        label: Some(label),
        bind_group_layouts: &[Some(layout)],
        immediate_size: 0,
    });
    device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
        label: Some(label),
        layout: Some(&pipeline_layout),
        module: &module,
        entry_point: Some(entry),
        compilation_options: Default::default(),
        cache: None,
    })
}

/// A uniform buffer of `size` bytes, written with `queue.write_buffer`.
pub fn uniform_buffer(device: &wgpu::Device, label: &str, size: u64) -> wgpu::Buffer {
    device.create_buffer(&wgpu::BufferDescriptor {
        label: Some(label),
        size,
        usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    })
}

/// One resource a bind group refers to, compared by identity (or a choice that selects one).
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Bound {
    /// A texture view.
    View(wgpu::TextureView),
    /// A buffer.
    Buffer(wgpu::Buffer),
    /// A choice between resources (a sampler, a table or none).
    Choice(u32),
}

/// The resources of a frame's bind groups that may change between frames: the frame's views
/// (depth, shadow map, spot texture, host raster) and the output. A technique adds its own
/// size- or settings-dependent resources.
pub fn frame_key(frame: &GpuFrame, output: &wgpu::TextureView) -> Vec<Bound> {
    let mut key = vec![Bound::View(frame.depth.clone()), Bound::View(frame.shadow_maps.clone())];
    key.push(frame.spot_textures.map_or(Bound::Choice(0), |v| Bound::View(v.clone())));
    key.push(frame.rectified_shadow_map().map_or(Bound::Choice(0), |v| Bound::View(v.clone())));
    key.push(Bound::View(output.clone()));
    key
}

/// A technique's bind groups, rebuilt only when a resource they bind changed (a resize, a
/// settings change that reallocates, other textures from the caller) — not every frame.
pub struct BindCache<T> {
    key: Vec<Bound>,
    value: Option<T>,
    builds: u64,
}

impl<T> Default for BindCache<T> {
    fn default() -> Self {
        Self { key: Vec::new(), value: None, builds: 0 }
    }
}

impl<T> BindCache<T> {
    /// True when the cached bind groups were built for exactly these resources.
    pub fn is_current(&self, key: &[Bound]) -> bool {
        self.value.is_some() && self.key == key
    }

    /// Keeps `value`, built for `key`.
    pub fn store(&mut self, key: Vec<Bound>, value: T) {
        self.key = key;
        self.value = Some(value);
        self.builds += 1;
    }

    /// The cached bind groups (call after [`BindCache::store`] or a true [`BindCache::is_current`]).
    pub fn value(&self) -> &T {
        self.value.as_ref().expect("bind groups built before use")
    }

    /// How many times the bind groups were built.
    pub fn builds(&self) -> u64 {
        self.builds
    }
}
