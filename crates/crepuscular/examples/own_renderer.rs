//! Using crepuscular from your own wgpu renderer. The example is the engine: it creates its own
//! device, draws its own tiny scene (a ground slab and a floating grate) with its own WGSL and
//! pipelines, and every frame records into **one encoder, submitted once**:
//! 1. a depth-only shadow pass from the sun into its shadow map (standard [0, 1] depth),
//! 2. a camera pass with a **reversed-Z infinite** projection **jittered** per frame (a TAA
//!    Halton(2, 3) offset): lit, shadowed surface colour (`Rgba16Float`) and the depth buffer,
//! 3. crepuscular's technique (`Scattering::encode`), handed the engine's device, depth buffer,
//!    shadow map and matrices: the in-scattered light into an `Rgba32Float` texture,
//! 4. with `--temporal`, crepuscular's temporal stage (`Temporal::encode`): the technique's
//!    samples move every frame (`TechniqueSettings::jittered`, through `Scattering::update`)
//!    and the stage blends the frame with the previous ones, reprojected through the previous
//!    and current (jittered) matrices and the depth buffer,
//! 5. crepuscular's composite (`Composite::encode`): L = T(s)·L_surface + L_scatt, tone-mapped
//!    into the engine's `Rgba8Unorm` target,
//!
//! for several frames and for every GPU technique, then checks each final picture (shafts in
//! the fog, shadows on the ground, not black) and saves it; it exits non-zero when a check fails.
//!
//! Run: `cargo run --release -p crepuscular --example own_renderer [-- OUT_DIR [TECHNIQUE] [--temporal]]`
//! (default: the current directory, every GPU technique, no temporal stage), writing
//! `own_renderer-<technique>.ppm` (`-temporal.ppm` with the stage).

use crepuscular::frame::{FrameDesc, FrameLight, GpuFrame};
use crepuscular::tonemap::ToneMap;
use crepuscular::{
    Composite, CompositeInputs, CompositeTarget, DepthConvention, FrameCamera, GpuContext, Light, Medium, Scattering,
    ShadowProjection, TechniqueSettings, Temporal, TemporalSettings,
};
use glam::{Mat4, Vec3};
use wgpu::util::DeviceExt;

const WIDTH: u32 = 320;
const HEIGHT: u32 = 180;
const SHADOW_SIZE: u32 = 1024;
const FRAMES: u32 = 4;

/// The engine's depth-only shader: one world → clip matrix per pass.
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

/// 36 vertices (12 triangles) of an axis-aligned box.
fn cuboid(a: Vec3, b: Vec3) -> Vec<[f32; 3]> {
    let c = |i: usize| {
        [if i & 1 == 0 { a.x } else { b.x }, if i & 2 == 0 { a.y } else { b.y }, if i & 4 == 0 { a.z } else { b.z }]
    };
    let faces = [[0, 1, 3, 2], [4, 6, 7, 5], [0, 4, 5, 1], [2, 3, 7, 6], [0, 2, 6, 4], [1, 5, 7, 3]];
    faces.iter().flat_map(|f| [f[0], f[1], f[2], f[0], f[2], f[3]].map(c)).collect()
}

/// The Halton sequence in `base` (a TAA jitter pattern), in [0, 1).
fn halton(mut i: u32, base: u32) -> f32 {
    let (mut f, mut r) = (1.0, 0.0);
    while i > 0 {
        f /= base as f32;
        r += f * (i % base) as f32;
        i /= base;
    }
    r
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let temporal = std::env::args().any(|a| a == "--temporal");
    let args: Vec<String> = std::env::args().skip(1).filter(|a| a != "--temporal").collect();
    let out_dir = std::path::PathBuf::from(args.first().cloned().unwrap_or_else(|| ".".into()));
    let only = args.get(1).cloned();

    // 1. The engine's own instance, adapter and device; crepuscular is handed the device.
    let mut desc = wgpu::InstanceDescriptor::new_without_display_handle();
    desc.backends = wgpu::Backends::from_env().unwrap_or(wgpu::Backends::PRIMARY);
    let instance = wgpu::Instance::new(desc);
    let adapter = pollster::block_on(instance.request_adapter(&Default::default()))
        .map_err(|e| format!("own_renderer needs a GPU adapter (Vulkan, Metal, DX12 or lavapipe): {e}"))?;
    let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
        label: Some("engine"),
        // Optional: lets crepuscular time its passes (timestamps read back frames later).
        required_features: adapter.features() & wgpu::Features::TIMESTAMP_QUERY,
        required_limits: adapter.limits(),
        ..Default::default()
    }))?;
    println!("adapter: {} ({:?})", adapter.get_info().name, adapter.get_info().backend);

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

    // The engine's camera (reversed-Z, infinite far plane; the fog ends 60 m out) and sun.
    let eye = Vec3::new(0.0, 1.7, 14.0);
    let view = Mat4::look_at_rh(eye, Vec3::new(0.0, 3.5, 0.0), Vec3::Y);
    let aspect = WIDTH as f32 / HEIGHT as f32;
    let projection = Mat4::perspective_infinite_reverse_rh(60f32.to_radians(), aspect, 0.1);
    let fog_far = 60.0;
    let sun_dir = Vec3::new(0.15, -0.55, 1.0).normalize(); // the direction the light travels
    let (sun_color, sun_intensity) = (Vec3::new(1.0, 0.9, 0.75), 2.0);
    let medium = Medium { scattering: Vec3::splat(0.04), absorption: Vec3::splat(0.005), ..Default::default() };
    // The engine's own directional shadow projection: an orthographic box of half-width R
    // around the scene, seen from the sun. Depth is [0, 1] from `near` to `far`, linear.
    let (center, r) = (Vec3::new(0.0, 2.0, 0.0), 25.0);
    let (light_near, light_far) = (0.1, 4.0 * r);
    let light_view = Mat4::look_at_rh(center - sun_dir * (2.0 * r), center, Vec3::Y);
    let light_vp = Mat4::orthographic_rh(-r, r, -r, r, light_near, light_far) * light_view;

    // The engine's render targets. crepuscular reads depth and shadow map (TEXTURE_BINDING).
    let texture = |label, w, h, format, usage| {
        device.create_texture(&wgpu::TextureDescriptor {
            label: Some(label),
            size: wgpu::Extent3d { width: w, height: h, depth_or_array_layers: 1 },
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format,
            usage,
            view_formats: &[],
        })
    };
    let depth_usage = wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::TEXTURE_BINDING;
    let shadow_map = texture("shadow map", SHADOW_SIZE, SHADOW_SIZE, wgpu::TextureFormat::Depth32Float, depth_usage);
    let depth = texture("camera depth", WIDTH, HEIGHT, wgpu::TextureFormat::Depth32Float, depth_usage);
    let surface = texture("surface colour", WIDTH, HEIGHT, wgpu::TextureFormat::Rgba16Float, depth_usage);
    let final_image = texture(
        "final image",
        WIDTH,
        HEIGHT,
        wgpu::TextureFormat::Rgba8Unorm,
        wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::COPY_SRC,
    );
    // crepuscular's output: an Rgba32Float storage texture of the frame's size.
    let inscatter = texture(
        "in-scattering",
        WIDTH,
        HEIGHT,
        wgpu::TextureFormat::Rgba32Float,
        wgpu::TextureUsages::STORAGE_BINDING | wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_SRC,
    );

    // The engine's two scene pipelines over the same vertices: depth only for the shadow pass
    // (standard depth, LESS) and lit colour + depth for the camera pass (reversed-Z, GREATER).
    let scene_pipeline = |label: &str, wgsl: &str, color: Option<wgpu::TextureFormat>, compare| {
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
                depth_compare: Some(compare),
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
    let shadow_pipeline = scene_pipeline("depth only", DEPTH_WGSL, None, wgpu::CompareFunction::Less);
    let lit_pipeline =
        scene_pipeline("lit", LIT_WGSL, Some(wgpu::TextureFormat::Rgba16Float), DepthConvention::Reversed.compare());
    let uniform = |label, size| {
        device.create_buffer(&wgpu::BufferDescriptor {
            label: Some(label),
            size,
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        })
    };
    let light_vp_buffer = uniform("light view_proj", 64);
    queue.write_buffer(&light_vp_buffer, 0, bytemuck::cast_slice(&light_vp.to_cols_array()));
    let lit_buffer = uniform("lit uniforms", 64 * 2 + 16 * 3);
    let shadow_bind = device.create_bind_group(&wgpu::BindGroupDescriptor {
        label: Some("light view_proj"),
        layout: &shadow_pipeline.get_bind_group_layout(0),
        entries: &[wgpu::BindGroupEntry { binding: 0, resource: light_vp_buffer.as_entire_binding() }],
    });
    let shadow_view = shadow_map.create_view(&Default::default());
    let compare = device.create_sampler(&wgpu::SamplerDescriptor {
        label: Some("shadow compare"),
        compare: Some(wgpu::CompareFunction::LessEqual),
        mag_filter: wgpu::FilterMode::Linear,
        min_filter: wgpu::FilterMode::Linear,
        ..Default::default()
    });
    let lit_bind = device.create_bind_group(&wgpu::BindGroupDescriptor {
        label: Some("lit"),
        layout: &lit_pipeline.get_bind_group_layout(0),
        entries: &[
            wgpu::BindGroupEntry { binding: 0, resource: lit_buffer.as_entire_binding() },
            wgpu::BindGroupEntry { binding: 1, resource: wgpu::BindingResource::TextureView(&shadow_view) },
            wgpu::BindGroupEntry { binding: 2, resource: wgpu::BindingResource::Sampler(&compare) },
        ],
    });
    // The views crepuscular reads: depth aspect only, the shadow map as a 2D array.
    let depth_view = depth
        .create_view(&wgpu::TextureViewDescriptor { aspect: wgpu::TextureAspect::DepthOnly, ..Default::default() });
    let shadow_array = shadow_map.create_view(&wgpu::TextureViewDescriptor {
        dimension: Some(wgpu::TextureViewDimension::D2Array),
        aspect: wgpu::TextureAspect::DepthOnly,
        ..Default::default()
    });
    let (color_view, surface_view) =
        (surface.create_view(&Default::default()), surface.create_view(&Default::default()));
    // With the temporal stage: its output, which the composite then reads.
    let resolved = texture(
        "resolved in-scattering",
        WIDTH,
        HEIGHT,
        wgpu::TextureFormat::Rgba32Float,
        wgpu::TextureUsages::STORAGE_BINDING | wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_SRC,
    );
    let (inscatter_view, resolved_view, final_view) = (
        inscatter.create_view(&Default::default()),
        resolved.create_view(&Default::default()),
        final_image.create_view(&Default::default()),
    );
    let light = Light::Directional { direction: sun_dir, color: sun_color, intensity: sun_intensity };
    let shadow = ShadowProjection {
        view_proj: [light_vp; 6],
        layers: 1,
        near: light_near,
        far: light_far,
        orthographic: true,
        size: SHADOW_SIZE,
        texel_world: 2.0 * r / SHADOW_SIZE as f32,
        depth: DepthConvention::Standard,
    };

    // One frame of the engine: its passes, crepuscular's technique and composite, one submit.
    let mut composite = Composite::new(&device)?;
    let mut frame = |scattering: &mut Scattering,
                     stage: Option<&mut Temporal>,
                     index: u32|
     -> Result<FrameCamera, crepuscular::Error> {
        let jitter = (halton(index + 1, 2) - 0.5, halton(index + 1, 3) - 0.5);
        let jittered =
            Mat4::from_translation(Vec3::new(2.0 * jitter.0 / WIDTH as f32, 2.0 * jitter.1 / HEIGHT as f32, 0.0))
                * projection;
        let camera = FrameCamera::new(view, jittered, DepthConvention::Reversed, Some(fog_far))?;
        let mut lit = Vec::new();
        lit.extend_from_slice(&camera.view_proj().to_cols_array());
        lit.extend_from_slice(&light_vp.to_cols_array());
        lit.extend_from_slice(&sun_dir.extend(0.0).to_array());
        lit.extend_from_slice(&(sun_color * sun_intensity).extend(0.0).to_array());
        lit.extend_from_slice(&eye.extend(1.0).to_array());
        queue.write_buffer(&lit_buffer, 0, bytemuck::cast_slice(&lit));
        // The engine's one light (add more with their shadow maps' layers: FrameLight::shadow_layer).
        let sun = FrameLight {
            shadow_bias: 0.02, // world units along the light's depth axis
            ..FrameLight::new(light.clone(), shadow.clone())
        };
        let desc = FrameDesc {
            camera: camera.clone(),
            lights: vec![sun],
            medium: medium.clone(),
            width: WIDTH,
            height: HEIGHT,
        };
        let mut encoder = device.create_command_encoder(&Default::default());
        {
            let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
                label: Some("shadow pass"),
                color_attachments: &[],
                depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
                    view: &shadow_view,
                    depth_ops: Some(wgpu::Operations { load: wgpu::LoadOp::Clear(1.0), store: wgpu::StoreOp::Store }),
                    stencil_ops: None,
                }),
                timestamp_writes: None,
                occlusion_query_set: None,
                multiview_mask: None,
            });
            pass.set_pipeline(&shadow_pipeline);
            pass.set_bind_group(0, &shadow_bind, &[]);
            pass.set_vertex_buffer(0, vertex_buffer.slice(..));
            pass.draw(0..verts.len() as u32, 0..1);
        }
        {
            // Camera pass: lit surfaces and the reversed-Z depth buffer crepuscular reads.
            let clear = DepthConvention::Reversed.far_value();
            let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
                label: Some("camera pass"),
                color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                    view: &color_view,
                    depth_slice: None,
                    resolve_target: None,
                    ops: wgpu::Operations {
                        load: wgpu::LoadOp::Clear(wgpu::Color::BLACK),
                        store: wgpu::StoreOp::Store,
                    },
                })],
                depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
                    view: &depth.create_view(&Default::default()),
                    depth_ops: Some(wgpu::Operations { load: wgpu::LoadOp::Clear(clear), store: wgpu::StoreOp::Store }),
                    stencil_ops: None,
                }),
                timestamp_writes: None,
                occlusion_query_set: None,
                multiview_mask: None,
            });
            pass.set_pipeline(&lit_pipeline);
            pass.set_bind_group(0, &lit_bind, &[]);
            pass.set_vertex_buffer(0, vertex_buffer.slice(..));
            pass.draw(0..verts.len() as u32, 0..1);
        }
        // 3. crepuscular records its passes into the engine's encoder.
        let gpu_frame = GpuFrame {
            desc: &desc,
            depth: &depth_view,
            shadow_maps: &shadow_array,
            spot_textures: None,
            rectified_shadow_maps: &[],
        };
        if stage.is_some() {
            // The samples move every frame: jitter on, frame_index = the frame (no rebuild).
            scattering.update(&scattering.settings().jittered(index))?;
        }
        scattering.encode(&mut encoder, &gpu_frame, &inscatter_view)?;
        // 4. The temporal stage, if on: this frame blended with the history (no motion
        // vectors: the scene is static, so reprojecting through the camera is exact).
        let composited = match stage {
            Some(stage) => {
                stage.encode(&mut encoder, &desc, &depth_view, &inscatter_view, &resolved_view, None)?;
                &resolved_view
            }
            None => &inscatter_view,
        };
        // 5. … and the composite, with the display transform, into the engine's target.
        let inputs = CompositeInputs { desc: &desc, depth: &depth_view, inscatter: composited, surface: &surface_view };
        composite.encode(&mut encoder, &inputs, CompositeTarget::Into(&final_view), Some(ToneMap::new(1.0)))?;
        queue.submit([encoder.finish()]); // the frame's one submit
        scattering.end_frame();
        let _ = device.poll(wgpu::PollType::Poll); // never waits: delivers finished readbacks
        Ok(camera)
    };

    // 6. Every GPU technique, several frames each; read back, check, report and save.
    let readback = GpuContext::from_device(&device, &queue); // the library's readback helpers
    let mut failures = Vec::new();
    for info in crepuscular::techniques::TECHNIQUES.iter().filter(|t| t.gpu) {
        if only.as_deref().is_some_and(|o| o != info.name) {
            continue;
        }
        let mut scattering = Scattering::new(&device, &queue, TechniqueSettings::named(info.name)?)?;
        let mut stage = if temporal { Some(Temporal::new(&device, TemporalSettings::default())?) } else { None };
        let mut camera = None;
        for i in 0..FRAMES {
            camera = Some(frame(&mut scattering, stage.as_mut(), i)?);
        }
        readback.wait()?;
        let camera = camera.expect("frames were rendered");
        let stats = scattering.stats().cloned();
        let pixel_of = |p: Vec3| {
            let ndc = camera.view_proj().project_point3(p);
            let x = ((ndc.x * 0.5 + 0.5) * WIDTH as f32).clamp(0.0, WIDTH as f32 - 1.0) as u32;
            let y = ((0.5 - ndc.y * 0.5) * HEIGHT as f32).clamp(0.0, HEIGHT as f32 - 1.0) as u32;
            (y * WIDTH + x) as usize
        };
        // A point on the ground in bar 2's shadow, and one 1 m beside it (under a gap, in the sun).
        let ground_shadow = Vec3::new(-1.0, 5.0, -1.5) + sun_dir * (5.0 / -sun_dir.y);
        let (in_shadow, in_sun) = (pixel_of(ground_shadow), pixel_of(ground_shadow + Vec3::X));
        let mut fail = |what: String| failures.push(format!("{}: {what}", info.name));

        let img = readback.read_image(if temporal { &resolved } else { &inscatter })?;
        if img.pixels.iter().any(|p| p.iter().any(|v| !v.is_finite())) {
            fail("NaN or infinity in the in-scattering".into());
        }
        let lum: Vec<f32> = img.pixels.iter().map(|p| 0.2126 * p[0] + 0.7152 * p[1] + 0.0722 * p[2]).collect();
        let mean = lum.iter().sum::<f32>() / lum.len() as f32;
        // The view ray to the shadowed ground runs through the bar's shadow volume, the ray
        // beside it does not, so it gathers more light: a shaft.
        let (a, b) = (lum[in_shadow], lum[in_sun]);
        if !(b > 1.1 * a) {
            fail(format!("no light shaft: in-scattering {a:.4} through the bar's shadow, {b:.4} beside it"));
        }
        let rgba = readback.read_texture_bytes(&final_image, 0)?;
        let rgb: Vec<u8> = rgba.chunks_exact(4).flat_map(|p| [p[0], p[1], p[2]]).collect();
        let luma =
            |i: usize| 0.2126 * rgb[3 * i] as f32 + 0.7152 * rgb[3 * i + 1] as f32 + 0.0722 * rgb[3 * i + 2] as f32;
        let final_mean = (0..lum.len()).map(luma).sum::<f32>() / lum.len() as f32;
        let (ga, gb) = (luma(in_shadow), luma(in_sun));
        if final_mean < 10.0 {
            fail(format!("the final image is (nearly) black (mean {final_mean:.1})"));
        }
        if !(gb > ga + 10.0) {
            fail(format!("the ground in the bar's shadow ({ga:.1}) is not darker than in the sun ({gb:.1})"));
        }
        let timing = stats.as_ref().map_or("no stats yet".to_string(), |s| {
            let passes: Vec<_> = s.passes.iter().map(|p| format!("{} {:.2} ms", p.name, p.ms)).collect();
            format!("{} ({})", passes.join(", "), s.timing)
        });
        println!(
            "{:<12} {FRAMES} frames{}, one submit each: in-scattering mean {mean:.4}, shaft {a:.4} vs {b:.4}; \
             final mean {final_mean:.1}, ground {ga:.0} in shadow vs {gb:.0} in sun; {timing}",
            info.name,
            if temporal { " with the temporal stage" } else { "" }
        );
        let suffix = if temporal { "-temporal" } else { "" };
        let path = out_dir.join(format!("own_renderer-{}{suffix}.ppm", info.name));
        let mut ppm = format!("P6\n{WIDTH} {HEIGHT}\n255\n").into_bytes();
        ppm.extend_from_slice(&rgb);
        std::fs::write(&path, ppm)?;
    }
    if !failures.is_empty() {
        return Err(failures.join("; ").into());
    }
    println!("checks passed for every technique: light shafts in the fog, shadows on the ground");
    Ok(())
}
