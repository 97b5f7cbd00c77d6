// prefiltered: the rectification (rectify.rs) and the Fourier basis (cpu.rs), shared by the
// passes; each function has a Rust twin of the same name. Klehm, Seidel & Eisemann 2014.

// `mode` of Params: the rectification (rectify.rs `Mode::code`).
const RECT_PROJECTIVE: u32 = 0u;
const RECT_EPIPOLAR: u32 = 1u;
// Bits of `flags` (settings.rs `PrefilteredParams::flags`).
const FLAG_TRANSMITTANCE_WEIGHTS: u32 = 1u;
const FLAG_FULL_CIRCLE: u32 = 2u;
const FLAG_HOST_RASTER: u32 = 4u;

// The uniform block of every prefiltered and minmax pass (settings.rs `PrefilteredParams`).
struct Params {
    mode: u32,             // RECT_PROJECTIVE or RECT_EPIPOLAR
    local: u32,            // 1 for a spot or point light
    width: u32,            // rectified map width (columns)
    height: u32,           // rectified map height (rows)
    regions: u32,          // column regions
    bases: u32,            // bases M
    bases_per_thread: u32,
    flags: u32,            // FLAG_* bits
    epipole_radius: u32,   // 0: off, or not on screen
    epipole_steps: u32,
    light_steps: u32,      // the local light's quadrature segments
    spot_steps: u32,       // the step policy's code (march.rs StepPolicy::code)
    camera: vec4<f32>, // camera position, mean extinction
    light: vec4<f32>,  // light position, camera–light distance
    axes: array<vec4<f32>, 3>,
    ranges: vec4<f32>, // projective (q0, q1, r0, r1); epipolar (phi0, phi1, theta0, theta1)
    epipole: vec4<f32>, // epipole pixel xy, volume bias, App. B denominator
    region_x: array<vec4<f32>, 3>,
    bands: u32,
    channels: u32,         // 1, or 3 for an RGB spot texture
    tree_levels: u32,      // minmax only
    max_nodes: u32,        // minmax only
}

const Z_MARGIN: f32 = 0.0625;

fn region_x(p: Params, i: u32) -> f32 {
    return p.region_x[i / 4u][i % 4u];
}

// rectify.rs Rectification::row_phi (and row_q).
fn row_param(p: Params, row: f32) -> f32 {
    return p.ranges.x + row / f32(p.height) * (p.ranges.y - p.ranges.x);
}

fn slice_dir(p: Params, phi: f32) -> vec3<f32> {
    return p.axes[0].xyz * cos(phi) + p.axes[1].xyz * sin(phi);
}

// rectify.rs Rectification::region_of_column.
fn region_of_column(p: Params, c: u32) -> u32 {
    return min(((min(c, p.width - 1u) + 1u) * p.regions - 1u) / p.width, p.regions - 1u);
}

fn region_columns(p: Params, region: u32) -> vec2<u32> {
    return vec2<u32>(region * p.width / p.regions, (region + 1u) * p.width / p.regions);
}

struct Column {
    region: u32,
    col: f32,
}

// rectify.rs column_warp / column_unwarp: the epipolar map's columns, warped with knee k.
fn column_warp(c: f32, c_max: f32, k: f32) -> f32 {
    if k <= 0.0 {
        return clamp(c / c_max, 0.0, 1.0);
    }
    return clamp(max(c, 0.0) / (max(c, 0.0) + k) * (c_max + k) / c_max, 0.0, 1.0);
}

fn column_unwarp(u: f32, c_max: f32, k: f32) -> f32 {
    if k <= 0.0 {
        return u * c_max;
    }
    let v = u * c_max / (c_max + k);
    return k * v / max(1.0 - v, 1e-9);
}

fn column_of(p: Params, c: f32) -> Column {
    var out: Column;
    if p.mode == RECT_PROJECTIVE {
        var r = 0u;
        while r + 1u < p.regions && c >= region_x(p, r + 1u) {
            r += 1u;
        }
        let x0 = region_x(p, r);
        let x1 = region_x(p, r + 1u);
        let u = clamp((1.0 / x0 - 1.0 / max(c, 1e-6)) / (1.0 / x0 - 1.0 / x1), 0.0, 1.0);
        let ab = region_columns(p, r);
        out.region = r;
        out.col = f32(ab.x) + u * f32(ab.y - ab.x);
        return out;
    }
    let u = column_warp(c, region_x(p, 1u), region_x(p, 2u));
    let col = u * f32(p.width);
    out.col = col;
    out.region = region_of_column(p, u32(col));
    return out;
}

fn line_of_column(p: Params, col: f32) -> f32 {
    if p.mode == RECT_PROJECTIVE {
        let r = region_of_column(p, u32(max(col, 0.0)));
        let ab = region_columns(p, r);
        let u = (col - f32(ab.x)) / f32(ab.y - ab.x);
        let x0 = region_x(p, r);
        let x1 = region_x(p, r + 1u);
        return 1.0 / (1.0 / x0 - u * (1.0 / x0 - 1.0 / x1));
    }
    return column_unwarp(col / f32(p.width), region_x(p, 1u), region_x(p, 2u));
}

// cpu.rs texel_depth: a texel's depth, with the volume bias added where the host rasterized
// the projective map (the bias in world units along the light is bias/(x·(r₁ − r₀)) in depth).
fn texel_depth(p: Params, stored: f32, col: u32) -> f32 {
    if (p.flags & FLAG_HOST_RASTER) != 0u && p.mode == RECT_PROJECTIVE {
        let x = line_of_column(p, f32(col) + 0.5);
        return stored + p.epipole.z / (x * (p.ranges.w - p.ranges.z));
    }
    return stored;
}

const INF: f32 = 3.0e38;

fn reference_distance(p: Params, rr: f32, row: u32, col: f32) -> f32 {
    let c = line_of_column(p, col);
    if p.mode == RECT_PROJECTIVE {
        let q = row_param(p, f32(row) + 0.5);
        return c * sqrt(1.0 + q * q + rr * rr);
    }
    if p.local == 0u {
        return c / max(sin(rr), 1e-6);
    }
    if rr + c >= PI - 1e-6 {
        return INF;
    }
    return p.light.w * sin(c) / max(sin(rr + c), 1e-9);
}

fn reference_dir(p: Params, rr: f32, row: u32) -> vec3<f32> {
    if p.mode == RECT_PROJECTIVE {
        let q = row_param(p, f32(row) + 0.5);
        return normalize(p.axes[0].xyz + p.axes[1].xyz * q + p.axes[2].xyz * rr);
    }
    return p.axes[2].xyz * cos(rr) + slice_dir(p, row_param(p, f32(row) + 0.5)) * sin(rr);
}

struct Rectified {
    row: f32,
    col: f32,
    region: u32,
    z: f32,
}

// The angle between a and b (any non-zero lengths), atan2(|a × b|, a · b): acos of the
// normalised dot product loses precision near 0 and π (an error of √(2ε) ≈ 3.5e-4 rad at
// θ → 0 in f32, which is where the view rays near the epipole are), atan2 does not.
fn angle_between(a: vec3<f32>, b: vec3<f32>) -> f32 {
    return atan2(length(cross(a, b)), dot(a, b));
}

fn reject(v: vec3<f32>, a: vec3<f32>) -> vec3<f32> {
    return v - a * dot(v, a);
}

fn rectify_point(p: Params, pt: vec3<f32>, dir: vec3<f32>) -> Rectified {
    var out: Rectified;
    let v = pt - p.camera.xyz;
    if p.mode == RECT_PROJECTIVE {
        let ex = p.axes[0].xyz;
        let l = vec3<f32>(dot(dir, ex), dot(dir, p.axes[1].xyz), dot(dir, p.axes[2].xyz));
        let lx = max(l.x, 1e-6);
        out.row = (l.y / lx - p.ranges.x) / (p.ranges.y - p.ranges.x) * f32(p.height);
        out.z = clamp((l.z / lx - p.ranges.z) / (p.ranges.w - p.ranges.z), 0.0, 1.0);
        let c = column_of(p, max(dot(v, ex), region_x(p, 0u)));
        out.col = c.col;
        out.region = c.region;
        return out;
    }
    let a = p.axes[2].xyz;
    var phi = atan2(dot(dir, p.axes[1].xyz), dot(dir, p.axes[0].xyz));
    if (p.flags & FLAG_FULL_CIRCLE) == 0u {
        phi = clamp(phi, p.ranges.x, p.ranges.y);
    }
    out.row = (phi - p.ranges.x) / (p.ranges.y - p.ranges.x) * f32(p.height);
    let theta = angle_between(dir, a);
    out.z = clamp((theta - p.ranges.z) / (p.ranges.w - p.ranges.z), 0.0, 1.0);
    var c = 0.0;
    if p.local == 1u {
        let to_cam = p.camera.xyz - p.light.xyz;
        let to_p = pt - p.light.xyz;
        // 0 where either vector is zero (atan2(0, 0) is undefined in WGSL).
        if dot(to_cam, to_cam) > 0.0 && dot(to_p, to_p) > 0.0 {
            c = angle_between(to_cam, to_p);
        }
    } else {
        c = length(reject(v, a));
    }
    let col = column_of(p, c);
    out.col = col.col;
    out.region = col.region;
    return out;
}

// Fourier basis, eq. 8 (cpu.rs basis_z, basis4, coeff4).
fn basis_z(z: f32) -> f32 {
    if z >= 1.0 {
        return 1.0;
    }
    return Z_MARGIN + (1.0 - 2.0 * Z_MARGIN) * max(z, 0.0);
}

fn basis4(z: f32, layer: u32) -> vec4<f32> {
    let k0 = 2u * layer;
    let c0 = PI * f32(2u * k0 + 1u);
    let c1 = PI * f32(2u * k0 + 3u);
    return vec4<f32>(sin(c0 * z), cos(c0 * z), sin(c1 * z), cos(c1 * z));
}

fn coeff4(z: f32, layer: u32) -> vec4<f32> {
    let k0 = 2u * layer;
    let c0 = PI * f32(2u * k0 + 1u);
    let c1 = PI * f32(2u * k0 + 3u);
    return vec4<f32>(2.0 / c0 * cos(c0 * z), -2.0 / c0 * sin(c0 * z), 2.0 / c1 * cos(c1 * z), -2.0 / c1 * sin(c1 * z));
}

struct Bracket {
    b0: u32,
    b1: u32,
    f: f32,
}

// rectify.rs Rectification::band_bracket: the bands around a view ray, from the nearest row's.
fn band_bracket(p: Params, rows_row: u32, dir: vec3<f32>) -> Bracket {
    var br: Bracket;
    br.b0 = 0u;
    br.b1 = 0u;
    br.f = 0.0;
    let nb = p.bands;
    if nb == 1u {
        return br;
    }
    var param = 0.0;
    let geometric = p.mode == RECT_EPIPOLAR;
    if geometric {
        param = angle_between(dir, p.axes[2].xyz);
    } else {
        param = dot(dir, p.axes[2].xyz) / max(dot(dir, p.axes[0].xyz), 1e-6);
    }
    let base = rows_row * nb;
    if param <= band_value(base) {
        return br;
    }
    for (var b = 0u; b + 1u < nb; b++) {
        let a = band_value(base + b);
        let c = band_value(base + b + 1u);
        if param < c {
            br.b0 = b;
            br.b1 = b + 1u;
            if geometric {
                br.f = clamp(log(max(param, 1e-6) / a) / log(c / a), 0.0, 1.0);
            } else {
                br.f = clamp((param - a) / (c - a), 0.0, 1.0);
            }
            return br;
        }
    }
    br.b0 = nb - 1u;
    br.b1 = nb - 1u;
    return br;
}
