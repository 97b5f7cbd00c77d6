// brute-force / march: Tóth & Umenhoffer 2009, eq. 1 — one thread per pixel marches N steps
// from the eye to the visible surface. Mirrored by techniques/brute_force/cpu.rs (`march`).

struct Params {
    steps: u32,
    jitter: u32,
    frame_index: u32,
    spot_steps: u32,
    spot_denominator: f32,
    _pad0: u32,
    _pad1: u32,
    _pad2: u32,
}

@group(0) @binding(0) var<uniform> frame: Frame;
@group(0) @binding(1) var<uniform> params: Params;
@group(0) @binding(2) var depth_tex: texture_2d<f32>;
@group(0) @binding(3) var shadow_map: texture_2d_array<f32>;
@group(0) @binding(4) var spot_tex: texture_2d_array<f32>;
@group(0) @binding(5) var out_tex: texture_storage_2d<rgba32float, write>;

// Eq. 1 over the interval the spot-step policy picks ([0, s] for any light under "fixed"),
// N steps, all evaluated by this pixel (march_pixel in common.wgsl): the in-scattering in xyz,
// its scattering distance in w.
fn march_ray(px: vec2<u32>, dir: vec3<f32>, s: f32) -> vec4<f32> {
    let p = params;
    return march_pixel(
        frame, shadow_map, spot_tex, px, dir, s, p.steps, p.jitter, p.frame_index, p.spot_steps, p.spot_denominator,
    );
}

@compute @workgroup_size(8, 8)
fn march(@builtin(global_invocation_id) gid: vec3<u32>) {
    if gid.x >= frame.width || gid.y >= frame.height {
        return;
    }
    let px = gid.xy;
    let dir = pixel_ray(frame, px);
    let d = textureLoad(depth_tex, vec2<i32>(px), 0).r;
    let s = view_distance(frame, d, dir);
    // alpha: minus the ray's scattering distance (0 where it has none), for the temporal stage
    // (temporal.rs TemporalSettings::scattering_distance).
    let m = march_ray(px, dir, s);
    textureStore(out_tex, vec2<i32>(px), vec4<f32>(m.xyz, -m.w));
}
