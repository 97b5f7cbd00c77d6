// epipolar / upsample: interpolation between the epipolar lines (Engelhardt & Dachsbacher 2010,
// §4.3, Fig. 5, §5.3, Fig. 8). One thread per pixel P:
// - a spot light's pixel whose own ray misses the cone before its surface gets 0 (exact);
// - a pixel within `epipole_radius` of the epipole, or whose points on both lines around it lie
//   within it (near the epipole the lines fan out), is re-marched
//   (the in-scattering may peak at the light's own pixel — 1/d² of a point or spot light seen
//   directly, a g → 1 phase function around the sun — which linear interpolation along the
//   lines, all of which start there, would smear over their first initial segment);
// - its position between lines, k + f (`line_position`: the ray from the epipole through P
//   leaves the sample rect at a border point, and the lines' border points are equidistant, so
//   the paper's 1D lookup texture is inverted in closed form);
// - the tap spacing l: the distance between P's projections on lines k and k + 1;
// - along each line a `taps`-tap 1D bilateral filter at P's projection ± j·l (in texels of the
//   line, at least one), each tap interpolating the radiance texture linearly (two sub-taps,
//   each with its own view distance); weight = spatial(|j|/σ_l) × linear × depth(|sᵢ − s|/s/σ_d);
//   a sub-tap on a texel inside the re-marched disc is skipped, and a line on which P's own
//   point lies inside the disc offers no taps (those left would extrapolate from farther out);
// - a line whose total weight is below MIN_WEIGHT (or that is culled) is replaced by the next
//   outer line, up to `outer_lines` further on each side;
// - between the two lines found: ((1 − f)·Σ₀wL + f·Σ₁wL) / ((1 − f)·W₀ + f·W₁), f measured
//   between the lines actually used; one line alone where the other side has none;
// - where neither side has a usable tap: the pixel is ray-marched at full resolution, as
//   brute-force (`fallback_remarch`, counted), or takes the tap nearest in depth.
// Mirrored by techniques/epipolar/cpu.rs (`projection`, `line_taps`, `upsample_pixel`,
// `upsample`).

@group(0) @binding(0) var<uniform> frame: Frame;
@group(0) @binding(1) var<uniform> params: Params;
@group(0) @binding(2) var depth_tex: texture_2d<f32>;
@group(0) @binding(3) var shadow_map: texture_2d_array<f32>;
@group(0) @binding(4) var spot_tex: texture_2d_array<f32>;
@group(0) @binding(5) var out_tex: texture_storage_2d<rgba32float, write>;
@group(0) @binding(6) var radiance_tex: texture_2d<f32>;
@group(0) @binding(7) var<storage, read> lines_buf: array<Line>;
@group(0) @binding(8) var<storage, read_write> counters: array<atomic<u32>, 4>;

// Re-marched pixels of this workgroup, added to counters[1] once per workgroup.
var<workgroup> workgroup_remarched: atomic<u32>;

// brute-force's march of pixel px (full resolution, the frame's own spot texture).
fn march_ray(px: vec2<u32>, dir: vec3<f32>, s: f32) -> vec3<f32> {
    let p = params;
    return march_pixel(
        frame, shadow_map, spot_tex, px, dir, s, p.steps, p.jitter, p.frame_index, p.spot_steps, p.spot_denominator,
    ).xyz;
}

// The projection of q onto the (unclipped) line of row `row`.
fn projection(row: u32, q: vec2<f32>) -> vec2<f32> {
    let line = lines_buf[row];
    return line.end + line.dir * dot(q - line.end, line.dir);
}

// One line's bilateral taps for a pixel at q with view distance s: Σw·L, Σw, and the tap
// nearest in depth.
struct Taps {
    sum: vec3<f32>,
    w: f32,
    nearest: vec3<f32>,
    nearest_diff: f32,
}

fn line_taps(row: u32, q: vec2<f32>, s: f32, l: f32) -> Taps {
    var r: Taps;
    r.sum = vec3<f32>(0.0);
    r.w = 0.0;
    r.nearest = vec3<f32>(0.0);
    r.nearest_diff = 3.0e38;
    let line = lines_buf[row];
    // q's own point on the line inside the re-marched disc: no estimate near q (cpu.rs
    // `line_taps`); the line is passed over as a culled one is.
    if line.valid == 0u || near_epipole(projection(row, q)) {
        return r;
    }
    let last = params.samples - 1u;
    let n1 = f32(last);
    let u = dot(q - line.end, line.dir);
    let tc = n1 * (1.0 - u / line.length);
    let spacing = max(l * n1 / line.length, 1.0);
    let m = i32(params.taps / 2u);
    let inv_s = 1.0 / max(s, 1e-6);
    for (var j = -m; j <= m; j++) {
        var tj = tc + f32(j) * spacing;
        if j == 0 {
            tj = clamp(tj, 0.0, n1);
        } else if tj < 0.0 || tj > n1 {
            continue;
        }
        let i0 = min(u32(floor(tj)), last);
        let i1 = min(i0 + 1u, last);
        let fr = tj - f32(i0);
        let ws = spatial_weight(f32(abs(j)) / params.spatial_scale);
        for (var h = 0u; h < 2u; h++) {
            let i = select(i0, i1, h == 1u);
            // A texel inside the re-marched disc holds no estimate (cpu.rs `line_taps`):
            // skipped.
            if near_epipole(texel_point(line, i)) {
                continue;
            }
            let wl = select(1.0 - fr, fr, h == 1u);
            let v = textureLoad(radiance_tex, vec2<i32>(i32(i), i32(row)), 0);
            let diff = abs(v.a - s);
            let w = ws * wl * depth_weight(diff * inv_s / params.depth_scale);
            r.sum += w * v.rgb;
            r.w += w;
            if diff < r.nearest_diff {
                r.nearest = v.rgb;
                r.nearest_diff = diff;
            }
        }
    }
    return r;
}

struct Upsampled {
    radiance: vec3<f32>,
    remarched: bool,
}

fn upsample_pixel(px: vec2<u32>) -> Upsampled {
    var out: Upsampled;
    out.radiance = vec3<f32>(0.0);
    out.remarched = false;
    let dir = pixel_ray(frame, px);
    let s = view_distance(frame, textureLoad(depth_tex, vec2<i32>(px), 0).r, dir);
    if lights.items[0].kind == LIGHT_SPOT {
        let iv = cone_interval(lights.items[0], frame.camera_pos.xyz, dir, s);
        if iv.y <= iv.x {
            return out;
        }
    }
    let q = vec2<f32>(px) + 0.5;
    let pos = line_position(frame, q);
    let k0 = i32(floor(pos));
    // q's points on lines k0 and k0 + 1: their distance is the tap spacing l; within the
    // epipole's disc, or both points inside it, the pixel is re-marched (cpu.rs
    // `upsample_pixel`: near the epipole the lines fan out).
    var l: f32;
    var remarch = false;
    if params.degenerate == 1u {
        l = (rect_max(frame).y - rect_min().y) / f32(params.slices);
    } else {
        let pa = projection(u32(line_row(k0)), q);
        let pb = projection(u32(line_row(k0 + 1)), q);
        l = length(pa - pb);
        remarch = near_epipole(q) || (near_epipole(pa) && near_epipole(pb));
    }
    if remarch {
        out.radiance = march_ray(px, dir, s);
        out.remarched = true;
        return out;
    }
    var nearest = vec3<f32>(0.0);
    var nearest_diff = 3.0e38;
    var a: Taps;
    var ka = k0;
    var found_a = false;
    for (var o = 0; o <= i32(params.outer_lines); o++) {
        let row = line_row(k0 - o);
        if row < 0 {
            break;
        }
        let t = line_taps(u32(row), q, s, l);
        if t.nearest_diff < nearest_diff {
            nearest = t.nearest;
            nearest_diff = t.nearest_diff;
        }
        if t.w >= MIN_WEIGHT {
            a = t;
            ka = k0 - o;
            found_a = true;
            break;
        }
    }
    var b: Taps;
    var kb = k0 + 1;
    var found_b = false;
    for (var o = 0; o <= i32(params.outer_lines); o++) {
        let row = line_row(k0 + 1 + o);
        if row < 0 {
            break;
        }
        let t = line_taps(u32(row), q, s, l);
        if t.nearest_diff < nearest_diff {
            nearest = t.nearest;
            nearest_diff = t.nearest_diff;
        }
        if t.w >= MIN_WEIGHT {
            b = t;
            kb = k0 + 1 + o;
            found_b = true;
            break;
        }
    }
    if found_a && found_b {
        let f = (pos - f32(ka)) / f32(kb - ka);
        out.radiance = ((1.0 - f) * a.sum + f * b.sum) / ((1.0 - f) * a.w + f * b.w);
    } else if found_a {
        out.radiance = a.sum / a.w;
    } else if found_b {
        out.radiance = b.sum / b.w;
    } else if params.fallback_remarch == 1u {
        out.radiance = march_ray(px, dir, s);
        out.remarched = true;
    } else {
        out.radiance = nearest;
    }
    return out;
}

@compute @workgroup_size(8, 8)
fn upsample(
    @builtin(global_invocation_id) gid: vec3<u32>,
    @builtin(local_invocation_index) lid: u32,
) {
    if gid.x < frame.width && gid.y < frame.height {
        let u = upsample_pixel(gid.xy);
        textureStore(out_tex, vec2<i32>(gid.xy), vec4<f32>(u.radiance, 1.0));
        if u.remarched {
            atomicAdd(&workgroup_remarched, 1u);
        }
    }
    // One global atomic per workgroup instead of one per re-marched pixel.
    workgroupBarrier();
    if lid == 0u {
        let n = atomicLoad(&workgroup_remarched);
        if n > 0u {
            atomicAdd(&counters[1], n);
        }
    }
}
