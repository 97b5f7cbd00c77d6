// epipolar / refine: discontinuity detection and sampling refinement (Engelhardt & Dachsbacher
// 2010, §4.2, §5.2), compaction and the indirect dispatch arguments. Entry `refine`, one thread
// per texel (t, k): inside the initial segment [a, b] that holds t (consecutive initial samples
// of line k), the paper's search walks left and right from t over the view distances of the
// coordinate texture until a depth discontinuity or the segment's end. A texel that is an
// initial sample or has a discontinuity next to it ends up with left = right = t: it is a
// ray-march sample, and it is appended to the sample list (an atomic counter instead of the
// paper's stencil mask). Every other texel interpolates between the two ray-march samples its
// search stopped at. The interpolation texture holds left | right << 16. A ray-march sample
// claims its pixel ⌊p⌋ (an atomicAdd on a per-pixel counter, cleared each frame): the first
// claim appends the pixel's index to the list, so each pixel is marched once however many
// texels (lines near the epipole, lines denser than pixels) fall on it. Entry `args`, one
// thread: the indirect dispatch of the march, ⌈count/64⌉ workgroups spread over y when they
// exceed the device's per-dimension limit. Mirrored by techniques/epipolar/cpu.rs
// (`refine_texel`, `refine`, `march_dispatch`).

@group(0) @binding(0) var<uniform> frame: Frame;
@group(0) @binding(1) var<uniform> params: Params;
@group(0) @binding(2) var coord_tex: texture_2d<f32>;
@group(0) @binding(3) var<storage, read> lines_buf: array<Line>;
@group(0) @binding(4) var interp_tex: texture_storage_2d<r32uint, write>;
@group(0) @binding(5) var<storage, read_write> list: array<u32>;
@group(0) @binding(6) var<storage, read_write> counters: array<atomic<u32>, 4>;
@group(0) @binding(7) var<storage, read_write> dispatch: array<u32, 3>;
@group(0) @binding(8) var<storage, read_write> claims: array<atomic<u32>>;

// Texel t of line k: its view distance, and whether it lies inside the re-marched disc
// around the epipole (near_epipole).
struct Texel {
    s: f32,
    near: bool,
}

fn texel_at(t: u32, k: u32) -> Texel {
    let c = textureLoad(coord_tex, vec2<i32>(i32(t), i32(k)), 0);
    return Texel(c.z, near_epipole(c.xy));
}

// A break between adjacent texels a and b: a depth discontinuity, or the edge of the
// re-marched disc around the epipole (cpu.rs refine_texel: no texel outside interpolates from
// the epipole).
fn breaks(a: Texel, b: Texel) -> bool {
    return discontinuity(a.s, b.s) || a.near != b.near;
}

// (left, right) of texel t of line k (§5.2 pseudo-code, restricted to t's initial segment).
fn refine_texel(t: u32, k: u32, n_init: u32) -> vec2<u32> {
    let seg = segment(t, n_init);
    var left = t;
    var cur = texel_at(t, k);
    while left > seg.x {
        let l = texel_at(left - 1u, k);
        if breaks(l, cur) {
            break;
        }
        cur = l;
        left -= 1u;
    }
    var right = t;
    cur = texel_at(t, k);
    while right < seg.y {
        let r = texel_at(right + 1u, k);
        if breaks(cur, r) {
            break;
        }
        cur = r;
        right += 1u;
    }
    if left == t || right == t {
        return vec2<u32>(t, t);
    }
    return vec2<u32>(left, right);
}

@compute @workgroup_size(8, 8)
fn refine(@builtin(global_invocation_id) gid: vec3<u32>) {
    let t = gid.x;
    let k = gid.y;
    if t >= params.samples || k >= params.slices {
        return;
    }
    let line = lines_buf[k];
    if line.valid == 0u {
        textureStore(interp_tex, vec2<i32>(i32(t), i32(k)), vec4<u32>(0u));
        return;
    }
    let lr = refine_texel(t, k, line.initial);
    textureStore(interp_tex, vec2<i32>(i32(t), i32(k)), vec4<u32>(lr.x | (lr.y << 16u), 0u, 0u, 0u));
    if lr.x == t && lr.y == t {
        atomicAdd(&counters[3], 1u);
        let px = texel_pixel(frame, textureLoad(coord_tex, vec2<i32>(i32(t), i32(k)), 0).xy);
        let pixel = px.y * frame.width + px.x;
        if atomicAdd(&claims[pixel], 1u) == 0u {
            let i = atomicAdd(&counters[0], 1u);
            list[i] = pixel;
        }
    }
}

@compute @workgroup_size(1)
fn args() {
    let n = atomicLoad(&counters[0]);
    let groups = (n + 63u) / 64u;
    let x = min(groups, params.max_workgroups);
    var y = 1u;
    if x > 0u {
        y = (groups + x - 1u) / x;
    }
    dispatch[0] = x;
    dispatch[1] = y;
    dispatch[2] = 1u;
}
