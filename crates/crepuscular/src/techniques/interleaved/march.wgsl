// interleaved / march: Tóth & Umenhoffer 2009, §4.1 — the screen is divided into M×M blocks
// and pixel (x, y) evaluates only the eq.-1 terms i ≡ k (mod M²), k = (y mod M)·M + (x mod M),
// of the N terms on its own view ray. Writes (the pixel's partial sum, its view distance s).
// Mirrored by techniques/interleaved/cpu.rs (`march`), function for function.

struct Params {
    block: u32,
    steps: u32,
    spot_steps: u32,
    spot_denominator: f32,
    jitter: u32,
    frame_index: u32,
    depth_aware: u32,
    depth_tolerance: f32,
    phase_lut: u32,
    phase_lut_size: u32,
    _pad0: u32,
    _pad1: u32,
}

@group(0) @binding(0) var<uniform> frame: Frame;
@group(0) @binding(1) var<uniform> params: Params;
@group(0) @binding(2) var depth_tex: texture_2d<f32>;
@group(0) @binding(3) var shadow_map: texture_2d_array<f32>;
@group(0) @binding(4) var spot_tex: texture_2d_array<f32>;
@group(0) @binding(5) var out_tex: texture_storage_2d<rgba32float, write>;
@group(0) @binding(6) var<storage, read> lut: array<vec4<f32>>;

// §4.1: "the N terms are distributed in them in a periodic way" — the pixel's offset k.
fn block_offset(px: vec2<u32>) -> u32 {
    let m = params.block;
    return (px.y % m) * m + (px.x % m);
}

// §4: "complicated phase functions like the Henyey-Greenstein phase function can be stored in
// a lookup table" — entries at u_i = i/(n − 1), u = √((1 − σ·cos θ)/2) (sin(θ/2) for σ = 1;
// σ = −1 when the asymmetry g < 0 puts the peak backwards), linear interpolation (PhaseLut in
// mod.rs builds it).
fn phase_lut(c: f32) -> vec3<f32> {
    let n = params.phase_lut_size;
    let sign = select(1.0, -1.0, frame.sigma_s.w < 0.0);
    let u = sqrt(clamp(0.5 - 0.5 * (sign * c), 0.0, 1.0));
    let x = u * f32(n - 1u);
    let i0 = min(u32(x), n - 2u);
    let f = x - f32(i0);
    return lut[i0].xyz * (1.0 - f) + lut[i0 + 1u].xyz * f;
}

// march_steps (common.wgsl) with the phase function read from the table: eq. 1 over the steps
// i = first, first + stride, … < n of the interval iv, σs·lut(cos θ)·L_in·V per step.
fn march_steps_lut(dir: vec3<f32>, iv: vec2<f32>, n: u32, first: u32, stride: u32, j: f32) -> vec3<f32> {
    if iv.y <= iv.x {
        return vec3<f32>(0.0);
    }
    let delta = (iv.y - iv.x) / f32(n);
    let st = extinction(frame);
    let seg = segment_transmittance(st, delta);
    let off = step_offset((st.x + st.y + st.z) / 3.0, delta, j);
    var sum = vec3<f32>(0.0);
    for (var i = first; i < n; i += stride) {
        let t0 = iv.x + f32(i) * delta;
        let t = t0 + off;
        let p = frame.camera_pos.xyz + dir * t;
        let tr = exp(-st * t0) * seg;
        for (var k = 0u; k < min(lights.count, MAX_LIGHTS); k++) {
            let li = lit_incident(frame, lights.items[k], shadow_map, spot_tex, p);
            if any(li.radiance != vec3<f32>(0.0)) {
                let cos_theta = -dot(li.dir, dir);
                sum += frame.sigma_s.xyz * phase_lut(cos_theta) * li.radiance * tr;
            }
        }
    }
    return sum;
}

// §4.1: "in a particular pixel we evaluate just N/M² terms" — the terms k, k + M², … of eq. 1
// over the interval the spot-step policy picks, on this pixel's own ray.
fn march_ray(px: vec2<u32>, dir: vec3<f32>, s: f32) -> vec3<f32> {
    let iv = lights_interval(frame, frame.camera_pos.xyz, dir, s, params.spot_steps, params.spot_denominator);
    var j = 0.5;
    if params.jitter == 1u {
        j = pixel_jitter(px / params.block, params.frame_index);
    }
    let stride = params.block * params.block;
    let k = block_offset(px);
    if params.phase_lut == 1u {
        return march_steps_lut(dir, iv, params.steps, k, stride, j);
    }
    return march_steps(frame, shadow_map, spot_tex, dir, iv, params.steps, k, stride, j);
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
    textureStore(out_tex, vec2<i32>(px), vec4<f32>(march_ray(px, dir, s), s));
}
