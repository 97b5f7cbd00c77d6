// epipolar / march, `march = "minmax"` (cpu.rs march_minmax): each pixel of the compacted list
// walks its own ray through the min-max tree of a rectified shadow map (minmax's `shade`,
// walk.wgsl; Chen et al. 2011) instead of marching N steps — the combination of Yusov 2013.
// Dispatched as the stepped march is, and writes the same marched texture (in-scattering, s).
// `params` is minmax's uniform block (prefiltered/geometry.wgsl's Params), not epipolar's.

@group(0) @binding(0) var<uniform> frame: Frame;
@group(0) @binding(1) var<uniform> params: Params;
@group(0) @binding(2) var depth_tex: texture_2d<f32>;
@group(0) @binding(3) var shadow_map: texture_2d_array<f32>;
@group(0) @binding(4) var spot_tex: texture_2d_array<f32>;
@group(0) @binding(5) var marched_tex: texture_storage_2d<rgba32float, write>;
@group(0) @binding(6) var<storage, read> tree: array<vec2<f32>>;
@group(0) @binding(7) var<storage, read> list: array<u32>;
@group(0) @binding(8) var<storage, read> counters: array<u32, 4>;

@compute @workgroup_size(64)
fn march(
    @builtin(workgroup_id) wg: vec3<u32>,
    @builtin(num_workgroups) nwg: vec3<u32>,
    @builtin(local_invocation_index) lid: u32,
) {
    let i = (wg.y * nwg.x + wg.x) * 64u + lid;
    if i >= counters[0] {
        return;
    }
    let pixel = list[i];
    let px = vec2<u32>(pixel % frame.width, pixel / frame.width);
    let dir = pixel_ray(frame, px);
    let s = view_distance(frame, textureLoad(depth_tex, vec2<i32>(px), 0).r, dir);
    let r = shade(frame, params, dir, s);
    textureStore(marched_tex, vec2<i32>(px), vec4<f32>(r.l, s));
}
