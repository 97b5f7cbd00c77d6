// interleaved / sum_columns: Tóth & Umenhoffer 2009, §4.1 — the vertical half of the separable
// addition. Adds the row sums over the M-pixel column window around each pixel, then
// renormalises by N / (terms added), which is exactly 1 for a complete window with every
// neighbour accepted. Mirrored by techniques/interleaved/cpu.rs (`sum_columns`).

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
@group(0) @binding(2) var rows_tex: texture_2d<f32>; // rgb: row sum, a: terms in it
@group(0) @binding(3) var march_tex: texture_2d<f32>; // a: view distance
@group(0) @binding(4) var out_tex: texture_storage_2d<rgba32float, write>;

// sum_rows.wgsl window_start.
fn window_start(c: u32, size: u32) -> u32 {
    let m = params.block;
    if size <= m {
        return 0u;
    }
    let lo = select(0u, c - m / 2u, c >= m / 2u);
    return min(lo, size - m);
}

// sum_rows.wgsl accept. The separable approximation: the row sum at (x, y′) was gathered
// around its own centre (x, y′); here (x, y′) is compared against (x, y).
fn accept(sn: f32, sc: f32) -> bool {
    return params.depth_aware == 0u || abs(sn - sc) <= params.depth_tolerance * sc;
}

@compute @workgroup_size(8, 8)
fn sum_columns(@builtin(global_invocation_id) gid: vec3<u32>) {
    let h = frame.height;
    if gid.x >= frame.width || gid.y >= h {
        return;
    }
    let px = gid.xy;
    let sc = textureLoad(march_tex, vec2<i32>(px), 0).a;
    let y0 = window_start(px.y, h);
    let y1 = min(y0 + params.block, h);
    var sum = vec3<f32>(0.0);
    var terms = 0.0;
    for (var y = y0; y < y1; y++) {
        let q = vec2<i32>(vec2<u32>(px.x, y));
        if accept(textureLoad(march_tex, q, 0).a, sc) {
            let r = textureLoad(rows_tex, q, 0);
            sum += r.rgb;
            terms += r.a;
        }
    }
    // Renormalise to N terms; a window with no term at all (only possible when N < M² and
    // depth awareness rejected offset 0's pixels) gets nothing rather than NaN.
    var l = vec3<f32>(0.0);
    if terms > 0.0 {
        l = sum * (f32(params.steps) / terms);
    }
    textureStore(out_tex, vec2<i32>(px), vec4<f32>(l, 1.0));
}
