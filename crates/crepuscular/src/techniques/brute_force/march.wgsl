// brute-force / march: Tóth & Umenhoffer 2009, eq. 1 — one thread per pixel marches N steps
// from the eye to the visible surface. Mirrored by techniques/brute_force/cpu.rs (`march`).

struct Params {
    steps: u32,
    jitter: u32,
    frame_index: u32,
    _pad: u32,
}

@group(0) @binding(0) var<uniform> frame: Frame;
@group(0) @binding(1) var<uniform> params: Params;
@group(0) @binding(2) var depth_tex: texture_2d<f32>;
@group(0) @binding(3) var shadow_map: texture_2d_array<f32>;
@group(0) @binding(4) var spot_tex: texture_2d<f32>;
@group(0) @binding(5) var out_tex: texture_storage_2d<rgba32float, write>;

// Eq. 1: L_scatt ≈ Σ_n σs·p·L_in(x(l_n))·V(x(l_n))·T(t_n)·Δ, with the transmittance integrated
// exactly over each step (segment_transmittance).
fn march_ray(px: vec2<u32>, dir: vec3<f32>, s: f32) -> vec3<f32> {
    let n = params.steps;
    let delta = s / f32(n);
    var j = 0.5;
    if params.jitter == 1u {
        j = pixel_jitter(px, params.frame_index);
    }
    let st = extinction(frame);
    let seg = segment_transmittance(st, delta);
    var sum = vec3<f32>(0.0);
    for (var i = 0u; i < n; i++) {
        let t0 = f32(i) * delta;
        let t = (f32(i) + j) * delta;
        let p = frame.camera_pos.xyz + dir * t;
        sum += inscatter_density(frame, shadow_map, spot_tex, dir, p) * exp(-st * t0) * seg;
    }
    return sum;
}

@compute @workgroup_size(8, 8)
fn march(@builtin(global_invocation_id) gid: vec3<u32>) {
    if gid.x >= frame.ints.x || gid.y >= frame.ints.y {
        return;
    }
    let px = gid.xy;
    let dir = pixel_ray(frame, px);
    let d = textureLoad(depth_tex, vec2<i32>(px), 0).r;
    let s = view_distance(frame, d, dir);
    textureStore(out_tex, vec2<i32>(px), vec4<f32>(march_ray(px, dir, s), 1.0));
}
