// subsampled / upsample: joint bilateral upsampling of the low-res grid to every pixel — the
// bilateral interpolation of Engelhardt & Dachsbacher 2010, §4.3 (a spatial weight times a
// depth weight, normalised), here on the regular grid: the 2×2 grid samples around the pixel,
// bilinear weights from the positions of their source pixels, times a weight on the relative
// difference of view distances. Where no neighbour is depth-compatible (a silhouette, or an
// object thinner than the grid spacing), the pixel is ray-marched at full resolution here, as
// brute-force would (`edge_remarch`), or takes the neighbour nearest in depth (cf. the filter
// that classifies taps by depth, which §4.3 attributes to Wyman & Ramsey 2008). Mirrored by
// techniques/subsampled/cpu.rs (`bracket`, `depth_weight`, `upsample_pixel`, `upsample`).

struct Params {
    steps: u32,
    jitter: u32,
    frame_index: u32,
    spot_steps: u32,
    spot_denominator: f32,
    grid_width: u32,
    grid_height: u32,
    depth_tolerance: f32,
    edge_remarch: u32,
    cone_aware: u32,
    _pad1: u32,
    _pad2: u32,
}

@group(0) @binding(0) var<uniform> frame: Frame;
@group(0) @binding(1) var<uniform> params: Params;
@group(0) @binding(2) var depth_tex: texture_2d<f32>;
@group(0) @binding(3) var shadow_map: texture_2d_array<f32>;
@group(0) @binding(4) var spot_tex: texture_2d_array<f32>;
@group(0) @binding(5) var out_tex: texture_storage_2d<rgba32float, write>;
@group(0) @binding(6) var grid_tex: texture_2d<f32>;
@group(0) @binding(7) var<storage, read_write> remarched: atomic<u32>;

// Re-marched pixels of this workgroup, added to `remarched` once per workgroup.
var<workgroup> workgroup_remarched: atomic<u32>;

// Below this total weight (of 1) no grid neighbour is depth-compatible.
const MIN_WEIGHT: f32 = 1e-3;

// march.wgsl source_pixel.
fn source_pixel(i: u32, full: u32, grid: u32) -> u32 {
    return ((2u * i + 1u) * full) / (2u * grid);
}

// march.wgsl march_ray: brute-force's march of pixel px.
fn march_ray(px: vec2<u32>, dir: vec3<f32>, s: f32) -> vec3<f32> {
    let p = params;
    return march_pixel(
        frame, shadow_map, spot_tex, px, dir, s, p.steps, p.jitter, p.frame_index, p.spot_steps, p.spot_denominator,
    ).xyz;
}

// The grid samples i0 ≤ i1 whose source pixels bracket pixel x along one axis, and the
// bilinear weight t of i1 (clamped at the borders, where i0 = i1 and t = 0).
struct Bracket {
    i0: u32,
    i1: u32,
    t: f32,
}

fn bracket(x: u32, full: u32, grid: u32) -> Bracket {
    var b: Bracket;
    // The sample whose footprint [i·full/grid, (i+1)·full/grid) holds x.
    let est = ((2u * x + 1u) * grid) / (2u * full);
    if source_pixel(est, full, grid) <= x {
        b.i0 = est;
    } else if est == 0u {
        b.i0 = 0u;
        b.i1 = 0u;
        b.t = 0.0;
        return b;
    } else {
        b.i0 = est - 1u;
    }
    b.i1 = min(b.i0 + 1u, grid - 1u);
    let p0 = source_pixel(b.i0, full, grid);
    let p1 = source_pixel(b.i1, full, grid);
    b.t = 0.0;
    if p1 > p0 {
        b.t = f32(x - p0) / f32(p1 - p0);
    }
    return b;
}

// The range weight of the bilateral filter on r = |s_i − s|/s: 1 up to half the tolerance
// (smooth surfaces keep plain bilinear interpolation), a smoothstep down to 0 at the tolerance.
fn depth_weight(r: f32, tol: f32) -> f32 {
    let t = clamp((r - 0.5 * tol) / (0.5 * tol), 0.0, 1.0);
    return 1.0 - t * t * (3.0 - 2.0 * t);
}

// cpu.rs cone_set: bit k set when the ray o + t·dir, t in [0, s], meets the cone of spot light
// k (the exact ray–cone test of the `exact-cone` policy); 0 for every other light. Outside a
// spot's cone its light is exactly zero, so two rays with different sets see different lights.
fn cone_set(dir: vec3<f32>, s: f32) -> u32 {
    var cones = 0u;
    for (var k = 0u; k < lights.count; k++) {
        let l = lights.items[k];
        if l.kind == LIGHT_SPOT {
            let c = cone_interval(l, frame.camera_pos.xyz, dir, s);
            if c.y > c.x {
                cones |= 1u << k;
            }
        }
    }
    return cones;
}

// cpu.rs any_spot: whether the frame has a spot light (else every cone set is 0).
fn any_spot() -> bool {
    for (var k = 0u; k < lights.count; k++) {
        if lights.items[k].kind == LIGHT_SPOT {
            return true;
        }
    }
    return false;
}

struct Upsampled {
    radiance: vec3<f32>,
    remarched: bool,
}

fn upsample_pixel(px: vec2<u32>) -> Upsampled {
    var out: Upsampled;
    out.remarched = false;
    let dir = pixel_ray(frame, px);
    let s = view_distance(frame, textureLoad(depth_tex, vec2<i32>(px), 0).r, dir);
    let bx = bracket(px.x, frame.width, params.grid_width);
    let by = bracket(px.y, frame.height, params.grid_height);
    var taps = array<vec4<f32>, 4>(
        textureLoad(grid_tex, vec2<i32>(i32(bx.i0), i32(by.i0)), 0),
        textureLoad(grid_tex, vec2<i32>(i32(bx.i1), i32(by.i0)), 0),
        textureLoad(grid_tex, vec2<i32>(i32(bx.i0), i32(by.i1)), 0),
        textureLoad(grid_tex, vec2<i32>(i32(bx.i1), i32(by.i1)), 0),
    );
    var bilinear = array<f32, 4>(
        (1.0 - bx.t) * (1.0 - by.t),
        bx.t * (1.0 - by.t),
        (1.0 - bx.t) * by.t,
        bx.t * by.t,
    );
    // The source pixels of the four taps, in the order of `taps`.
    let gw = params.grid_width;
    let gh = params.grid_height;
    let sx = vec2<u32>(source_pixel(bx.i0, frame.width, gw), source_pixel(bx.i1, frame.width, gw));
    let sy = vec2<u32>(source_pixel(by.i0, frame.height, gh), source_pixel(by.i1, frame.height, gh));
    let sources = array<vec2<u32>, 4>(
        vec2<u32>(sx.x, sy.x),
        vec2<u32>(sx.y, sy.x),
        vec2<u32>(sx.x, sy.y),
        vec2<u32>(sx.y, sy.y),
    );
    let cones = LOCAL_LIGHTS && params.cone_aware == 1u && any_spot();
    var own_cones = 0u;
    if cones {
        own_cones = cone_set(dir, s);
    }
    let inv_s = 1.0 / max(s, 1e-6);
    var sum = vec3<f32>(0.0);
    var wsum = 0.0;
    var nearest = 0u;
    var nearest_diff = abs(taps[0].a - s);
    var nearest_mismatch = true;
    for (var k = 0u; k < 4u; k++) {
        // A tap that sees other spot cones than the pixel is as far as a depth step: it counts
        // neither in the blend nor as the nearest, unless every tap is such.
        var mismatch = false;
        if cones {
            mismatch = cone_set(pixel_ray(frame, sources[k]), taps[k].a) != own_cones;
        }
        let diff = abs(taps[k].a - s);
        let w = select(bilinear[k] * depth_weight(diff * inv_s, params.depth_tolerance), 0.0, mismatch);
        sum += w * taps[k].rgb;
        wsum += w;
        if (nearest_mismatch && !mismatch) || (mismatch == nearest_mismatch && diff < nearest_diff) {
            nearest = k;
            nearest_diff = diff;
            nearest_mismatch = mismatch;
        }
    }
    if wsum >= MIN_WEIGHT {
        out.radiance = sum / wsum;
    } else if params.edge_remarch == 1u {
        out.radiance = march_ray(px, dir, s);
        out.remarched = true;
    } else {
        out.radiance = taps[nearest].rgb;
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
            atomicAdd(&remarched, n);
        }
    }
}
