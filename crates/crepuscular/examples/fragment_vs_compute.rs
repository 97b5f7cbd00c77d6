//! The same per-pixel shadow march as a fragment shader (a full-screen triangle, as Bevy's
//! `VolumetricFog` draws inside its fog volume) and as a compute shader (8×8 threads per tile,
//! as the library's techniques run), timed by GPU timestamps around each pass.
//!
//! ```text
//! cargo run --release -p crepuscular --example fragment_vs_compute -- [WIDTHxHEIGHT] [STEPS,...]
//! ```
//!
//! Why it exists: docs/RESULTS.md "Bevy's VolumetricFog against the plugin, NVIDIA H200"
//! compares a fragment-shader effect with compute-shader techniques on one GPU. Where a GPU's
//! fragment path is much slower than its compute path for the same arithmetic (a compute part
//! such as the H200), that comparison measures the GPU rather than the techniques; this
//! example measures the ratio itself. Each step reads one texel of a 1024² shadow map
//! (`textureLoad`, the library's binary test) or takes one hardware-filtered comparison
//! (`textureSampleCompareLevel`, Bevy's 2×2 PCF), and accumulates exp(−t) weights. Prints one
//! line per (lookup, steps): fragment ms, compute ms, ratio. On a software adapter the
//! timestamps mean nothing and it says so; without timestamp queries it exits with an error.

/// The full-screen triangle both fragment passes draw (prepended to their WGSL).
const FULL_SCREEN_VS: &str = r#"
@vertex
fn vs(@builtin(vertex_index) i: u32) -> @builtin(position) vec4<f32> {
    let p = vec2<f32>(f32((i << 1u) & 2u), f32(i & 2u));
    return vec4<f32>(p * 2.0 - 1.0, 0.0, 1.0);
}
"#;

const SHADER: &str = r#"
@group(0) @binding(0) var shadow: texture_depth_2d;
@group(0) @binding(1) var cmp: sampler_comparison;
@group(0) @binding(2) var<uniform> params: vec4<u32>; // width, height, steps, lookup (0 load, 1 compare)
@group(0) @binding(3) var out_image: texture_storage_2d<rgba16float, write>;

// The march of one pixel: a ray through a sun's orthographic map, `steps` samples.
fn march(pixel: vec2<f32>) -> vec4<f32> {
    let size = vec2<f32>(f32(params.x), f32(params.y));
    let uv0 = pixel / size;
    let steps = params.z;
    var sum = 0.0;
    for (var i = 0u; i < steps; i++) {
        let t = (f32(i) + 0.5) / f32(steps);
        let uv = fract(uv0 * 0.7 + vec2<f32>(0.13, 0.29) * t);
        let depth = 0.2 + 0.6 * t;
        var lit = 0.0;
        if params.w == 0u {
            let texel = vec2<i32>(uv * 1023.0);
            lit = select(0.0, 1.0, textureLoad(shadow, texel, 0) >= depth);
        } else {
            lit = textureSampleCompareLevel(shadow, cmp, uv, depth);
        }
        sum += lit * exp(-2.0 * t);
    }
    return vec4<f32>(sum / f32(steps), 0.0, 0.0, 1.0);
}


@fragment
fn fs(@builtin(position) pos: vec4<f32>) -> @location(0) vec4<f32> {
    return march(pos.xy);
}

@compute @workgroup_size(8, 8)
fn cs(@builtin(global_invocation_id) id: vec3<u32>) {
    if id.x >= params.x || id.y >= params.y {
        return;
    }
    textureStore(out_image, id.xy, march(vec2<f32>(id.xy) + 0.5));
}
"#;

fn main() {
    if let Err(e) = run() {
        eprintln!("error: {e}");
        std::process::exit(1);
    }
}

fn run() -> Result<(), String> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let size = args.first().map(String::as_str).unwrap_or("1920x1080");
    let (w, h) = size
        .split_once('x')
        .and_then(|(a, b)| Some((a.parse::<u32>().ok()?, b.parse::<u32>().ok()?)))
        .filter(|&(a, b)| a > 0 && b > 0)
        .ok_or_else(|| format!("size {size:?}: expected WIDTHxHEIGHT, both at least 1"))?;
    let steps: Vec<u32> = match args.get(1) {
        Some(s) => s
            .split(',')
            .map(|v| v.parse::<u32>().ok().filter(|&n| n > 0).ok_or(format!("steps {v:?}: expected a count ≥ 1")))
            .collect::<Result<_, _>>()?,
        None => vec![16, 64, 256],
    };
    let gpu = crepuscular::GpuContext::new().map_err(|e| e.to_string())?;
    gpu.check_texture_size("the output", w, h).map_err(|e| e.to_string())?;
    let (device, queue) = (&gpu.device, &gpu.queue);
    if !device.features().contains(wgpu::Features::TIMESTAMP_QUERY) {
        return Err(format!("{}: no timestamp queries", gpu.describe()));
    }
    println!("adapter: {}", gpu.describe());
    if gpu.software {
        println!("(a software adapter: its timestamps mean nothing; the numbers below are not timings)");
    }

    // A shadow map of stripes and noise, so that both lookups see edges.
    let map = 1024u32;
    let texels: Vec<f32> = (0..map * map)
        .map(|i| {
            let (x, y) = (i % map, i / map);
            let hash = (x.wrapping_mul(73_856_093) ^ y.wrapping_mul(19_349_663)) % 1000;
            if (x / 37 + y / 53) % 2 == 0 { 0.3 + hash as f32 * 1e-4 } else { 0.9 }
        })
        .collect();
    let shadow = device.create_texture(&wgpu::TextureDescriptor {
        label: Some("shadow"),
        size: wgpu::Extent3d { width: map, height: map, depth_or_array_layers: 1 },
        mip_level_count: 1,
        sample_count: 1,
        dimension: wgpu::TextureDimension::D2,
        format: wgpu::TextureFormat::Depth32Float,
        usage: wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::RENDER_ATTACHMENT,
        view_formats: &[],
    });
    // WebGPU copies no buffer into a depth texture: a fragment shader writes frag_depth.
    fill_depth(device, queue, &shadow, &texels, map)?;
    // The fragment pass draws into one texture, the compute pass stores into another (a texture
    // cannot be a pass's colour target and a storage binding of the same pass); the fragment
    // pass's bind group holds a 1×1 storage texture it never writes.
    let drawn = device.create_texture(&wgpu::TextureDescriptor {
        label: Some("fragment out"),
        size: wgpu::Extent3d { width: w, height: h, depth_or_array_layers: 1 },
        mip_level_count: 1,
        sample_count: 1,
        dimension: wgpu::TextureDimension::D2,
        format: wgpu::TextureFormat::Rgba16Float,
        usage: wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::COPY_SRC,
        view_formats: &[],
    });
    let storage = |label, width, height| {
        crepuscular::gpu::storage_texture(device, label, wgpu::TextureFormat::Rgba16Float, width, height)
    };
    let stored = storage("compute out", w, h);
    let unused_view = storage("unused", 1, 1).create_view(&Default::default());
    let (out_view, stored_view) = (drawn.create_view(&Default::default()), stored.create_view(&Default::default()));
    let shadow_view = shadow.create_view(&Default::default());
    let cmp = device.create_sampler(&wgpu::SamplerDescriptor {
        mag_filter: wgpu::FilterMode::Linear,
        min_filter: wgpu::FilterMode::Linear,
        compare: Some(wgpu::CompareFunction::LessEqual),
        ..Default::default()
    });
    let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
        label: Some("fragment_vs_compute"),
        source: wgpu::ShaderSource::Wgsl(format!("{FULL_SCREEN_VS}{SHADER}").into()),
    });
    let vis = wgpu::ShaderStages::COMPUTE | wgpu::ShaderStages::FRAGMENT;
    let bgl = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
        label: Some("fragment_vs_compute"),
        entries: &[
            wgpu::BindGroupLayoutEntry {
                binding: 0,
                visibility: vis,
                ty: wgpu::BindingType::Texture {
                    sample_type: wgpu::TextureSampleType::Depth,
                    view_dimension: wgpu::TextureViewDimension::D2,
                    multisampled: false,
                },
                count: None,
            },
            wgpu::BindGroupLayoutEntry {
                binding: 1,
                visibility: vis,
                ty: wgpu::BindingType::Sampler(wgpu::SamplerBindingType::Comparison),
                count: None,
            },
            wgpu::BindGroupLayoutEntry {
                binding: 2,
                visibility: vis,
                ty: wgpu::BindingType::Buffer {
                    ty: wgpu::BufferBindingType::Uniform,
                    has_dynamic_offset: false,
                    min_binding_size: None,
                },
                count: None,
            },
            wgpu::BindGroupLayoutEntry {
                binding: 3,
                visibility: wgpu::ShaderStages::COMPUTE,
                ty: wgpu::BindingType::StorageTexture {
                    access: wgpu::StorageTextureAccess::WriteOnly,
                    format: wgpu::TextureFormat::Rgba16Float,
                    view_dimension: wgpu::TextureViewDimension::D2,
                },
                count: None,
            },
        ],
    });
    let layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
        label: Some("fragment_vs_compute"),
        bind_group_layouts: &[Some(&bgl)],
        immediate_size: 0,
    });
    let target = [Some(wgpu::ColorTargetState {
        format: wgpu::TextureFormat::Rgba16Float,
        blend: None,
        write_mask: wgpu::ColorWrites::ALL,
    })];
    let render = full_screen_pipeline(device, "fragment march", Some(&layout), &module, &target, None);
    let compute = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
        label: Some("compute march"),
        layout: Some(&layout),
        module: &module,
        entry_point: Some("cs"),
        compilation_options: Default::default(),
        cache: None,
    });
    let params = device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("params"),
        size: 16,
        usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    });
    let bind_with = |storage: &wgpu::TextureView| {
        device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("fragment_vs_compute"),
            layout: &bgl,
            entries: &[
                wgpu::BindGroupEntry { binding: 0, resource: wgpu::BindingResource::TextureView(&shadow_view) },
                wgpu::BindGroupEntry { binding: 1, resource: wgpu::BindingResource::Sampler(&cmp) },
                wgpu::BindGroupEntry { binding: 2, resource: params.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 3, resource: wgpu::BindingResource::TextureView(storage) },
            ],
        })
    };
    let (frag_bind, comp_bind) = (bind_with(&unused_view), bind_with(&stored_view));
    let queries = device.create_query_set(&wgpu::QuerySetDescriptor {
        label: Some("fragment_vs_compute"),
        ty: wgpu::QueryType::Timestamp,
        count: 4,
    });
    let resolve = device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("resolve"),
        size: 32,
        usage: wgpu::BufferUsages::QUERY_RESOLVE | wgpu::BufferUsages::COPY_SRC,
        mapped_at_creation: false,
    });
    let readback = device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("readback"),
        size: 32,
        usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    });
    let period = queue.get_timestamp_period() as f64;
    println!("| lookup | steps | fragment (ms) | compute (ms) | fragment / compute |");
    println!("| --- | ---: | ---: | ---: | ---: |");
    for (lookup, name) in [(0u32, "textureLoad"), (1, "textureSampleCompareLevel (2x2 PCF)")] {
        for &n in &steps {
            queue.write_buffer(&params, 0, bytemuck::cast_slice(&[w, h, n, lookup]));
            // Median of 9 frames after 3 warm-up frames.
            let (mut frag, mut comp) = (Vec::new(), Vec::new());
            for frame in 0..12 {
                let mut enc = device.create_command_encoder(&Default::default());
                {
                    let mut pass = enc.begin_render_pass(&wgpu::RenderPassDescriptor {
                        label: Some("fragment march"),
                        color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                            view: &out_view,
                            depth_slice: None,
                            resolve_target: None,
                            ops: wgpu::Operations {
                                load: wgpu::LoadOp::Clear(wgpu::Color::BLACK),
                                store: wgpu::StoreOp::Store,
                            },
                        })],
                        depth_stencil_attachment: None,
                        timestamp_writes: Some(wgpu::RenderPassTimestampWrites {
                            query_set: &queries,
                            beginning_of_pass_write_index: Some(0),
                            end_of_pass_write_index: Some(1),
                        }),
                        occlusion_query_set: None,
                        multiview_mask: None,
                    });
                    pass.set_pipeline(&render);
                    pass.set_bind_group(0, &frag_bind, &[]);
                    pass.draw(0..3, 0..1);
                }
                {
                    let mut pass = enc.begin_compute_pass(&wgpu::ComputePassDescriptor {
                        label: Some("compute march"),
                        timestamp_writes: Some(wgpu::ComputePassTimestampWrites {
                            query_set: &queries,
                            beginning_of_pass_write_index: Some(2),
                            end_of_pass_write_index: Some(3),
                        }),
                    });
                    pass.set_pipeline(&compute);
                    pass.set_bind_group(0, &comp_bind, &[]);
                    pass.dispatch_workgroups(w.div_ceil(8), h.div_ceil(8), 1);
                }
                enc.resolve_query_set(&queries, 0..4, &resolve, 0);
                enc.copy_buffer_to_buffer(&resolve, 0, &readback, 0, 32);
                queue.submit([enc.finish()]);
                let t = gpu
                    .read_mapped(&readback, "timestamps", |b| bytemuck::cast_slice::<u8, u64>(b).to_vec())
                    .map_err(|e| e.to_string())?;
                if frame >= 3 {
                    frag.push(t[1].wrapping_sub(t[0]) as f64 * period / 1e6);
                    comp.push(t[3].wrapping_sub(t[2]) as f64 * period / 1e6);
                }
            }
            let med = |v: &mut Vec<f64>| {
                v.sort_by(f64::total_cmp);
                v[v.len() / 2]
            };
            // Both passes computed the same picture (so neither skipped the work).
            let a = gpu.read_texture_f32(&drawn, 0).map_err(|e| e.to_string())?;
            let b = gpu.read_texture_f32(&stored, 0).map_err(|e| e.to_string())?;
            let worst = a.iter().zip(&b).map(|(x, y)| (x - y).abs()).fold(0.0f32, f32::max);
            if worst > 2e-3 {
                return Err(format!("{name}, {n} steps: the two passes differ by up to {worst}"));
            }
            let (f, c) = (med(&mut frag), med(&mut comp));
            println!("| {name} | {n} | {f:.3} | {c:.3} | {:.1} |", f / c.max(1e-9));
        }
    }
    Ok(())
}

/// Writes `texels` (row-major, `map`²) into a `Depth32Float` texture: a full-screen triangle
/// whose fragment shader sets `frag_depth` from a storage buffer.
fn fill_depth(
    device: &wgpu::Device,
    queue: &wgpu::Queue,
    target: &wgpu::Texture,
    texels: &[f32],
    map: u32,
) -> Result<(), String> {
    const FILL: &str = r#"
@group(0) @binding(0) var<storage, read> depth: array<f32>;
@group(0) @binding(1) var<uniform> size: vec4<u32>;
@fragment
fn fs(@builtin(position) pos: vec4<f32>) -> @builtin(frag_depth) f32 {
    let p = vec2<u32>(pos.xy);
    return depth[p.y * size.x + p.x];
}
"#;
    use wgpu::util::DeviceExt;
    let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
        label: Some("fill depth"),
        source: wgpu::ShaderSource::Wgsl(format!("{FULL_SCREEN_VS}{FILL}").into()),
    });
    let data = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: Some("depth texels"),
        contents: bytemuck::cast_slice(texels),
        usage: wgpu::BufferUsages::STORAGE,
    });
    let size = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: Some("size"),
        contents: bytemuck::cast_slice(&[map, map, 0, 0]),
        usage: wgpu::BufferUsages::UNIFORM,
    });
    let depth = wgpu::DepthStencilState {
        format: wgpu::TextureFormat::Depth32Float,
        depth_write_enabled: Some(true),
        depth_compare: Some(wgpu::CompareFunction::Always),
        stencil: Default::default(),
        bias: Default::default(),
    };
    let pipeline = full_screen_pipeline(device, "fill depth", None, &module, &[], Some(depth));
    let bind = device.create_bind_group(&wgpu::BindGroupDescriptor {
        label: Some("fill depth"),
        layout: &pipeline.get_bind_group_layout(0),
        entries: &[
            wgpu::BindGroupEntry { binding: 0, resource: data.as_entire_binding() },
            wgpu::BindGroupEntry { binding: 1, resource: size.as_entire_binding() },
        ],
    });
    let view = target.create_view(&Default::default());
    let mut enc = device.create_command_encoder(&Default::default());
    {
        let mut pass = enc.begin_render_pass(&wgpu::RenderPassDescriptor {
            label: Some("fill depth"),
            color_attachments: &[],
            depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
                view: &view,
                depth_ops: Some(wgpu::Operations { load: wgpu::LoadOp::Clear(0.0), store: wgpu::StoreOp::Store }),
                stencil_ops: None,
            }),
            timestamp_writes: None,
            occlusion_query_set: None,
            multiview_mask: None,
        });
        pass.set_pipeline(&pipeline);
        pass.set_bind_group(0, &bind, &[]);
        pass.draw(0..3, 0..1);
    }
    queue.submit([enc.finish()]);
    crepuscular::gpu::wait_idle(device).map_err(|e| e.to_string())
}

/// A pipeline drawing [`FULL_SCREEN_VS`]'s triangle with `module`'s `vs` and `fs`.
fn full_screen_pipeline(
    device: &wgpu::Device,
    label: &str,
    layout: Option<&wgpu::PipelineLayout>,
    module: &wgpu::ShaderModule,
    targets: &[Option<wgpu::ColorTargetState>],
    depth_stencil: Option<wgpu::DepthStencilState>,
) -> wgpu::RenderPipeline {
    device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
        label: Some(label),
        layout,
        vertex: wgpu::VertexState {
            module,
            entry_point: Some("vs"),
            compilation_options: Default::default(),
            buffers: &[],
        },
        fragment: Some(wgpu::FragmentState {
            module,
            entry_point: Some("fs"),
            compilation_options: Default::default(),
            targets,
        }),
        primitive: Default::default(),
        depth_stencil,
        multisample: Default::default(),
        multiview_mask: None,
        cache: None,
    })
}
