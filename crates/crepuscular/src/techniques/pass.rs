//! What every technique's compute passes share: [`Pass`] (a pipeline whose bind group layout is
//! read from its own WGSL, bound by the shader's variable names), the frame's resources
//! ([`frame_resources`]), the output and intermediate formats, uniform buffers and the bind
//! group cache.

use crate::frame::GpuFrame;

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

/// The binding of the frame's lights (`lights` in common.wgsl, [`crate::LightsUniforms`]) in
/// group 0 of every pass that evaluates a light.
pub const LIGHTS_BINDING: u32 = 15;

/// The bind group entry of the lights' uniform buffer.
pub fn lights_binding(lights: &wgpu::Buffer) -> wgpu::BindGroupEntry<'_> {
    wgpu::BindGroupEntry { binding: LIGHTS_BINDING, resource: lights.as_entire_binding() }
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

/// Writes `bytes` to the start of `dst` (a `COPY_DST` buffer) in `encoder`, before the passes
/// recorded after it: copied from a staging buffer of this call's own, so several frames
/// recorded into one encoder each read their own values. For the stages that record into a
/// bare encoder (the temporal stage, the composite); techniques write through
/// [`crate::gpu::Recorder::write_buffer`].
pub fn write_in_encoder(device: &wgpu::Device, encoder: &mut wgpu::CommandEncoder, dst: &wgpu::Buffer, bytes: &[u8]) {
    use wgpu::util::DeviceExt;
    let staging = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: Some("uniforms upload"),
        contents: bytes,
        usage: wgpu::BufferUsages::COPY_SRC,
    });
    encoder.copy_buffer_to_buffer(&staging, 0, dst, 0, bytes.len() as u64);
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

/// A shader entry point's bind group layout, declared once — by its WGSL. The layout is read
/// from the shader's own `@group(0) @binding(n) var name: type;` declarations (naga's
/// reflection of the globals the entry point uses: uniforms, storage buffers with their access,
/// sampled textures with their dimension and sample type, storage textures with their format
/// and access, samplers), and a bind group is built from resources named as the shader names
/// them. So the shader is the one list of what a pass reads and writes: there is no binding
/// number in Rust to keep in step with it, and a resource missing, unknown or given twice is an
/// error naming the pass and the variable.
///
/// A sampled float texture is filterable exactly when the entry point samples it through a
/// sampler (`textureSample*`); textures read with `textureLoad` are unfilterable, so
/// `Rgba32Float` needs no `FLOAT32_FILTERABLE`.
pub struct Bindings {
    label: String,
    layout: wgpu::BindGroupLayout,
    /// (variable name, binding) of every global the entry point uses, in binding order.
    slots: Vec<(String, u32)>,
    /// Names declared in the module but unused by this entry point: accepted and skipped.
    unused: Vec<String>,
}

/// A resource for the variable of the same name in a pass's WGSL.
pub type Resource<'a> = (&'a str, wgpu::BindingResource<'a>);

impl Bindings {
    /// The layout of `entry` (a `stage` entry point) of the composed WGSL `source`, the entry
    /// point's workgroup size and whether it reads the [`ShaderVariant`]'s constants; `label`
    /// names it in errors and GPU captures.
    pub fn new(
        device: &wgpu::Device,
        label: &str,
        source: &str,
        entry: &str,
        stage: naga::ShaderStage,
    ) -> Result<(Self, [u32; 3], bool), crate::Error> {
        let reflected = reflect(source, entry, stage)
            .map_err(|message| crate::Error::Gpu { context: format!("reading the bindings of {label}"), message })?;
        let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some(label),
            entries: &reflected.entries,
        });
        let Reflected { slots, unused, workgroup, reads_overrides, .. } = reflected;
        Ok((Self { label: label.to_string(), layout, slots, unused }, workgroup, reads_overrides))
    }

    /// The bind group layout.
    pub fn layout(&self) -> &wgpu::BindGroupLayout {
        &self.layout
    }

    /// The variables the entry point binds, in binding order: (name, binding).
    pub fn slots(&self) -> &[(String, u32)] {
        &self.slots
    }

    /// A bind group of `resources`, each named as the shader names its variable. Every variable
    /// the entry point uses must be given once; a name the module declares but this entry point
    /// does not use is skipped (one resource list can serve several entry points of one shader);
    /// any other name is an error.
    pub fn bind(&self, device: &wgpu::Device, resources: &[Resource<'_>]) -> Result<wgpu::BindGroup, crate::Error> {
        let err = |message: String| crate::Error::Gpu { context: format!("binding {}", self.label), message };
        let mut entries = Vec::with_capacity(self.slots.len());
        for (name, binding) in &self.slots {
            let mut given = resources.iter().filter(|(n, _)| n == name);
            let Some((_, resource)) = given.next() else {
                return Err(err(format!("the shader's `{name}` (binding {binding}) was given no resource")));
            };
            if given.next().is_some() {
                return Err(err(format!("`{name}` was given twice")));
            }
            entries.push(wgpu::BindGroupEntry { binding: *binding, resource: resource.clone() });
        }
        let declared = |n: &str| self.slots.iter().any(|(s, _)| s == n) || self.unused.iter().any(|u| u == n);
        if let Some((name, _)) = resources.iter().find(|(n, _)| !declared(n)) {
            return Err(err(format!("the shader declares no `{name}`")));
        }
        Ok(device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some(&self.label),
            layout: &self.layout,
            entries: &entries,
        }))
    }
}

/// Which light code a pass's pipeline holds: the pipeline-overridable constants
/// `LOCAL_LIGHTS` and `SPOT_TEXTURES` of common.wgsl. A frame runs the variant of the lights it
/// holds ([`ShaderVariant::of`]): a pipeline without spot and point lights has their code (cone,
/// attenuation, cube faces, their own march intervals) compiled out, and one without projected
/// textures the texture's projection and four reads. The result for such a frame is the same;
/// what changes is what the device pays for branches no pixel takes. On llvmpipe, which runs a
/// branch's code whenever it cannot prove every lane skips it, the sun-only variant marches
/// 1.8× faster (docs/RESULTS.md, "Shader variants by light kind"); a GPU skips a branch no lane
/// takes, and gains at most the registers the branch held.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct ShaderVariant {
    /// The frame may hold spot or point lights (`LOCAL_LIGHTS`).
    pub local_lights: bool,
    /// The frame may hold a spot light with a projected texture (`SPOT_TEXTURES`).
    pub spot_textures: bool,
}

impl ShaderVariant {
    /// Every kind of light: the only variant of a pass whose entry point evaluates no light.
    pub const ALL: Self = Self { local_lights: true, spot_textures: true };

    /// The variant of a frame: spot and point lights where `desc` holds one, projected textures
    /// where one of its spots has a texture.
    pub fn of(desc: &crate::FrameDesc) -> Self {
        Self {
            local_lights: desc.lights.iter().any(|l| !matches!(l.light, crate::Light::Directional { .. })),
            spot_textures: desc.lights.iter().any(|l| l.spot_texture().is_some()),
        }
    }

    fn index(self) -> usize {
        self.local_lights as usize | (self.spot_textures as usize) << 1
    }

    /// The override values, by the names common.wgsl gives them.
    fn constants(self) -> [(&'static str, f64); 2] {
        [("LOCAL_LIGHTS", self.local_lights as u8 as f64), ("SPOT_TEXTURES", self.spot_textures as u8 as f64)]
    }
}

/// One compute pass: a pipeline with the layout its WGSL declares ([`Bindings`]), built per
/// [`ShaderVariant`] on its first use when its entry point reads the variant's constants (one
/// pipeline for every variant otherwise).
pub struct Pass {
    bindings: Bindings,
    module: wgpu::ShaderModule,
    layout: wgpu::PipelineLayout,
    entry: String,
    /// Whether the entry point reads `LOCAL_LIGHTS` or `SPOT_TEXTURES`.
    specialized: bool,
    /// The pipeline of each variant ([`ShaderVariant::index`]), built on first use.
    pipelines: [std::sync::OnceLock<wgpu::ComputePipeline>; 4],
    workgroup: [u32; 3],
    device: wgpu::Device,
}

impl Pass {
    /// Builds the pass `entry` of `pass_wgsl` (composed with common.wgsl), its layout read from
    /// the shader. `label` names it in errors and GPU captures (`technique/pass`).
    /// The shader module is built and validated here; each variant's pipeline on its first
    /// use ([`Pass::pipeline`]), so a frame compiles only the variants it runs.
    pub fn new(device: &wgpu::Device, label: &str, pass_wgsl: &str, entry: &str) -> Result<Self, crate::Error> {
        let source = crate::shaders::compose(pass_wgsl);
        let (bindings, workgroup, specialized) =
            Bindings::new(device, label, &source, entry, naga::ShaderStage::Compute)?;
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some(label),
            source: wgpu::ShaderSource::Wgsl(source.into()),
        });
        let layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some(label),
            bind_group_layouts: &[Some(bindings.layout())],
            immediate_size: 0,
        });
        Ok(Self {
            bindings,
            module,
            layout,
            entry: entry.to_string(),
            specialized,
            pipelines: Default::default(),
            workgroup,
            device: device.clone(),
        })
    }

    /// Whether the entry point reads the [`ShaderVariant`]'s constants (else every variant
    /// runs the one pipeline).
    pub fn is_specialized(&self) -> bool {
        self.specialized
    }

    /// Pipelines built so far (0 to 4).
    pub fn pipelines_built(&self) -> usize {
        self.pipelines.iter().filter(|p| p.get().is_some()).count()
    }

    /// The pass's name (`technique/pass`).
    pub fn label(&self) -> &str {
        &self.bindings.label
    }

    /// The entry point's `@workgroup_size`.
    pub fn workgroup_size(&self) -> [u32; 3] {
        self.workgroup
    }

    /// The workgroups that cover a `width`×`height` grid of invocations (one per pixel).
    pub fn groups_2d(&self, width: u32, height: u32) -> [u32; 3] {
        [width.div_ceil(self.workgroup[0]), height.div_ceil(self.workgroup[1]), 1]
    }

    /// The variables the pass binds, in binding order: (name, binding).
    pub fn bindings(&self) -> &[(String, u32)] {
        self.bindings.slots()
    }

    /// A bind group of `resources`, named as the shader names them ([`Bindings::bind`]).
    pub fn bind(&self, device: &wgpu::Device, resources: &[Resource<'_>]) -> Result<wgpu::BindGroup, crate::Error> {
        self.bindings.bind(device, resources)
    }

    /// Records the pass with `bind` over `groups` workgroups in `variant`'s pipeline
    /// ([`Pass::pipeline`]), timed as `name` ([`crate::gpu::Recorder::dispatch`]).
    pub fn dispatch(
        &self,
        rec: &mut crate::gpu::Recorder,
        variant: ShaderVariant,
        name: &str,
        bind: &wgpu::BindGroup,
        groups: [u32; 3],
    ) -> Result<(), crate::Error> {
        rec.dispatch(name, self.label(), self.pipeline(variant), bind, groups)
    }

    /// The compute pipeline of `variant` (for passes recorded by hand: indirect, or sharing a
    /// compute pass), built on first use; [`ShaderVariant::ALL`]'s for a pass that reads no
    /// light.
    pub fn pipeline(&self, variant: ShaderVariant) -> &wgpu::ComputePipeline {
        let variant = if self.specialized { variant } else { ShaderVariant::ALL };
        self.pipelines[variant.index()].get_or_init(|| {
            let constants = if self.specialized { variant.constants().to_vec() } else { Vec::new() };
            let label = format!("{} {variant:?}", self.label());
            self.device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
                label: Some(&label),
                layout: Some(&self.layout),
                module: &self.module,
                entry_point: Some(&self.entry),
                compilation_options: wgpu::PipelineCompilationOptions { constants: &constants, ..Default::default() },
                cache: None,
            })
        })
    }
}

/// What [`reflect`] reads from a shader.
#[derive(Clone, Debug)]
pub struct Reflected {
    /// The layout entries of the globals the entry point uses, in binding order.
    pub entries: Vec<wgpu::BindGroupLayoutEntry>,
    /// (name, binding) of each, in the same order.
    pub slots: Vec<(String, u32)>,
    /// Bound globals the entry point does not use.
    pub unused: Vec<String>,
    /// The entry point's workgroup size.
    pub workgroup: [u32; 3],
    /// Whether the entry point, or a function it calls, reads a pipeline-overridable constant.
    pub reads_overrides: bool,
}

/// Whether `function`, or a function it calls, reads a pipeline-overridable constant.
fn reads_overrides(module: &naga::Module, function: &naga::Function) -> bool {
    fn block_calls(block: &naga::Block, out: &mut Vec<naga::Handle<naga::Function>>) {
        use naga::Statement as S;
        for statement in block.iter() {
            match statement {
                S::Call { function, .. } => out.push(*function),
                S::Block(b) => block_calls(b, out),
                S::If { accept, reject, .. } => {
                    block_calls(accept, out);
                    block_calls(reject, out);
                }
                S::Switch { cases, .. } => cases.iter().for_each(|c| block_calls(&c.body, out)),
                S::Loop { body, continuing, .. } => {
                    block_calls(body, out);
                    block_calls(continuing, out);
                }
                _ => {}
            }
        }
    }
    let mut stack = vec![function];
    let mut seen = std::collections::HashSet::new();
    while let Some(f) = stack.pop() {
        if f.expressions.iter().any(|(_, e)| matches!(e, naga::Expression::Override(_))) {
            return true;
        }
        let mut calls = Vec::new();
        block_calls(&f.body, &mut calls);
        stack.extend(calls.into_iter().filter(|h| seen.insert(*h)).map(|h| &module.functions[h]));
    }
    false
}

/// Reads the bind group layout of the `stage` entry point `entry` of the composed WGSL
/// `source`: every global in group 0 the entry point uses (naga's analysis), typed as the shader
/// declares it, visible to that stage. Another group, an unnamed or unsupported binding, or a
/// missing entry point is an error.
pub fn reflect(source: &str, entry: &str, stage: naga::ShaderStage) -> Result<Reflected, String> {
    use naga::{AddressSpace, ImageClass, ImageDimension, ScalarKind, StorageAccess, TypeInner};
    let module = naga::front::wgsl::parse_str(source).map_err(|e| e.emit_to_string(source))?;
    let info = naga::valid::Validator::new(naga::valid::ValidationFlags::all(), naga::valid::Capabilities::all())
        .validate(&module)
        .map_err(|e| format!("{:?}", e.into_inner()))?;
    let index = module
        .entry_points
        .iter()
        .position(|ep| ep.name == entry && ep.stage == stage)
        .ok_or_else(|| format!("no {stage:?} entry point `{entry}`"))?;
    let visibility = match stage {
        naga::ShaderStage::Vertex => wgpu::ShaderStages::VERTEX,
        naga::ShaderStage::Fragment => wgpu::ShaderStages::FRAGMENT,
        _ => wgpu::ShaderStages::COMPUTE,
    };
    let ep_info = info.get_entry_point(index);
    let sampled: Vec<_> = ep_info.sampling_set.iter().map(|k| k.image).collect();
    let mut found = Vec::new();
    let mut unused = Vec::new();
    for (handle, var) in module.global_variables.iter() {
        let Some(rb) = &var.binding else { continue };
        let name = var.name.clone().ok_or_else(|| format!("binding {} has no name", rb.binding))?;
        if ep_info[handle].is_empty() {
            unused.push(name);
            continue;
        }
        if rb.group != 0 {
            return Err(format!("`{name}` is in group {}; passes use group 0 only", rb.group));
        }
        let ty = match (&var.space, &module.types[var.ty].inner) {
            (AddressSpace::Uniform, _) => wgpu::BindingType::Buffer {
                ty: wgpu::BufferBindingType::Uniform,
                has_dynamic_offset: false,
                min_binding_size: None,
            },
            (AddressSpace::Storage { access }, _) => wgpu::BindingType::Buffer {
                ty: wgpu::BufferBindingType::Storage { read_only: !access.contains(StorageAccess::STORE) },
                has_dynamic_offset: false,
                min_binding_size: None,
            },
            (AddressSpace::Handle, TypeInner::Sampler { comparison }) => wgpu::BindingType::Sampler(if *comparison {
                wgpu::SamplerBindingType::Comparison
            } else {
                wgpu::SamplerBindingType::Filtering
            }),
            (AddressSpace::Handle, TypeInner::Image { dim, arrayed, class }) => {
                use wgpu::TextureViewDimension as D;
                let view_dimension = match (dim, arrayed) {
                    (ImageDimension::D1, false) => D::D1,
                    (ImageDimension::D2, false) => D::D2,
                    (ImageDimension::D2, true) => D::D2Array,
                    (ImageDimension::D3, false) => D::D3,
                    (ImageDimension::Cube, false) => D::Cube,
                    (ImageDimension::Cube, true) => D::CubeArray,
                    _ => return Err(format!("`{name}`: unsupported texture dimension")),
                };
                match class {
                    ImageClass::Sampled { kind, multi } => wgpu::BindingType::Texture {
                        sample_type: match kind {
                            ScalarKind::Float => {
                                wgpu::TextureSampleType::Float { filterable: sampled.contains(&handle) }
                            }
                            ScalarKind::Uint => wgpu::TextureSampleType::Uint,
                            ScalarKind::Sint => wgpu::TextureSampleType::Sint,
                            _ => return Err(format!("`{name}`: unsupported texel type")),
                        },
                        view_dimension,
                        multisampled: *multi,
                    },
                    ImageClass::Depth { multi } => wgpu::BindingType::Texture {
                        sample_type: wgpu::TextureSampleType::Depth,
                        view_dimension,
                        multisampled: *multi,
                    },
                    ImageClass::Storage { format, access } => wgpu::BindingType::StorageTexture {
                        access: match (access.contains(StorageAccess::LOAD), access.contains(StorageAccess::STORE)) {
                            (true, true) => wgpu::StorageTextureAccess::ReadWrite,
                            (true, false) => wgpu::StorageTextureAccess::ReadOnly,
                            _ => wgpu::StorageTextureAccess::WriteOnly,
                        },
                        format: storage_format(*format)
                            .ok_or_else(|| format!("`{name}`: unsupported format {format:?}"))?,
                        view_dimension,
                    },
                    ImageClass::External => return Err(format!("`{name}`: external textures are not supported")),
                }
            }
            (space, _) => return Err(format!("`{name}`: unsupported binding in {space:?}")),
        };
        found.push((wgpu::BindGroupLayoutEntry { binding: rb.binding, visibility, ty, count: None }, name));
    }
    found.sort_by_key(|(e, _)| e.binding);
    let workgroup = module.entry_points[index].workgroup_size;
    let slots = found.iter().map(|(e, n)| (n.clone(), e.binding)).collect();
    let reads_overrides = reads_overrides(&module, &module.entry_points[index].function);
    Ok(Reflected { entries: found.into_iter().map(|(e, _)| e).collect(), slots, unused, workgroup, reads_overrides })
}

/// The wgpu format of a WGSL storage texel format the passes use.
fn storage_format(format: naga::StorageFormat) -> Option<wgpu::TextureFormat> {
    use naga::StorageFormat as S;
    use wgpu::TextureFormat as T;
    Some(match format {
        S::Rgba32Float => T::Rgba32Float,
        S::Rgba16Float => T::Rgba16Float,
        S::Rg32Float => T::Rg32Float,
        S::R32Float => T::R32Float,
        S::R32Uint => T::R32Uint,
        S::R32Sint => T::R32Sint,
        S::Rgba32Uint => T::Rgba32Uint,
        S::Rgba8Unorm => T::Rgba8Unorm,
        S::Rg16Float => T::Rg16Float,
        S::R16Float => T::R16Float,
        _ => return None,
    })
}

/// The uniforms every pass may read, named as the passes name them: `frame`, `params` and
/// `lights` (declared by common.wgsl in every module, so a pass that does not read the lights
/// skips them).
pub fn uniform_resources<'a>(buffers: &'a FrameBuffers, params: &'a wgpu::Buffer) -> Vec<Resource<'a>> {
    vec![
        ("frame", buffers.frame.as_entire_binding()),
        ("params", params.as_entire_binding()),
        ("lights", buffers.lights.as_entire_binding()),
    ]
}

/// The frame's resources, named as common.wgsl's passes name them: the uniforms
/// ([`uniform_resources`]), `depth_tex`, `shadow_map` and `spot_tex` (`white`, a one-layer
/// array, stands in when no light has a texture). A pass adds what it writes (`out_tex`, …)
/// and its own inputs.
pub fn frame_resources<'a>(
    buffers: &'a FrameBuffers,
    params: &'a wgpu::Buffer,
    frame: &GpuFrame<'a>,
    white: &'a wgpu::TextureView,
) -> Vec<Resource<'a>> {
    let view = wgpu::BindingResource::TextureView;
    with(
        uniform_resources(buffers, params),
        [
            ("depth_tex", view(frame.depth)),
            ("shadow_map", view(frame.shadow_maps)),
            ("spot_tex", view(frame.spot_textures.unwrap_or(white))),
        ],
    )
}

/// `resources` with `more` added; an entry of `more` replaces the one of the same name.
pub fn with<'a>(mut resources: Vec<Resource<'a>>, more: impl IntoIterator<Item = Resource<'a>>) -> Vec<Resource<'a>> {
    for (name, resource) in more {
        match resources.iter_mut().find(|(n, _)| *n == name) {
            Some(slot) => slot.1 = resource,
            None => resources.push((name, resource)),
        }
    }
    resources
}

#[cfg(test)]
mod tests {
    use super::*;
    use wgpu::TextureViewDimension as D;

    /// Every compute entry point of every library shader, composed as the passes compose it.
    fn compute_entries() -> Vec<(String, String, String)> {
        let mut out = Vec::new();
        for (name, src) in crate::shaders::all_library_shaders() {
            let module = naga::front::wgsl::parse_str(&src).expect(name);
            for ep in module.entry_points.iter().filter(|e| e.stage == naga::ShaderStage::Compute) {
                out.push((name.to_string(), src.clone(), ep.name.clone()));
            }
        }
        out
    }

    fn reflected(name: &str, entry: &str) -> Reflected {
        let (_, src, _) = compute_entries()
            .into_iter()
            .find(|(n, _, e)| n == name && e == entry)
            .unwrap_or_else(|| panic!("no {name}/{entry}"));
        reflect(&src, entry, naga::ShaderStage::Compute).unwrap()
    }

    #[test]
    fn every_library_pass_reflects_its_layout() {
        let entries = compute_entries();
        assert!(entries.len() >= 25, "{} entry points", entries.len());
        for (name, src, entry) in entries {
            let r = reflect(&src, &entry, naga::ShaderStage::Compute).unwrap_or_else(|e| panic!("{name}/{entry}: {e}"));
            assert!(!r.entries.is_empty(), "{name}/{entry} binds nothing");
            assert_eq!(r.entries.len(), r.slots.len());
            // Distinct bindings and names, in binding order.
            for w in r.slots.windows(2) {
                assert!(w[0].1 < w[1].1, "{name}/{entry}: {:?}", r.slots);
            }
            assert!(r.workgroup.iter().all(|&n| n >= 1), "{name}/{entry}: {:?}", r.workgroup);
        }
    }

    #[test]
    fn the_passes_that_evaluate_lights_and_only_they_are_specialized() {
        let read: Vec<String> = compute_entries()
            .into_iter()
            .filter(|(_, src, entry)| reflect(src, entry, naga::ShaderStage::Compute).unwrap().reads_overrides)
            .map(|(name, _, entry)| format!("{name}/{entry}"))
            .collect();
        for must in [
            "brute_force/march/march",
            "interleaved/march/march",
            "subsampled/march/march",
            "subsampled/upsample/upsample",
            "epipolar/march/march",
            "epipolar/upsample/upsample",
            "minmax/traverse/traverse",
            "prefiltered/evaluate/evaluate",
        ] {
            assert!(read.iter().any(|r| r == must), "{must} not in {read:?}");
        }
        for never in ["light_sum/", "light_clear/", "temporal/", "sum_rows", "sum_columns", "/refine", "/args"] {
            assert!(!read.iter().any(|r| r.contains(never)), "{never} in {read:?}");
        }
    }

    #[test]
    fn interleaved_march_layout_is_the_one_its_wgsl_declares() {
        let r = reflected("interleaved/march", "march");
        let names: Vec<(&str, u32)> = r.slots.iter().map(|(n, b)| (n.as_str(), *b)).collect();
        assert_eq!(
            names,
            [
                ("frame", 0),
                ("params", 1),
                ("depth_tex", 2),
                ("shadow_map", 3),
                ("spot_tex", 4),
                ("out_tex", 5),
                ("lut", 6),
                ("lights", LIGHTS_BINDING)
            ]
        );
        let uniform = wgpu::BindingType::Buffer {
            ty: wgpu::BufferBindingType::Uniform,
            has_dynamic_offset: false,
            min_binding_size: None,
        };
        let texture = |dim| wgpu::BindingType::Texture {
            sample_type: wgpu::TextureSampleType::Float { filterable: false },
            view_dimension: dim,
            multisampled: false,
        };
        let types: Vec<wgpu::BindingType> = r.entries.iter().map(|e| e.ty).collect();
        assert_eq!(
            types,
            [
                uniform,
                uniform,
                texture(D::D2),
                texture(D::D2Array),
                texture(D::D2Array),
                wgpu::BindingType::StorageTexture {
                    access: wgpu::StorageTextureAccess::WriteOnly,
                    format: wgpu::TextureFormat::Rgba32Float,
                    view_dimension: D::D2,
                },
                wgpu::BindingType::Buffer {
                    ty: wgpu::BufferBindingType::Storage { read_only: true },
                    has_dynamic_offset: false,
                    min_binding_size: None,
                },
                uniform,
            ]
        );
        assert!(r.entries.iter().all(|e| e.visibility == wgpu::ShaderStages::COMPUTE));
        assert_eq!(r.workgroup, [8, 8, 1]);
    }

    #[test]
    fn a_texture_read_through_a_sampler_is_filterable_and_a_loaded_one_is_not() {
        let r = reflected("prefiltered/evaluate", "evaluate");
        let ty = |name: &str| {
            let i = r.slots.iter().position(|(n, _)| n == name).unwrap_or_else(|| panic!("no {name}"));
            r.entries[i].ty
        };
        let float = |filterable| wgpu::BindingType::Texture {
            sample_type: wgpu::TextureSampleType::Float { filterable },
            view_dimension: D::D2Array,
            multisampled: false,
        };
        assert_eq!(ty("basis_tex"), float(true));
        assert_eq!(ty("cumw_tex"), float(false));
        assert_eq!(ty("basis_sampler"), wgpu::BindingType::Sampler(wgpu::SamplerBindingType::Filtering));
    }

    #[test]
    fn storage_access_and_formats_follow_the_declarations() {
        let r = reflected("epipolar/refine", "refine");
        let ty = |name: &str| r.entries[r.slots.iter().position(|(n, _)| n == name).unwrap()].ty;
        let buffer = |read_only| wgpu::BindingType::Buffer {
            ty: wgpu::BufferBindingType::Storage { read_only },
            has_dynamic_offset: false,
            min_binding_size: None,
        };
        assert_eq!(ty("lines_buf"), buffer(true));
        assert_eq!(ty("counters"), buffer(false));
        assert_eq!(
            ty("interp_tex"),
            wgpu::BindingType::StorageTexture {
                access: wgpu::StorageTextureAccess::WriteOnly,
                format: wgpu::TextureFormat::R32Uint,
                view_dimension: D::D2,
            }
        );
    }

    #[test]
    fn an_entry_point_binds_only_what_it_uses() {
        // light_clear writes its output and reads nothing else, though common.wgsl declares
        // the lights for every module.
        let r = reflected("light_clear", "clear");
        assert_eq!(r.slots, [("out_tex".to_string(), 2)]);
        assert!(r.unused.contains(&"lights".to_string()), "{:?}", r.unused);
        // refine.wgsl's `args` reads the counters and writes the indirect arguments only.
        let args = reflected("epipolar/refine", "args");
        let refine = reflected("epipolar/refine", "refine");
        assert!(args.slots.len() < refine.slots.len(), "{:?} vs {:?}", args.slots, refine.slots);
        assert!(args.slots.iter().any(|(n, _)| n == "dispatch"));
    }

    #[test]
    fn a_missing_entry_point_or_a_foreign_group_is_an_error() {
        let src = crate::shaders::compose(
            "@group(1) @binding(0) var<uniform> u: vec4<f32>;\n@compute @workgroup_size(1) fn main() { _ = u.x; }",
        );
        let e = reflect(&src, "main", naga::ShaderStage::Compute).err().expect("group 1 refused");
        assert!(e.contains("`u`") && e.contains("group 1"), "{e}");
        let e = reflect(&src, "nope", naga::ShaderStage::Compute).err().expect("no entry point");
        assert!(e.contains("nope"), "{e}");
    }
}
