// epipolar / refine: discontinuity detection and sampling refinement (Engelhardt & Dachsbacher
// 2010, §4.2, §5.2), compaction and the indirect dispatch arguments. Entry `refine`, one thread
// per initial segment (i, k) (consecutive initial samples a, b of line k): the paper's search
// gives texel t of the segment the texels `left` and `right` where a walk from t to the left and
// to the right stops, at a depth discontinuity or at the segment's end (§5.2 pseudo-code). So
// left and right are the ends of the run of texels around t with no break inside, clipped to
// [a, b]. The thread walks its segment once, finds those runs and writes every texel's
// (left, right) from them: the same classification as the paper's per-texel search, with S
// texel reads per line instead of S × (texels per segment) (at 1920×1080, S = 1469 and K = 16,
// 92 times fewer; docs/RESULTS.md "epipolar's refine in one walk per segment"). A texel that is
// an initial sample or has a discontinuity next to it ends up with left = right = t: it is a
// ray-march sample, and it is appended to the sample list (an atomic counter instead of the
// paper's stencil mask). Every other texel interpolates between the two ray-march samples
// around it. The interpolation texture holds left | right << 16. A ray-march sample claims its
// pixel ⌊p⌋ (an atomicAdd on a per-pixel counter, cleared each frame): the first claim appends
// the pixel's index to the list, so each pixel is marched once however many texels (lines near
// the epipole, lines denser than pixels) fall on it. Entry `args`, one thread: the indirect
// dispatch of the march, ⌈count/64⌉ workgroups spread over y when they exceed the device's
// per-dimension limit. Mirrored by techniques/epipolar/cpu.rs (`refine_line`, `refine`,
// `march_dispatch`).

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
// re-marched disc around the epipole (cpu.rs refine_line: no texel outside interpolates from
// the epipole).
fn breaks(a: Texel, b: Texel) -> bool {
    return discontinuity(a.s, b.s) || a.near != b.near;
}

// Writes texel u of line k, in the run [l, r] of texels with no break inside (clipped to its
// segment): a ray-march sample at either end of the run, else interpolated from both ends.
fn write_texel(u: u32, k: u32, l: u32, r: u32) {
    var lr = vec2<u32>(l, r);
    if u == l || u == r {
        lr = vec2<u32>(u, u);
    }
    textureStore(interp_tex, vec2<i32>(i32(u), i32(k)), vec4<u32>(lr.x | (lr.y << 16u), 0u, 0u, 0u));
    if lr.x == u && lr.y == u {
        atomicAdd(&counters[3], 1u);
        let px = texel_pixel(frame, textureLoad(coord_tex, vec2<i32>(i32(u), i32(k)), 0).xy);
        let pixel = px.y * frame.width + px.x;
        if atomicAdd(&claims[pixel], 1u) == 0u {
            let i = atomicAdd(&counters[0], 1u);
            list[i] = pixel;
        }
    }
}

// The texels of the run [l, r] that segment i of line k owns (a texel on the boundary of two
// segments is written once, by the segment `segment_index` gives it).
fn write_run(k: u32, l: u32, r: u32, i: u32, n_init: u32) {
    for (var u = l; u <= r; u += 1u) {
        if segment_index(u, n_init) == i {
            write_texel(u, k, l, r);
        }
    }
}

@compute @workgroup_size(8, 8)
fn refine(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let i = gid.x;
    let k = gid.y;
    if k >= params.slices {
        return;
    }
    let line = lines_buf[k];
    if line.valid == 0u {
        // A culled line's row is cleared, each thread a stride of it.
        for (var t = i; t < params.samples; t += groups.x * 8u) {
            textureStore(interp_tex, vec2<i32>(i32(t), i32(k)), vec4<u32>(0u));
        }
        return;
    }
    let n_init = line.initial;
    if i + 1u >= n_init {
        return;
    }
    let a = initial_index(i, n_init);
    let b = initial_index(i + 1u, n_init);
    // One walk over [a, b]: a run ends at a break (a depth discontinuity, or the edge of the
    // re-marched disc around the epipole) or at b.
    var start = a;
    var prev = texel_at(a, k);
    for (var t = a + 1u; t <= b; t += 1u) {
        let cur = texel_at(t, k);
        if breaks(prev, cur) {
            write_run(k, start, t - 1u, i, n_init);
            start = t;
        }
        prev = cur;
    }
    write_run(k, start, b, i, n_init);
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
