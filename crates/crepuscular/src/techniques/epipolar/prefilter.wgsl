// epipolar / prefilter: the spot texture prefiltered for a given number of epipolar lines
// (Engelhardt & Dachsbacher 2010, §6: "when using a lower number of epipolar lines, we have to
// prefilter the light texture accordingly"). One thread per output texel: the mean of the
// 2^L × 2^L block of source texels it covers (fewer at the right and bottom edges), so that
// light_incident's bilinear lookup (in texture-relative coordinates) reads a box-filtered
// level L of the texture. The source is the light's layer of the frame's spot-texture array
// (its top-left `texture_size` texels). Mirrored by techniques/epipolar/cpu.rs (`prefilter_spot_texture`).

@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(1) var src_tex: texture_2d_array<f32>;
@group(0) @binding(2) var dst_tex: texture_storage_2d<rgba32float, write>;

@compute @workgroup_size(8, 8)
fn prefilter(@builtin(global_invocation_id) gid: vec3<u32>) {
    let dim = textureDimensions(dst_tex);
    if gid.x >= dim.x || gid.y >= dim.y {
        return;
    }
    let n = 1u << params.prefilter_level;
    let light = lights.items[0];
    let src = light.texture_size;
    var sum = vec3<f32>(0.0);
    var count = 0u;
    for (var y = 0u; y < n; y++) {
        for (var x = 0u; x < n; x++) {
            let p = gid.xy * n + vec2<u32>(x, y);
            if p.x < src.x && p.y < src.y {
                sum += textureLoad(src_tex, vec2<i32>(p), i32(light.texture_layer), 0).rgb;
                count += 1u;
            }
        }
    }
    textureStore(dst_tex, vec2<i32>(gid.xy), vec4<f32>(sum / f32(max(count, 1u)), 1.0));
}
