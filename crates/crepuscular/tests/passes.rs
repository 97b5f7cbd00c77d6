//! A pass's bind group is built from resources named as its WGSL names them: a missing, unknown
//! or doubled name is an error naming the pass and the variable, never a wgpu validation panic.

use crepuscular::gpu::test_gpu;
use crepuscular::techniques::pass::{Pass, Resource, ShaderVariant};

const SHADER: &str = "
@group(0) @binding(0) var<uniform> scale: vec4<f32>;
@group(0) @binding(1) var src_tex: texture_2d<f32>;
@group(0) @binding(2) var out_tex: texture_storage_2d<rgba32float, write>;
@compute @workgroup_size(4, 2)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    textureStore(out_tex, gid.xy, textureLoad(src_tex, gid.xy, 0) * scale);
}
";

#[test]
fn a_pass_binds_by_name_and_names_what_is_wrong() {
    let Some(gpu) = test_gpu("a_pass_binds_by_name_and_names_what_is_wrong") else { return };
    let device = &gpu.device;
    let pass = gpu.try_scoped("test pass", || Pass::new(device, "test/scale", SHADER, "main")).unwrap();
    assert_eq!(pass.workgroup_size(), [4, 2, 1]);
    assert_eq!(pass.groups_2d(9, 5), [3, 3, 1]);
    let names: Vec<&str> = pass.bindings().iter().map(|(n, _)| n.as_str()).collect();
    assert_eq!(names, ["scale", "src_tex", "out_tex"]);

    let scale = crepuscular::techniques::pass::uniform_buffer(device, "scale", 16);
    gpu.queue.write_buffer(&scale, 0, bytemuck::cast_slice(&[2.0f32, 3.0, 4.0, 5.0]));
    let mut src = crepuscular::Image::new(8, 2);
    for (i, p) in src.pixels.iter_mut().enumerate() {
        *p = [i as f32, 1.0, 0.5, 0.25];
    }
    let src = gpu.upload_image("src", &src);
    let out = gpu.create_output_texture(8, 2);
    let (src_view, out_view) = (src.create_view(&Default::default()), out.create_view(&Default::default()));
    let view = wgpu::BindingResource::TextureView;
    let all: Vec<Resource> =
        vec![("scale", scale.as_entire_binding()), ("src_tex", view(&src_view)), ("out_tex", view(&out_view))];

    let err = |resources: &[Resource]| pass.bind(device, resources).err().expect("refused").to_string();
    let missing = err(&all[..2]);
    assert!(missing.contains("test/scale") && missing.contains("`out_tex`"), "{missing}");
    let mut unknown = all.clone();
    unknown.push(("shadow_map", view(&src_view)));
    let unknown = err(&unknown);
    assert!(unknown.contains("`shadow_map`"), "{unknown}");
    let mut twice = all.clone();
    twice.push(("src_tex", view(&src_view)));
    let twice = err(&twice);
    assert!(twice.contains("`src_tex`") && twice.contains("twice"), "{twice}");

    // The order of the names is free; the result is the shader's.
    let mut shuffled = all.clone();
    shuffled.reverse();
    let bind = gpu.try_scoped("binding the test pass", || pass.bind(device, &shuffled)).unwrap();
    // The tools' wall-clock recorder submits and waits for the pass.
    let mut rec = crepuscular::gpu::Recorder::wall_clock(&gpu);
    pass.dispatch(&mut rec, ShaderVariant::ALL, "scale", &bind, pass.groups_2d(8, 2)).unwrap();
    drop(rec);
    let got = gpu.read_image(&out).unwrap();
    for (i, p) in got.pixels.iter().enumerate() {
        assert_eq!(*p, [2.0 * i as f32, 3.0, 2.0, 1.25], "pixel {i}");
    }
}

/// Writes the variant's two constants (common.wgsl's `LOCAL_LIGHTS`, `SPOT_TEXTURES`) as 0 or 1.
const VARIANT_SHADER: &str = "
@group(0) @binding(0) var out_tex: texture_storage_2d<rgba32float, write>;
@compute @workgroup_size(1)
fn main() {
    textureStore(out_tex, vec2<u32>(0u), vec4<f32>(select(0.0, 1.0, LOCAL_LIGHTS), select(0.0, 1.0, SPOT_TEXTURES), 0.0, 1.0));
}
";

#[test]
fn each_shader_variant_runs_its_own_pipeline_built_on_first_use() {
    let Some(gpu) = test_gpu("each_shader_variant_runs_its_own_pipeline_built_on_first_use") else { return };
    let device = &gpu.device;
    let pass = gpu.try_scoped("variant pass", || Pass::new(device, "test/variant", VARIANT_SHADER, "main")).unwrap();
    assert!(pass.is_specialized());
    assert_eq!(pass.pipelines_built(), 0, "pipelines are built on first use");
    let out = gpu.create_output_texture(1, 1);
    let out_view = out.create_view(&Default::default());
    let bind = pass.bind(device, &[("out_tex", wgpu::BindingResource::TextureView(&out_view))]).unwrap();
    let variants = [
        (ShaderVariant::ALL, [1.0, 1.0]),
        (ShaderVariant { local_lights: false, spot_textures: false }, [0.0, 0.0]),
        (ShaderVariant { local_lights: true, spot_textures: false }, [1.0, 0.0]),
        (ShaderVariant { local_lights: false, spot_textures: false }, [0.0, 0.0]),
    ];
    for (i, (variant, want)) in variants.into_iter().enumerate() {
        let mut rec = crepuscular::gpu::Recorder::wall_clock(&gpu);
        pass.dispatch(&mut rec, variant, "variant", &bind, [1, 1, 1]).unwrap();
        drop(rec);
        let got = gpu.read_image(&out).unwrap().pixels[0];
        assert_eq!([got[0], got[1]], want, "{variant:?}");
        assert_eq!(pass.pipelines_built(), [1, 2, 3, 3][i], "after {variant:?}");
    }
    // A pass that reads neither constant has one pipeline for every variant.
    let plain = Pass::new(device, "test/scale", SHADER, "main").unwrap();
    assert!(!plain.is_specialized());
    let _ = plain.pipeline(ShaderVariant { local_lights: false, spot_textures: false });
    assert_eq!(plain.pipelines_built(), 1);
}
