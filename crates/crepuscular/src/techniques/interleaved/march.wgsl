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

// σs·lut(cos θ)·L_in·V of one light at p (inscatter_density with the phase from the table).
fn density_lut(l: Light, dir: vec3<f32>, p: vec3<f32>) -> vec3<f32> {
    let li = lit_incident(frame, l, shadow_map, spot_tex, p);
    if all(li.radiance == vec3<f32>(0.0)) {
        return vec3<f32>(0.0);
    }
    return frame.sigma_s.xyz * phase_lut(-dot(li.dir, dir)) * li.radiance;
}

// march_steps (common.wgsl) with the phase function read from the table: eq. 1 over the steps
// i = first, first + stride, … < n of `st`, σs·lut(cos θ)·L_in·V per step, of the lights of
// `mask` (march_density in common.wgsl).
fn march_steps_lut(dir: vec3<f32>, st: Steps, first: u32, stride: u32, j: f32, mask: u32) -> vec3<f32> {
    if st.iv.y <= st.iv.x {
        return vec3<f32>(0.0);
    }
    let sigma = extinction(frame);
    let uni = uniform_step(st, sigma, j);
    var sum = vec3<f32>(0.0);
    for (var i = first; i < st.n; i += stride) {
        let step = march_step(st, i, sigma, j, uni);
        let p = frame.camera_pos.xyz + dir * (step.t0 + step.off);
        var d = vec3<f32>(0.0);
        var m = mask;
        while m != 0u {
            let k = firstTrailingBit(m);
            m &= m - 1u;
            d += density_lut(lights.items[k], dir, p);
        }
        sum += d * step.scale * exp(-sigma * step.t0) * step.seg;
    }
    return sum;
}

// march_lights (common.wgsl) with the phase table.
fn march_lights_lut(dir: vec3<f32>, s: f32, n: u32, first: u32, stride: u32, j: f32) -> vec3<f32> {
    let o = frame.camera_pos.xyz;
    let policy = params.spot_steps;
    let sm = shared_march(frame, o, dir, s, policy, params.spot_denominator);
    var sum = march_steps_lut(dir, uniform_steps(sm.iv, n), first, stride, j, sm.mask);
    for (var k = 0u; k < min(lights.count, MAX_LIGHTS); k++) {
        let l = lights.items[k];
        if own_interval(l, policy) {
            let iv = march_interval(frame, l, o, dir, s, policy, params.spot_denominator);
            sum += march_steps_lut(dir, own_steps(l, iv, n, o, dir, policy), first, stride, j, 1u << k);
        }
    }
    return sum;
}

// §4.1: "in a particular pixel we evaluate just N/M² terms" — the terms k, k + M², … of eq. 1
// over the intervals the spot-step policy picks (march_lights), on this pixel's own ray.
fn march_ray(px: vec2<u32>, dir: vec3<f32>, s: f32) -> vec3<f32> {
    var j = 0.5;
    if params.jitter == 1u {
        j = pixel_jitter(px / params.block, params.frame_index);
    }
    let stride = params.block * params.block;
    let k = block_offset(px);
    if params.phase_lut == 1u {
        return march_lights_lut(dir, s, params.steps, k, stride, j);
    }
    return march_lights(
        frame, shadow_map, spot_tex, dir, s, params.steps, k, stride, j, params.spot_steps, params.spot_denominator,
    ).xyz;
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
