// epipolar / lines: epipolar line generation and the coordinate texture (Engelhardt &
// Dachsbacher 2010, §4.1, §5.1). Entry `lines`, one thread per line k: the segment from the
// border point b_k towards the epipole, clipped to the sample rect R (the part [e, b_k] ∩ R;
// lines whose visible part is shorter than half a pixel are culled), for a spot light shrunk
// to the rays that meet the cone before the far plane (§4.1: "epipolar lines that map to
// outside of the light frustum are omitted"; the rays of one line lie in one plane through the
// camera and the light, and those of them that meet the cone form one contiguous range, found
// by testing the rays at the S texel positions and padding by one texel), and its number of
// initial samples. Entry `coordinates`, one thread per texel (t, k): the point p of the texel,
// the view distance s of pixel ⌊p⌋ from the depth buffer (stored here so that no later pass
// reads depth again), valid. Mirrored by techniques/epipolar/cpu.rs (`setup_line`,
// `spot_clip`, `lines`, `coordinates`).

@group(0) @binding(0) var<uniform> frame: Frame;
@group(0) @binding(1) var<uniform> params: Params;
@group(0) @binding(2) var depth_tex: texture_2d<f32>;
@group(0) @binding(3) var<storage, read_write> lines_buf: array<Line>;
@group(0) @binding(4) var coord_tex: texture_storage_2d<rgba32float, write>;
@group(0) @binding(5) var<storage, read_write> counters: array<atomic<u32>, 4>;

// Shrinks a valid line to the texels whose rays meet the spot cone before the far plane.
fn spot_clip(line_in: Line) -> Line {
    var line = line_in;
    let n = params.samples;
    var first = n;
    var last = 0u;
    for (var i = 0u; i < n; i++) {
        let dir = point_ray(frame, texel_point(line, i));
        let iv = cone_interval(lights.items[0], frame.camera_pos.xyz, dir, far_distance(frame, dir));
        if iv.y > iv.x {
            if first == n {
                first = i;
            }
            last = i;
        }
    }
    if first == n {
        line.valid = 0u;
        return line;
    }
    let i0 = max(first, 1u) - 1u;
    let i1 = min(last + 1u, n - 1u);
    let end = texel_point(line, i1);
    line.length = line.length * (f32(i1 - i0) / f32(n - 1u));
    line.end = end;
    if line.length < MIN_LINE_LENGTH {
        line.valid = 0u;
    }
    return line;
}

fn setup_line(k: u32) -> Line {
    var line: Line;
    let b = line_border_point(frame, k);
    let te = towards_epipole(b);
    line.end = b;
    line.dir = te.xy;
    line.length = 0.0;
    line.valid = 0u;
    line.initial = 0u;
    line._pad = 0u;
    if all(te.xy == vec2<f32>(0.0)) {
        return line;
    }
    let c = clip_ray(frame, b, te.xy, te.z);
    let u0 = max(c.x, 0.0);
    if c.y - u0 < MIN_LINE_LENGTH {
        return line;
    }
    line.end = b + te.xy * u0;
    line.length = c.y - u0;
    line.valid = 1u;
    if lights.items[0].kind == LIGHT_SPOT {
        line = spot_clip(line);
    }
    if line.valid == 1u {
        line.initial = initial_count(frame, line.length);
    } else {
        line.length = 0.0;
    }
    return line;
}

@compute @workgroup_size(64)
fn lines(@builtin(global_invocation_id) gid: vec3<u32>) {
    let k = gid.x;
    if k >= params.slices {
        return;
    }
    let line = setup_line(k);
    lines_buf[k] = line;
    if line.valid == 1u {
        atomicAdd(&counters[2], 1u);
    }
}

@compute @workgroup_size(8, 8)
fn coordinates(@builtin(global_invocation_id) gid: vec3<u32>) {
    let t = gid.x;
    let k = gid.y;
    if t >= params.samples || k >= params.slices {
        return;
    }
    let line = lines_buf[k];
    if line.valid == 0u {
        textureStore(coord_tex, vec2<i32>(i32(t), i32(k)), vec4<f32>(0.0));
        return;
    }
    let p = texel_point(line, t);
    let px = texel_pixel(frame, p);
    let dir = pixel_ray(frame, px);
    let s = view_distance(frame, textureLoad(depth_tex, vec2<i32>(px), 0).r, dir);
    textureStore(coord_tex, vec2<i32>(i32(t), i32(k)), vec4<f32>(p, s, 1.0));
}
