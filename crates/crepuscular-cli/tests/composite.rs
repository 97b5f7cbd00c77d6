//! The library's GPU composite (L = T(s)·L_surface + L_scatt, then optionally the display
//! transform) against its CPU mirror, `tonemap::composite` over `surface_transmittance` and
//! `ToneMap::apply`, pixel by pixel; and the in-place composite against the one into another
//! target.

use crepuscular::frame::surface_transmittance;
use crepuscular::gpu::{GpuContext, test_gpu};
use crepuscular::tonemap::{ToneMap, composite};
use crepuscular::{Composite, CompositeInputs, CompositeTarget, TechniqueSettings};
use crepuscular_cli::render::{composite_target, frame_desc, render_gpu, scattering};
use crepuscular_scene::{GpuHost, builtin};

fn texture(gpu: &GpuContext, w: u32, h: u32, format: wgpu::TextureFormat, usage: wgpu::TextureUsages) -> wgpu::Texture {
    gpu.device.create_texture(&wgpu::TextureDescriptor {
        label: Some("test target"),
        size: wgpu::Extent3d { width: w, height: h, depth_or_array_layers: 1 },
        mip_level_count: 1,
        sample_count: 1,
        dimension: wgpu::TextureDimension::D2,
        format,
        usage,
        view_formats: &[],
    })
}

#[test]
fn gpu_composite_matches_its_cpu_mirror() {
    let Some(gpu) = test_gpu("gpu_composite_matches_its_cpu_mirror") else { return };
    let mut comp = Composite::new(&gpu.device).unwrap();
    for scene_name in ["colonnade", "cage", "stained-glass"] {
        let mut scene = builtin::builtin(scene_name).unwrap();
        scene.render.width = 96;
        scene.render.height = 54;
        scene.render.shadow.size = 256;
        let desc = frame_desc(&scene).unwrap();
        let (w, h) = (desc.width, desc.height);
        let host = GpuHost::for_scene(&gpu, &scene).unwrap();
        let tex = host.render(&gpu, &desc).unwrap();
        let views = tex.views();
        let frame = views.frame(&desc);
        let settings = TechniqueSettings::named("brute-force").unwrap();
        let mut sc = scattering(&gpu, &settings).unwrap().unwrap();
        let out = gpu.create_output_texture(w, h);
        let out_view = out.create_view(&Default::default());
        render_gpu(&mut sc, Some(&host), &frame, &out_view).unwrap();

        // The CPU mirror on the very images the GPU used.
        let surface = gpu.read_image(&tex.surface).unwrap();
        let inscatter = gpu.read_image(&out).unwrap();
        let depth = gpu.read_texture_f32(&tex.depth, 0).unwrap();
        let want = composite(&surface, &inscatter, &surface_transmittance(&desc, &depth));

        let surface_view = tex.surface.create_view(&Default::default());
        let inputs = CompositeInputs { desc: &desc, depth: frame.depth, inscatter: &out_view, surface: &surface_view };
        // Linear HDR into another target.
        let hdr = composite_target(&gpu, w, h);
        let mut enc = gpu.device.create_command_encoder(&Default::default());
        comp.encode(&mut enc, &inputs, CompositeTarget::Into(&hdr.create_view(&Default::default())), None).unwrap();
        gpu.queue.submit([enc.finish()]);
        let got = gpu.read_image(&hdr).unwrap();
        let mut worst = 0.0f32;
        for (g, c) in got.pixels.iter().zip(&want.pixels) {
            for i in 0..3 {
                let err = (g[i] - c[i]).abs() / c[i].abs().max(1e-3);
                worst = worst.max(err);
            }
            assert_eq!(g[3], 1.0);
        }
        eprintln!("{scene_name}: worst relative difference GPU vs CPU composite {worst:.2e}");
        assert!(worst < 2e-5, "{scene_name}: GPU composite differs from the CPU mirror by {worst}");
        let lit = want.pixels.iter().filter(|p| p[0] + p[1] + p[2] > 0.01).count();
        assert!(lit > (w * h / 4) as usize, "{scene_name}: a dark composite ({lit} lit pixels)");

        // Two frames' composites in one encoder each use their own frame (a denser medium
        // first, then this frame).
        let mut denser = desc.clone();
        denser.medium.absorption += glam::Vec3::splat(0.05);
        let other = CompositeInputs { desc: &denser, ..inputs };
        let (x, y) = (composite_target(&gpu, w, h), composite_target(&gpu, w, h));
        let mut enc = gpu.device.create_command_encoder(&Default::default());
        comp.encode(&mut enc, &other, CompositeTarget::Into(&x.create_view(&Default::default())), None).unwrap();
        comp.encode(&mut enc, &inputs, CompositeTarget::Into(&y.create_view(&Default::default())), None).unwrap();
        gpu.queue.submit([enc.finish()]);
        assert_eq!(gpu.read_image(&y).unwrap().pixels, got.pixels, "{scene_name}: the second composite in one encoder");
        assert_ne!(gpu.read_image(&x).unwrap().pixels, got.pixels, "{scene_name}: the denser medium changed nothing");

        // In place: the engine's HDR colour itself (a copy of the surface here).
        let colour = texture(
            &gpu,
            w,
            h,
            wgpu::TextureFormat::Rgba32Float,
            wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::COPY_SRC | wgpu::TextureUsages::COPY_DST,
        );
        let mut enc = gpu.device.create_command_encoder(&Default::default());
        enc.copy_texture_to_texture(
            tex.surface.as_image_copy(),
            colour.as_image_copy(),
            wgpu::Extent3d { width: w, height: h, depth_or_array_layers: 1 },
        );
        comp.encode(&mut enc, &inputs, CompositeTarget::InPlace(&colour), None).unwrap();
        gpu.queue.submit([enc.finish()]);
        assert_eq!(gpu.read_image(&colour).unwrap().pixels, got.pixels, "{scene_name}: in place ≠ into a target");

        // The display transform into 8 bits, against ToneMap::apply of the CPU composite.
        for exposure in [1.0f32, 3.0] {
            let ldr = texture(
                &gpu,
                w,
                h,
                wgpu::TextureFormat::Rgba8Unorm,
                wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::COPY_SRC,
            );
            let tone = ToneMap::new(exposure);
            let mut enc = gpu.device.create_command_encoder(&Default::default());
            comp.encode(&mut enc, &inputs, CompositeTarget::Into(&ldr.create_view(&Default::default())), Some(tone))
                .unwrap();
            gpu.queue.submit([enc.finish()]);
            let bytes = gpu.read_texture_bytes(&ldr, 0).unwrap();
            let mut off = 0;
            for (px, c) in bytes.chunks_exact(4).zip(&want.pixels) {
                let cpu = tone.apply([c[0], c[1], c[2]]);
                for i in 0..3 {
                    let d = (px[i] as i32 - cpu[i] as i32).abs();
                    assert!(d <= 1, "{scene_name}: 8-bit composite {:?} vs CPU {cpu:?}", &px[..3]);
                    off += (d > 0) as usize;
                }
            }
            eprintln!("{scene_name} exposure {exposure}: {off} of {} 8-bit channels off by one", w * h * 3);
        }
    }
}

#[test]
fn composite_refuses_targets_that_do_not_fit() {
    let Some(gpu) = test_gpu("composite_refuses_targets_that_do_not_fit") else { return };
    let mut scene = builtin::builtin("colonnade").unwrap();
    scene.render.width = 64;
    scene.render.height = 36;
    scene.render.shadow.size = 128;
    let desc = frame_desc(&scene).unwrap();
    let host = GpuHost::for_scene(&gpu, &scene).unwrap();
    let tex = host.render(&gpu, &desc).unwrap();
    let views = tex.views();
    let frame = views.frame(&desc);
    let out = gpu.create_output_texture(64, 36);
    let out_view = out.create_view(&Default::default());
    let surface_view = tex.surface.create_view(&Default::default());
    let inputs = CompositeInputs { desc: &desc, depth: frame.depth, inscatter: &out_view, surface: &surface_view };
    let mut comp = Composite::new(&gpu.device).unwrap();
    let mut enc = gpu.device.create_command_encoder(&Default::default());
    let wrong = composite_target(&gpu, 32, 36);
    let e = comp.encode(&mut enc, &inputs, CompositeTarget::Into(&wrong.create_view(&Default::default())), None);
    assert!(e.as_ref().is_err_and(|e| e.to_string().contains("composite target")), "{e:?}");
    // In place without COPY_SRC.
    let no_copy = texture(&gpu, 64, 36, wgpu::TextureFormat::Rgba16Float, wgpu::TextureUsages::RENDER_ATTACHMENT);
    let e = comp.encode(&mut enc, &inputs, CompositeTarget::InPlace(&no_copy), None);
    assert!(e.as_ref().is_err_and(|e| e.to_string().contains("COPY_SRC")), "{e:?}");
    // A surface of another size, an in-scattering texture that cannot be sampled.
    let target = composite_target(&gpu, 64, 36);
    let target_view = target.create_view(&Default::default());
    let small = texture(&gpu, 32, 36, wgpu::TextureFormat::Rgba16Float, wgpu::TextureUsages::TEXTURE_BINDING);
    let small_view = small.create_view(&Default::default());
    let e = comp.encode(
        &mut enc,
        &CompositeInputs { surface: &small_view, ..inputs },
        CompositeTarget::Into(&target_view),
        None,
    );
    assert!(e.as_ref().is_err_and(|e| e.to_string().contains("surface") && e.to_string().contains("64×36")), "{e:?}");
    let unsampled = texture(&gpu, 64, 36, wgpu::TextureFormat::Rgba32Float, wgpu::TextureUsages::STORAGE_BINDING);
    let unsampled_view = unsampled.create_view(&Default::default());
    let e = comp.encode(
        &mut enc,
        &CompositeInputs { inscatter: &unsampled_view, ..inputs },
        CompositeTarget::Into(&target_view),
        None,
    );
    assert!(
        e.as_ref().is_err_and(|e| e.to_string().contains("inscatter") && e.to_string().contains("TEXTURE_BINDING")),
        "{e:?}"
    );
    // The same views frame after frame: one bind group; new views: one more.
    let mut comp = Composite::new(&gpu.device).unwrap();
    for _ in 0..3 {
        let mut enc = gpu.device.create_command_encoder(&Default::default());
        comp.encode(&mut enc, &inputs, CompositeTarget::Into(&target_view), None).unwrap();
        gpu.queue.submit([enc.finish()]);
    }
    assert_eq!(comp.bind_group_builds(), 1);
    let other_surface = tex.surface.create_view(&Default::default());
    let mut enc = gpu.device.create_command_encoder(&Default::default());
    comp.encode(
        &mut enc,
        &CompositeInputs { surface: &other_surface, ..inputs },
        CompositeTarget::Into(&target_view),
        None,
    )
    .unwrap();
    gpu.queue.submit([enc.finish()]);
    assert_eq!(comp.bind_group_builds(), 2);
}
