//! Using crepuscular from your own wgpu renderer. The example is the engine: it draws its own
//! tiny scene (a ground slab and a floating grate) with its own WGSL and pipelines —
//! 1. a depth-only shadow pass from the sun into its shadow map,
//! 2. a camera pass: lit, shadowed surface colour (`Rgba16Float`) and the depth buffer,
//! 3. crepuscular's `brute-force` technique, handed the engine's depth buffer, shadow map and
//!    matrices, which writes the in-scattered light (god rays) into an `Rgba32Float` texture,
//! 4. the engine's composite: L = T(s)·L_surface + L_scatt with T(s) = exp(−σt·s) (s = the
//!    distance to the surface, rebuilt from depth), tone-mapped into `Rgba8Unorm`,
//!
//! then checks the picture (shafts in the fog, shadows on the ground) and saves it.
//!
//! What the engine supplies, per frame: a camera depth buffer (`Depth32Float`, standard [0, 1]
//! depth, not reversed-Z), a shadow map (`Depth32Float`, sampled as a 2D array), the camera and
//! light matrices those were rendered with, and the light and fog parameters.
//!
//! Run: `cargo run --release -p crepuscular --example own_renderer [-- OUT.ppm]` (default
//! `own_renderer.ppm`); it exits with an error when a check fails.

use crepuscular::frame::{FrameDesc, GpuFrame};
use crepuscular::{Camera, GpuContext, Light, Medium, Scattering, ShadowProjection, TechniqueSettings};
use glam::{Mat4, Vec3};
use wgpu::util::DeviceExt;

const WIDTH: u32 = 320;
const HEIGHT: u32 = 180;
const SHADOW_SIZE: u32 = 1024;

/// The engine's own depth-only shader: one world → clip matrix per pass.
const DEPTH_WGSL: &str = "
@group(0) @binding(0) var<uniform> view_proj: mat4x4<f32>;
@vertex fn vs(@location(0) p: vec3<f32>) -> @builtin(position) vec4<f32> {
    return view_proj * vec4<f32>(p, 1.0);
}";

/// The engine's lit shader: flat normals from screen-space derivatives, the sun's N·L, a
/// comparison lookup in the engine's shadow map, a little ambient.
const LIT_WGSL: &str = "
struct Lit { view_proj: mat4x4<f32>, light_vp: mat4x4<f32>, sun_dir: vec4<f32>, sun_rgb: vec4<f32>, eye: vec4<f32> }
@group(0) @binding(0) var<uniform> u: Lit;
@group(0) @binding(1) var shadow_map: texture_depth_2d;
@group(0) @binding(2) var shadow_cmp: sampler_comparison;
struct VOut { @builtin(position) clip: vec4<f32>, @location(0) world: vec3<f32> }
@vertex fn vs(@location(0) p: vec3<f32>) -> VOut {
    return VOut(u.view_proj * vec4<f32>(p, 1.0), p);
}
@fragment fn fs(i: VOut) -> @location(0) vec4<f32> {
    var n = normalize(cross(dpdx(i.world), dpdy(i.world)));
    n = select(n, -n, dot(n, u.eye.xyz - i.world) < 0.0);
    let s = u.light_vp * vec4<f32>(i.world + 0.05 * n, 1.0);
    let uv = vec2<f32>(s.x * 0.5 + 0.5, 0.5 - s.y * 0.5);
    let lit = textureSampleCompare(shadow_map, shadow_cmp, uv, s.z - 0.001);
    let albedo = 0.6;
    return vec4<f32>(albedo * (u.sun_rgb.rgb * max(dot(n, -u.sun_dir.xyz), 0.0) * lit + vec3<f32>(0.03)), 1.0);
}";

/// The engine's composite: L = T(s)·L_surface + L_scatt, then a tone curve. Sky pixels (depth 1)
/// have no surface; crepuscular marched them to the far plane.
const COMPOSITE_WGSL: &str = "
struct Comp { inv_view_proj: mat4x4<f32>, eye: vec4<f32>, sigma_t: vec4<f32> }
@group(0) @binding(0) var<uniform> c: Comp;
@group(0) @binding(1) var surface: texture_2d<f32>;
@group(0) @binding(2) var depth: texture_depth_2d;
@group(0) @binding(3) var inscatter: texture_2d<f32>;
@vertex fn vs(@builtin(vertex_index) i: u32) -> @builtin(position) vec4<f32> {
    let uv = vec2<f32>(f32((i << 1u) & 2u), f32(i & 2u));
    return vec4<f32>(uv * 2.0 - 1.0, 0.0, 1.0);
}
@fragment fn fs(@builtin(position) frag: vec4<f32>) -> @location(0) vec4<f32> {
    let px = vec2<i32>(frag.xy);
    let d = textureLoad(depth, px, 0);
    var l = textureLoad(inscatter, px, 0).rgb;
    if d < 1.0 {
        let size = vec2<f32>(textureDimensions(depth));
        let ndc = vec2<f32>(frag.x / size.x * 2.0 - 1.0, 1.0 - frag.y / size.y * 2.0);
        let w = c.inv_view_proj * vec4<f32>(ndc, d, 1.0);
        let s = distance(w.xyz / w.w, c.eye.xyz);
        l += textureLoad(surface, px, 0).rgb * exp(-c.sigma_t.rgb * s);
    }
    return vec4<f32>(1.0 - exp(-l), 1.0);
}";

/// 36 vertices (12 triangles) of an axis-aligned box.
fn cuboid(a: Vec3, b: Vec3) -> Vec<[f32; 3]> {
    let c = |i: usize| {
        [if i & 1 == 0 { a.x } else { b.x }, if i & 2 == 0 { a.y } else { b.y }, if i & 4 == 0 { a.z } else { b.z }]
    };
    let faces = [[0, 1, 3, 2], [4, 6, 7, 5], [0, 4, 5, 1], [2, 3, 7, 6], [0, 2, 6, 4], [1, 5, 7, 3]];
    faces.iter().flat_map(|f| [f[0], f[1], f[2], f[0], f[2], f[3]].map(c)).collect()
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    // 1. The device. An engine that already owns an adapter wraps it instead:
    //    `GpuContext::from_adapter(adapter)?` (crepuscular then uses that adapter's device).
    let gpu = match GpuContext::new() {
        Ok(gpu) => gpu,
        Err(e) => {
            eprintln!("own_renderer needs a GPU adapter (Vulkan, Metal, DX12 or lavapipe): {e}");
            std::process::exit(1);
        }
    };
    println!("adapter: {}", gpu.describe());
    let device = &gpu.device;

    // 2. The engine's scene: a 40 m ground slab and a grate of four bars floating 5 m up.
    let mut verts = cuboid(Vec3::new(-20.0, -0.1, -20.0), Vec3::new(20.0, 0.0, 20.0));
    for i in 0..4 {
        let x = -3.5 + 2.0 * i as f32;
        verts.extend(cuboid(Vec3::new(x, 5.0, -4.0), Vec3::new(x + 1.0, 5.3, 1.0)));
    }
    let vertex_buffer = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: Some("scene"),
        contents: bytemuck::cast_slice(&verts),
        usage: wgpu::BufferUsages::VERTEX,
    });

    // The engine's camera and sun. crepuscular rebuilds the camera's view rays from `Camera`
    // (look_at_rh × perspective_rh), so the depth pass below uses exactly that matrix.
    let camera = Camera {
        position: Vec3::new(0.0, 1.7, 14.0),
        look_at: Vec3::new(0.0, 3.5, 0.0),
        fov_y_degrees: 60.0,
        near: 0.1,
        far: 60.0,
        ..Default::default()
    };
    let camera_vp = camera.view_projection(WIDTH as f32 / HEIGHT as f32);
    let sun_dir = Vec3::new(0.15, -0.55, 1.0).normalize(); // the direction the light travels
    let (sun_color, sun_intensity) = (Vec3::new(1.0, 0.9, 0.75), 2.0);
    let medium = Medium { scattering: Vec3::splat(0.04), absorption: Vec3::splat(0.005), ..Default::default() };
    // The engine's own directional shadow projection: an orthographic box of half-width R
    // around the scene, seen from the sun. Depth is [0, 1] from `near` to `far`, linear.
    let (center, r) = (Vec3::new(0.0, 2.0, 0.0), 25.0);
    let (light_near, light_far) = (0.1, 4.0 * r);
    let light_view = Mat4::look_at_rh(center - sun_dir * (2.0 * r), center, Vec3::Y);
    let light_vp = Mat4::orthographic_rh(-r, r, -r, r, light_near, light_far) * light_view;

    // The engine's render targets. crepuscular needs both as sampled textures (TEXTURE_BINDING).
    let depth_texture = |label, w, h| {
        device.create_texture(&wgpu::TextureDescriptor {
            label: Some(label),
            size: wgpu::Extent3d { width: w, height: h, depth_or_array_layers: 1 },
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format: wgpu::TextureFormat::Depth32Float,
            usage: wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::TEXTURE_BINDING,
            view_formats: &[],
        })
    };
    let shadow_map = depth_texture("shadow map", SHADOW_SIZE, SHADOW_SIZE);
    let depth = depth_texture("camera depth", WIDTH, HEIGHT);
    let color_target = |label, format, usage| {
        device.create_texture(&wgpu::TextureDescriptor {
            label: Some(label),
            size: wgpu::Extent3d { width: WIDTH, height: HEIGHT, depth_or_array_layers: 1 },
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format,
            usage: wgpu::TextureUsages::RENDER_ATTACHMENT | usage,
            view_formats: &[],
        })
    };
    let surface =
        color_target("surface colour", wgpu::TextureFormat::Rgba16Float, wgpu::TextureUsages::TEXTURE_BINDING);
    let final_image = color_target("final image", wgpu::TextureFormat::Rgba8Unorm, wgpu::TextureUsages::COPY_SRC);

    // The engine's two scene pipelines over the same vertices, depth-tested: depth only (WGSL
    // `vs`, no fragment stage) for the shadow pass, and lit colour + depth for the camera pass.
    let scene_pipeline = |label: &str, wgsl: &str, color: Option<wgpu::TextureFormat>| {
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some(label),
            source: wgpu::ShaderSource::Wgsl(wgsl.into()),
        });
        let targets = [color.map(wgpu::ColorTargetState::from)];
        device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
            label: Some(label),
            layout: None,
            vertex: wgpu::VertexState {
                module: &module,
                entry_point: Some("vs"),
                compilation_options: Default::default(),
                buffers: &[wgpu::VertexBufferLayout {
                    array_stride: 12,
                    step_mode: wgpu::VertexStepMode::Vertex,
                    attributes: &wgpu::vertex_attr_array![0 => Float32x3],
                }],
            },
            primitive: wgpu::PrimitiveState::default(), // cull_mode: None
            depth_stencil: Some(wgpu::DepthStencilState {
                format: wgpu::TextureFormat::Depth32Float,
                depth_write_enabled: Some(true),
                depth_compare: Some(wgpu::CompareFunction::Less),
                stencil: Default::default(),
                bias: Default::default(),
            }),
            multisample: Default::default(),
            fragment: color.map(|_| wgpu::FragmentState {
                module: &module,
                entry_point: Some("fs"),
                compilation_options: Default::default(),
                targets: &targets,
            }),
            multiview_mask: None,
            cache: None,
        })
    };
    let pipeline = scene_pipeline("depth only", DEPTH_WGSL, None);
    let lit_pipeline = scene_pipeline("lit", LIT_WGSL, Some(wgpu::TextureFormat::Rgba16Float));
    let uniform = |label, bytes: &[u8]| {
        device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some(label),
            contents: bytes,
            usage: wgpu::BufferUsages::UNIFORM,
        })
    };
    let mut encoder = device.create_command_encoder(&Default::default());
    {
        // Shadow pass.
        let vp = uniform("light view_proj", bytemuck::cast_slice(&light_vp.to_cols_array()));
        let bind = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("light view_proj"),
            layout: &pipeline.get_bind_group_layout(0),
            entries: &[wgpu::BindGroupEntry { binding: 0, resource: vp.as_entire_binding() }],
        });
        let view = shadow_map.create_view(&Default::default());
        let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
            label: Some("shadow pass"),
            color_attachments: &[],
            depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
                view: &view,
                depth_ops: Some(wgpu::Operations { load: wgpu::LoadOp::Clear(1.0), store: wgpu::StoreOp::Store }),
                stencil_ops: None,
            }),
            timestamp_writes: None,
            occlusion_query_set: None,
            multiview_mask: None,
        });
        pass.set_pipeline(&pipeline);
        pass.set_bind_group(0, &bind, &[]);
        pass.set_vertex_buffer(0, vertex_buffer.slice(..));
        pass.draw(0..verts.len() as u32, 0..1);
    }
    {
        // Camera pass: lit surfaces and the depth buffer crepuscular will read.
        let mut lit = Vec::new();
        lit.extend_from_slice(&camera_vp.to_cols_array());
        lit.extend_from_slice(&light_vp.to_cols_array());
        lit.extend_from_slice(&sun_dir.extend(0.0).to_array());
        lit.extend_from_slice(&(sun_color * sun_intensity).extend(0.0).to_array());
        lit.extend_from_slice(&camera.position.extend(1.0).to_array());
        let lit = uniform("lit uniforms", bytemuck::cast_slice(&lit));
        let shadow_2d = shadow_map.create_view(&Default::default());
        let compare = device.create_sampler(&wgpu::SamplerDescriptor {
            label: Some("shadow compare"),
            compare: Some(wgpu::CompareFunction::LessEqual),
            mag_filter: wgpu::FilterMode::Linear,
            min_filter: wgpu::FilterMode::Linear,
            ..Default::default()
        });
        let bind = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("lit"),
            layout: &lit_pipeline.get_bind_group_layout(0),
            entries: &[
                wgpu::BindGroupEntry { binding: 0, resource: lit.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 1, resource: wgpu::BindingResource::TextureView(&shadow_2d) },
                wgpu::BindGroupEntry { binding: 2, resource: wgpu::BindingResource::Sampler(&compare) },
            ],
        });
        let (color_view, depth_view) =
            (surface.create_view(&Default::default()), depth.create_view(&Default::default()));
        let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
            label: Some("camera pass"),
            color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                view: &color_view,
                depth_slice: None,
                resolve_target: None,
                ops: wgpu::Operations { load: wgpu::LoadOp::Clear(wgpu::Color::BLACK), store: wgpu::StoreOp::Store },
            })],
            depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
                view: &depth_view,
                depth_ops: Some(wgpu::Operations { load: wgpu::LoadOp::Clear(1.0), store: wgpu::StoreOp::Store }),
                stencil_ops: None,
            }),
            timestamp_writes: None,
            occlusion_query_set: None,
            multiview_mask: None,
        });
        pass.set_pipeline(&lit_pipeline);
        pass.set_bind_group(0, &bind, &[]);
        pass.set_vertex_buffer(0, vertex_buffer.slice(..));
        pass.draw(0..verts.len() as u32, 0..1);
    }
    gpu.queue.submit([encoder.finish()]);

    // 3. The frame boundary: the same camera, the sun, the fog, and the shadow projection the
    //    shadow map was rendered with (one layer; six only for a point light's cube map).
    let desc = FrameDesc {
        camera: camera.clone(),
        light: Light::Directional { direction: sun_dir, color: sun_color, intensity: sun_intensity },
        medium: medium.clone(),
        shadow: ShadowProjection {
            view_proj: [light_vp; 6],
            layers: 1,
            near: light_near,
            far: light_far,
            orthographic: true,
            size: SHADOW_SIZE,
            texel_world: 2.0 * r / SHADOW_SIZE as f32,
        },
        shadow_bias: 0.02,         // world units along the light's depth axis
        normal_offset_texels: 0.0, // only used by crepuscular's own surface shading
        ambient: Vec3::ZERO,
        width: WIDTH,
        height: HEIGHT,
    };
    // The views crepuscular reads: depth aspect only, the shadow map as a 2D array.
    let depth_view = depth
        .create_view(&wgpu::TextureViewDescriptor { aspect: wgpu::TextureAspect::DepthOnly, ..Default::default() });
    let shadow_view = shadow_map.create_view(&wgpu::TextureViewDescriptor {
        dimension: Some(wgpu::TextureViewDimension::D2Array),
        aspect: wgpu::TextureAspect::DepthOnly,
        ..Default::default()
    });
    let output = gpu.create_output_texture(WIDTH, HEIGHT);
    let output_view = output.create_view(&Default::default());
    let frame = GpuFrame {
        desc: &desc,
        depth: &depth_view,
        shadow_map: &shadow_view,
        spot_texture: None,
        rectified_shadow_map: None,
    };
    // Build once, call every frame. The result is in-scattered radiance only: the engine adds it
    // to its lit surfaces attenuated by exp(-σt·distance) (see crepuscular::tonemap::composite).
    let mut technique = Scattering::new(&gpu.device, &gpu.queue, TechniqueSettings::named("brute-force")?)?;
    let stats = technique.render(&frame, &output_view)?;

    // 4. The engine's composite: its surface colour, attenuated by the fog between the eye and
    //    the surface, plus crepuscular's in-scattering; then a tone curve.
    let composite = device.create_shader_module(wgpu::ShaderModuleDescriptor {
        label: Some("composite"),
        source: wgpu::ShaderSource::Wgsl(COMPOSITE_WGSL.into()),
    });
    // An explicit layout: `Rgba32Float` (the in-scattering) is not filterable, so its binding
    // must say so; the shader reads every texture with `textureLoad`.
    let texture_entry = |binding, sample_type| wgpu::BindGroupLayoutEntry {
        binding,
        visibility: wgpu::ShaderStages::FRAGMENT,
        ty: wgpu::BindingType::Texture {
            sample_type,
            view_dimension: wgpu::TextureViewDimension::D2,
            multisampled: false,
        },
        count: None,
    };
    let composite_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
        label: Some("composite"),
        entries: &[
            wgpu::BindGroupLayoutEntry {
                binding: 0,
                visibility: wgpu::ShaderStages::FRAGMENT,
                ty: wgpu::BindingType::Buffer {
                    ty: wgpu::BufferBindingType::Uniform,
                    has_dynamic_offset: false,
                    min_binding_size: None,
                },
                count: None,
            },
            texture_entry(1, wgpu::TextureSampleType::Float { filterable: false }),
            texture_entry(2, wgpu::TextureSampleType::Depth),
            texture_entry(3, wgpu::TextureSampleType::Float { filterable: false }),
        ],
    });
    let composite_pipeline = device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
        label: Some("composite"),
        layout: Some(&device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("composite"),
            bind_group_layouts: &[Some(&composite_layout)],
            immediate_size: 0,
        })),
        vertex: wgpu::VertexState {
            module: &composite,
            entry_point: Some("vs"),
            compilation_options: Default::default(),
            buffers: &[],
        },
        primitive: Default::default(),
        depth_stencil: None,
        multisample: Default::default(),
        fragment: Some(wgpu::FragmentState {
            module: &composite,
            entry_point: Some("fs"),
            compilation_options: Default::default(),
            targets: &[Some(wgpu::TextureFormat::Rgba8Unorm.into())],
        }),
        multiview_mask: None,
        cache: None,
    });
    let mut comp = Vec::new();
    comp.extend_from_slice(&camera_vp.inverse().to_cols_array());
    comp.extend_from_slice(&camera.position.extend(1.0).to_array());
    comp.extend_from_slice(&medium.extinction().extend(0.0).to_array());
    let comp = uniform("composite uniforms", bytemuck::cast_slice(&comp));
    let surface_view = surface.create_view(&Default::default());
    let bind = device.create_bind_group(&wgpu::BindGroupDescriptor {
        label: Some("composite"),
        layout: &composite_layout,
        entries: &[
            wgpu::BindGroupEntry { binding: 0, resource: comp.as_entire_binding() },
            wgpu::BindGroupEntry { binding: 1, resource: wgpu::BindingResource::TextureView(&surface_view) },
            wgpu::BindGroupEntry { binding: 2, resource: wgpu::BindingResource::TextureView(&depth_view) },
            wgpu::BindGroupEntry { binding: 3, resource: wgpu::BindingResource::TextureView(&output_view) },
        ],
    });
    let final_view = final_image.create_view(&Default::default());
    let mut encoder = device.create_command_encoder(&Default::default());
    {
        let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
            label: Some("composite"),
            color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                view: &final_view,
                depth_slice: None,
                resolve_target: None,
                ops: wgpu::Operations { load: wgpu::LoadOp::Clear(wgpu::Color::BLACK), store: wgpu::StoreOp::Store },
            })],
            depth_stencil_attachment: None,
            timestamp_writes: None,
            occlusion_query_set: None,
            multiview_mask: None,
        });
        pass.set_pipeline(&composite_pipeline);
        pass.set_bind_group(0, &bind, &[]);
        pass.draw(0..3, 0..1);
    }
    gpu.queue.submit([encoder.finish()]);

    // 5. Read back, check, report and save.
    for p in &stats.passes {
        println!("pass {:<8} {:8.3} ms ({})", p.name, p.ms, stats.timing);
    }
    let pixel_of = |p: Vec3| {
        let ndc = camera_vp.project_point3(p);
        let x = ((ndc.x * 0.5 + 0.5) * WIDTH as f32).clamp(0.0, WIDTH as f32 - 1.0) as u32;
        let y = ((0.5 - ndc.y * 0.5) * HEIGHT as f32).clamp(0.0, HEIGHT as f32 - 1.0) as u32;
        (y * WIDTH + x) as usize
    };
    // A point on the ground in bar 2's shadow, and one 1 m beside it (under a gap, in the sun).
    let ground_shadow = Vec3::new(-1.0, 5.0, -1.5) + sun_dir * (5.0 / -sun_dir.y);
    let (in_shadow, in_sun) = (pixel_of(ground_shadow), pixel_of(ground_shadow + Vec3::X));
    let mut failures = Vec::new();

    let img = gpu.read_image(&output)?;
    let lum: Vec<f32> = img.pixels.iter().map(|p| 0.2126 * p[0] + 0.7152 * p[1] + 0.0722 * p[2]).collect();
    let mean = lum.iter().sum::<f32>() / lum.len() as f32;
    let (min, max) = lum.iter().fold((f32::MAX, f32::MIN), |(a, b), &v| (a.min(v), b.max(v)));
    println!("in-scattering luminance: mean {mean:.4}, min {min:.4}, max {max:.4}");
    // The view ray to the shadowed ground runs through the bar's shadow volume, the ray beside
    // it does not, so it gathers more light: a shaft.
    let (a, b) = (lum[in_shadow], lum[in_sun]);
    println!("in-scattering towards the shadowed ground {a:.4}, beside it {b:.4}");
    if !(b > 1.1 * a) {
        failures.push("no light shaft: the in-scattering is not lower through the bar's shadow");
    }

    let rgba = gpu.read_texture_bytes(&final_image, 0)?;
    let rgb: Vec<u8> = rgba.chunks_exact(4).flat_map(|p| [p[0], p[1], p[2]]).collect();
    let luma = |i: usize| 0.2126 * rgb[3 * i] as f32 + 0.7152 * rgb[3 * i + 1] as f32 + 0.0722 * rgb[3 * i + 2] as f32;
    let final_mean = (0..lum.len()).map(luma).sum::<f32>() / lum.len() as f32;
    let (a, b) = (luma(in_shadow), luma(in_sun));
    println!("final image: mean {final_mean:.1} / 255; the shadowed ground {a:.1}, beside it in the sun {b:.1}");
    if final_mean < 10.0 {
        failures.push("the final image is (nearly) black");
    }
    if !(b > a + 10.0) {
        failures.push("the ground in the bar's shadow is not darker than the ground in the sun");
    }

    let path = std::env::args().nth(1).unwrap_or_else(|| "own_renderer.ppm".into());
    let mut ppm = format!("P6\n{WIDTH} {HEIGHT}\n255\n").into_bytes();
    ppm.extend_from_slice(&rgb);
    std::fs::write(&path, ppm)?;
    println!("wrote {path}");
    if !failures.is_empty() {
        return Err(failures.join("; ").into());
    }
    println!("checks passed: light shafts in the fog, shadows on the ground");
    Ok(())
}
