// interleaved / sum_rows: Tóth & Umenhoffer 2009, §4.1 — "as the addition filter is separable
// we can use an addition once in a horizontal and once in a vertical direction". Adds the
// march pass's partial sums over the M-pixel row window around each pixel and counts the eq.-1
// terms added (rgb = sum, a = terms). Mirrored by techniques/interleaved/cpu.rs (`sum_rows`).

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
@group(0) @binding(2) var march_tex: texture_2d<f32>; // rgb: partial sum, a: view distance
@group(0) @binding(3) var out_tex: texture_storage_2d<rgba32float, write>;

// The number of eq.-1 terms the march pass evaluated at pixel px: i = k, k + M², … < N.
fn offset_terms(px: vec2<u32>) -> u32 {
    let m = params.block;
    let k = (px.y % m) * m + (px.x % m);
    if k >= params.steps {
        return 0u;
    }
    let m2 = m * m;
    return (params.steps - k + m2 - 1u) / m2;
}

// First pixel of the sliding M-pixel window around c: clamp(c − ⌊M/2⌋, 0, size − M), so the
// window stays complete at the borders (0 when the image is smaller than M).
fn window_start(c: u32, size: u32) -> u32 {
    let m = params.block;
    if size <= m {
        return 0u;
    }
    let lo = select(0u, c - m / 2u, c >= m / 2u);
    return min(lo, size - m);
}

// Depth awareness: a neighbour at view distance sn joins the centre at sc when within the
// relative tolerance (always, when depth_aware is off).
fn accept(sn: f32, sc: f32) -> bool {
    return params.depth_aware == 0u || abs(sn - sc) <= params.depth_tolerance * sc;
}

@compute @workgroup_size(8, 8)
fn sum_rows(@builtin(global_invocation_id) gid: vec3<u32>) {
    let w = frame.width;
    if gid.x >= w || gid.y >= frame.height {
        return;
    }
    let px = gid.xy;
    let sc = textureLoad(march_tex, vec2<i32>(px), 0).a;
    let x0 = window_start(px.x, w);
    let x1 = min(x0 + params.block, w);
    var sum = vec3<f32>(0.0);
    var terms = 0u;
    for (var x = x0; x < x1; x++) {
        let q = vec2<u32>(x, px.y);
        let v = textureLoad(march_tex, vec2<i32>(q), 0);
        if accept(v.a, sc) {
            sum += v.rgb;
            terms += offset_terms(q);
        }
    }
    textureStore(out_tex, vec2<i32>(px), vec4<f32>(sum, f32(terms)));
}
