// epipolar / geometry: what every epipolar pass shares (Engelhardt & Dachsbacher 2010, §4.1,
// §5.1, §5.3): the uniform block, the line record, the sample rect R = [½, W − ½] × [½, H − ½]
// of pixel centres, its perimeter (clockwise from the top-left corner, y down), the border
// points b_k, the homogeneous epipole, clipping, and the pixel → line lookup. Prepended to
// every epipolar pass (after common.wgsl); each pass declares `params` and its own bindings.
// Mirrored function for function by techniques/epipolar/cpu.rs.

struct Params {
    steps: u32,
    jitter: u32,
    frame_index: u32,
    spot_steps: u32,
    spot_denominator: f32,
    slices: u32,
    samples: u32,
    initial_samples: u32,
    length_proportional: u32,
    depth_threshold: f32,
    threshold_growth: f32,
    taps: u32,
    weighting: u32,
    spatial_scale: f32,
    depth_scale: f32,
    outer_lines: u32,
    fallback_remarch: u32,
    degenerate: u32,
    max_workgroups: u32,
    prefilter_level: u32,
    epipole_radius: f32,
    _pad0: u32,
    _pad1: u32,
    _pad2: u32,
    epipole: vec4<f32>,
}

// One epipolar line: texel t at end + dir·length·(S − 1 − t)/(S − 1).
struct Line {
    end: vec2<f32>,
    dir: vec2<f32>,
    length: f32,
    valid: u32,
    initial: u32,
    _pad: u32,
}

// Visible segments shorter than this (pixels) are culled.
const MIN_LINE_LENGTH: f32 = 5e-1;
// Below this total bilateral weight a line has no usable tap.
const MIN_WEIGHT: f32 = 1e-3;

fn rect_min() -> vec2<f32> {
    return vec2<f32>(0.5);
}

fn rect_max(f: Frame) -> vec2<f32> {
    return vec2<f32>(f32(f.width) - 0.5, f32(f.height) - 0.5);
}

fn perimeter(f: Frame) -> f32 {
    let d = rect_max(f) - rect_min();
    return 2.0 * (d.x + d.y);
}

// The point at perimeter parameter u of R: top edge left to right, right edge top to bottom,
// bottom edge right to left, left edge bottom to top.
fn border_point(f: Frame, u: f32) -> vec2<f32> {
    let lo = rect_min();
    let hi = rect_max(f);
    let wr = hi.x - lo.x;
    let hr = hi.y - lo.y;
    if u < wr {
        return vec2<f32>(lo.x + u, lo.y);
    }
    if u < wr + hr {
        return vec2<f32>(hi.x, lo.y + (u - wr));
    }
    if u < 2.0 * wr + hr {
        return vec2<f32>(hi.x - (u - wr - hr), hi.y);
    }
    return vec2<f32>(lo.x, hi.y - (u - 2.0 * wr - hr));
}

// The perimeter parameter of a point b on the border of R (the inverse of border_point).
fn border_param(f: Frame, b: vec2<f32>) -> f32 {
    let lo = rect_min();
    let hi = rect_max(f);
    let wr = hi.x - lo.x;
    let hr = hi.y - lo.y;
    let dt = abs(b.y - lo.y);
    let dr = abs(b.x - hi.x);
    let db = abs(b.y - hi.y);
    let dl = abs(b.x - lo.x);
    let m = min(min(dt, dr), min(db, dl));
    if dt == m {
        return clamp(b.x - lo.x, 0.0, wr);
    }
    if dr == m {
        return wr + clamp(b.y - lo.y, 0.0, hr);
    }
    if db == m {
        return wr + hr + clamp(hi.x - b.x, 0.0, wr);
    }
    return 2.0 * wr + hr + clamp(hi.y - b.y, 0.0, hr);
}

// b_k: line k's point on the border, at perimeter parameter (k + ½)·P/slices; in the degenerate
// case (camera at the light) evenly on the right edge.
fn line_border_point(f: Frame, k: u32) -> vec2<f32> {
    let n = f32(params.slices);
    if params.degenerate == 1u {
        let hr = rect_max(f).y - rect_min().y;
        return vec2<f32>(rect_max(f).x, rect_min().y + (f32(k) + 0.5) * hr / n);
    }
    return border_point(f, (f32(k) + 0.5) * perimeter(f) / n);
}

// From the point q: the unit direction towards the epipole (xy) and the distance to it (z;
// 1e30 for an epipole at infinity). (0, 0, 0) at the epipole itself.
fn towards_epipole(q: vec2<f32>) -> vec3<f32> {
    let e = params.epipole;
    let v = e.xy - q * e.z;
    let n = length(v);
    if n <= 0.0 {
        return vec3<f32>(0.0);
    }
    let sg = select(-1.0, 1.0, e.z >= 0.0);
    let dir = v / n * sg;
    var dist = 1e30;
    if abs(e.z) * 1e30 > n {
        dist = n / abs(e.z);
    }
    return vec3<f32>(dir, dist);
}

// The parameter range [u0, u1] of the ray q + u·d, u in [0, umax], inside R (slab clipping);
// empty when u1 < u0.
fn clip_ray(f: Frame, q: vec2<f32>, d: vec2<f32>, umax: f32) -> vec2<f32> {
    let lo = rect_min();
    let hi = rect_max(f);
    var u0 = 0.0;
    var u1 = umax;
    for (var a = 0; a < 2; a++) {
        if abs(d[a]) < 1e-12 {
            if q[a] < lo[a] || q[a] > hi[a] {
                return vec2<f32>(1.0, 0.0);
            }
        } else {
            let t1 = (lo[a] - q[a]) / d[a];
            let t2 = (hi[a] - q[a]) / d[a];
            u0 = max(u0, min(t1, t2));
            u1 = min(u1, max(t1, t2));
        }
    }
    return vec2<f32>(u0, u1);
}

// The view ray through a continuous pixel-space point q (pixel_ray for q = px + ½).
fn point_ray(f: Frame, q: vec2<f32>) -> vec3<f32> {
    let size = vec2<f32>(f32(f.width), f32(f.height));
    let ndc = vec2<f32>(q.x / size.x * 2.0 - 1.0, 1.0 - q.y / size.y * 2.0);
    return ndc_ray(f, ndc);
}

// The point of texel t of a line.
fn texel_point(line: Line, t: u32) -> vec2<f32> {
    let n1 = params.samples - 1u;
    let a = line.length * (f32(n1 - t) / f32(n1));
    return line.end + line.dir * a;
}

// The pixel a sample at q takes: ⌊q⌋, clamped to the image.
fn texel_pixel(f: Frame, q: vec2<f32>) -> vec2<u32> {
    let hi = vec2<f32>(f32(f.width) - 1.0, f32(f.height) - 1.0);
    return vec2<u32>(clamp(floor(q), vec2<f32>(0.0), hi));
}

// K of a line of visible length `len` (pixels): K, or K·len/diagonal (at least 2).
fn initial_count(f: Frame, len: f32) -> u32 {
    let k = params.initial_samples;
    if params.length_proportional == 0u {
        return k;
    }
    let diag = max(length(rect_max(f) - rect_min()), 1.0);
    return clamp(u32(ceil(f32(k) * len / diag)), 2u, k);
}

// Texel index of initial sample i of a line with n_init initial samples: round(i·(S−1)/(n−1)).
fn initial_index(i: u32, n_init: u32) -> u32 {
    let s1 = params.samples - 1u;
    let k1 = n_init - 1u;
    return (2u * i * s1 + k1) / (2u * k1);
}

// The index i of the initial segment [initial_index(i), initial_index(i + 1)] that holds texel
// t (a texel on the boundary of two segments belongs to one of them).
fn segment_index(t: u32, n_init: u32) -> u32 {
    let s1 = params.samples - 1u;
    let k1 = n_init - 1u;
    return min(t * k1 / s1, k1 - 1u);
}

// A depth discontinuity between adjacent texels of view distances sa, sb (§4.2, with the
// threshold growing with distance, §6).
fn discontinuity(sa: f32, sb: f32) -> bool {
    return abs(sa - sb) > params.depth_threshold + params.threshold_growth * min(sa, sb);
}

// The continuous line position of the pixel-space point q: k + f where k, k + 1 are the lines
// around it and f in [0, 1) its fraction between them (Fig. 8: the ray from the epipole through
// q meets the border of R beyond q at perimeter parameter u, and line k sits at
// u = (k + ½)·P/slices; the paper's 1D lookup texture, inverted in closed form).
fn line_position(f: Frame, q: vec2<f32>) -> f32 {
    let n = f32(params.slices);
    let lo = rect_min();
    let hi = rect_max(f);
    if params.degenerate == 1u {
        let hr = hi.y - lo.y;
        if hr <= 0.0 {
            return 0.0;
        }
        return (q.y - lo.y) * n / hr - 0.5;
    }
    let te = towards_epipole(q);
    // Within half a pixel of the epipole every line passes by: take line 0.
    if te.z < 0.5 || all(te.xy == vec2<f32>(0.0)) {
        return 0.0;
    }
    let d = -te.xy;
    var v = 1e30;
    for (var a = 0; a < 2; a++) {
        if d[a] > 0.0 {
            v = min(v, (hi[a] - q[a]) / d[a]);
        } else if d[a] < 0.0 {
            v = min(v, (lo[a] - q[a]) / d[a]);
        }
    }
    let b = clamp(q + d * v, lo, hi);
    let per = perimeter(f);
    if per <= 0.0 {
        return 0.0;
    }
    return border_param(f, b) * n / per - 0.5;
}

// Line index k (unwrapped) → its row, or -1 when there is no such line (the degenerate case
// does not wrap around).
fn line_row(k: i32) -> i32 {
    let n = i32(params.slices);
    if params.degenerate == 1u {
        return select(-1, k, k >= 0 && k < n);
    }
    return ((k % n) + n) % n;
}

// A pixel within `epipole_radius` pixels of the epipole, where the in-scattering may peak at the
// light's own pixel (1/d² of a point or spot light seen directly, a strongly forward phase
// function around the sun) and is re-marched, not interpolated.
fn near_epipole(q: vec2<f32>) -> bool {
    return params.degenerate == 0u && towards_epipole(q).z < params.epipole_radius;
}

// The bilateral kernels (§4.3), x ≥ 0 in units of σ.
fn spatial_weight(x: f32) -> f32 {
    if params.weighting == 1u {
        return 1.0 / (1.0 + x * x);
    }
    return exp(-x * x);
}

fn depth_weight(x: f32) -> f32 {
    if params.weighting == 1u {
        return 1.0 / (1.0 + x * x);
    }
    if params.weighting == 2u {
        return select(0.0, 1.0, x <= 1.0);
    }
    return exp(-x * x);
}
