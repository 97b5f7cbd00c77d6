// The sum over lights of a technique that renders one light per run (docs/MODEL.md §6):
// out = a + b per pixel (rgb; alpha taken from a), and `clear` for a frame no light reaches.
// Mirrored on the CPU by the image sum in TechniqueSettings::render_cpu.

@group(0) @binding(0) var a_tex: texture_2d<f32>;
@group(0) @binding(1) var b_tex: texture_2d<f32>;
@group(0) @binding(2) var out_tex: texture_storage_2d<rgba32float, write>;

@compute @workgroup_size(8, 8)
fn add(@builtin(global_invocation_id) gid: vec3<u32>) {
    let size = textureDimensions(out_tex);
    if gid.x >= size.x || gid.y >= size.y {
        return;
    }
    let px = vec2<i32>(gid.xy);
    let a = textureLoad(a_tex, px, 0);
    let b = textureLoad(b_tex, px, 0);
    textureStore(out_tex, px, vec4<f32>(a.rgb + b.rgb, a.a));
}
