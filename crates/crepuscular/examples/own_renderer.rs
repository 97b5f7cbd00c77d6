//! Using crepuscular from your own wgpu renderer: the example draws its own tiny scene (a
//! ground quad and a floating grate) with its own WGSL and pipelines into its own shadow map and
//! camera depth buffer, then hands those textures and the matrices it used to the brute-force
//! technique, which writes the in-scattered light (god rays) into an `Rgba32Float` texture.
//!
//! What the engine supplies, per frame: a camera depth buffer (`Depth32Float`, standard [0, 1]
//! depth, not reversed-Z), a shadow map (`Depth32Float`, sampled as a 2D array), the camera and
//! light matrices those were rendered with, and the light and fog parameters.
//!
//! Run: `cargo run --release -p crepuscular --example own_renderer` (writes `own_renderer.ppm`).

use crepuscular::frame::{FrameDesc, GpuFrame};
use crepuscular::techniques::brute_force::BruteForce;
use crepuscular::{Camera, GpuContext, Light, Medium, ShadowProjection};
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

    // The engine's depth-only pipeline, used for both passes with a different matrix each.
    let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
        label: Some("depth"),
        source: wgpu::ShaderSource::Wgsl(DEPTH_WGSL.into()),
    });
    let pipeline = device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
        label: Some("depth only"),
        layout: None,
        vertex: wgpu::VertexState {
            module: &module,
            entry_point: Some("vs"),
            compilation_options: Default::default(),
            buffers: &[Some(wgpu::VertexBufferLayout {
                array_stride: 12,
                step_mode: wgpu::VertexStepMode::Vertex,
                attributes: &wgpu::vertex_attr_array![0 => Float32x3],
            })],
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
        fragment: None,
        multiview_mask: None,
        cache: None,
    });
    let mut encoder = device.create_command_encoder(&Default::default());
    for (label, target, vp) in [("shadow pass", &shadow_map, light_vp), ("depth pre-pass", &depth, camera_vp)] {
        let uniforms = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("view_proj"),
            contents: bytemuck::cast_slice(&vp.to_cols_array()),
            usage: wgpu::BufferUsages::UNIFORM,
        });
        let bind = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("view_proj"),
            layout: &pipeline.get_bind_group_layout(0),
            entries: &[wgpu::BindGroupEntry { binding: 0, resource: uniforms.as_entire_binding() }],
        });
        let view = target.create_view(&Default::default());
        let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
            label: Some(label),
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
    gpu.queue.submit([encoder.finish()]);

    // 3. The frame boundary: the same camera, the sun, the fog, and the shadow projection the
    //    shadow map was rendered with (one layer; six only for a point light's cube map).
    let desc = FrameDesc {
        camera,
        light: Light::Directional { direction: sun_dir, color: Vec3::new(1.0, 0.9, 0.75), intensity: 2.0 },
        medium: Medium { scattering: Vec3::splat(0.04), absorption: Vec3::splat(0.005), ..Default::default() },
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
    let frame = GpuFrame { desc: &desc, depth: &depth_view, shadow_map: &shadow_view, spot_texture: None };
    // Build once, call every frame. The result is in-scattered radiance only: the engine adds it
    // to its lit surfaces attenuated by exp(-σt·distance) (see crepuscular::tonemap::composite).
    let mut technique = BruteForce::new(&gpu, Default::default())?;
    let stats = technique.render(&gpu, &frame, &output_view)?;

    // 4. Read back, report, and save a tone-mapped picture.
    for p in &stats.passes {
        println!("pass {:<8} {:8.3} ms ({})", p.name, p.ms, stats.timing);
    }
    let img = gpu.read_image(&output)?;
    let lum: Vec<f32> = img.pixels.iter().map(|p| 0.2126 * p[0] + 0.7152 * p[1] + 0.0722 * p[2]).collect();
    let mean = lum.iter().sum::<f32>() / lum.len() as f32;
    let (min, max) = lum.iter().fold((f32::MAX, f32::MIN), |(a, b), &v| (a.min(v), b.max(v)));
    println!("in-scattering luminance: mean {mean:.4}, min {min:.4}, max {max:.4}");
    // Sanity check: the view ray to the ground in a bar's shadow crosses that bar's shaft, the
    // ray to the ground 1 m beside it (under a gap) does not, so it gathers more light.
    let pixel = |p: Vec3| {
        let ndc = camera_vp.project_point3(p);
        let x = ((ndc.x * 0.5 + 0.5) * WIDTH as f32).clamp(0.0, WIDTH as f32 - 1.0) as u32;
        let y = ((0.5 - ndc.y * 0.5) * HEIGHT as f32).clamp(0.0, HEIGHT as f32 - 1.0) as u32;
        lum[(y * WIDTH + x) as usize]
    };
    let ground_shadow = Vec3::new(-1.0, 5.0, -1.5) + sun_dir * (5.0 / -sun_dir.y); // under bar 2
    let (shadowed, lit) = (pixel(ground_shadow), pixel(ground_shadow + Vec3::X));
    let verdict = if lit > 1.1 * shadowed { "shafts visible" } else { "NO SHAFTS?" };
    println!("in the shaft {shadowed:.4}, beside it {lit:.4}: {verdict}");
    let rgb = crepuscular::tonemap::ToneMap::new(1.0).to_rgb8(&img);
    let mut ppm = format!("P6\n{WIDTH} {HEIGHT}\n255\n").into_bytes();
    ppm.extend_from_slice(&rgb);
    std::fs::write("own_renderer.ppm", ppm)?;
    println!("wrote own_renderer.ppm");
    Ok(())
}
