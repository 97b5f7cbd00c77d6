// epipolar / march: ray marching of the compacted ray-march samples (Engelhardt & Dachsbacher
// 2010, §4.3, §5.3), dispatched indirectly over the list the refine pass wrote — this replaces
// the paper's stencil + early-z trick. The list holds pixels (each claimed by the ray-march
// texels that fall on it, and marched once): each thread takes one, and marches that pixel's
// own ray exactly as brute-force does (`march_pixel`: N steps over the spot-step policy's
// interval; the spot texture bound here is the prefiltered one when the prefilter runs).
// Writes (in-scattering, s) into the marched texture at the pixel. Mirrored by
// techniques/epipolar/cpu.rs (`march`).

@group(0) @binding(0) var<uniform> frame: Frame;
@group(0) @binding(1) var<uniform> params: Params;
@group(0) @binding(2) var depth_tex: texture_2d<f32>;
@group(0) @binding(3) var shadow_map: texture_2d_array<f32>;
@group(0) @binding(4) var spot_tex: texture_2d_array<f32>;
@group(0) @binding(5) var marched_tex: texture_storage_2d<rgba32float, write>;
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
    let p = params;
    let l = march_pixel(
        frame, shadow_map, spot_tex, px, dir, s, p.steps, p.jitter, p.frame_index, p.spot_steps, p.spot_denominator,
    ).xyz;
    textureStore(marched_tex, vec2<i32>(px), vec4<f32>(l, s));
}
