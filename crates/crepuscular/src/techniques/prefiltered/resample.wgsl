// prefiltered / minmax: the light line of a rectified texel and the rectified depth of a point
// on it (rectify.rs texel_line, occluder_depth), shared by prefiltered's pass `rectify` and
// minmax's pass `build` (bounds.wgsl).

struct Line {
    p: vec3<f32>,
    dir: vec3<f32>,
}

fn texel_line(p: Params, col: f32, row: f32) -> Line {
    var l: Line;
    let c = line_of_column(p, col);
    if p.mode == RECT_PROJECTIVE {
        let q = row_param(p, row);
        l.p = p.camera.xyz + p.axes[0].xyz * c + p.axes[1].xyz * (q * c);
        l.dir = p.axes[2].xyz;
        return l;
    }
    let w = slice_dir(p, row_param(p, row));
    let a = p.axes[2].xyz;
    if p.local == 1u {
        l.p = p.light.xyz;
        l.dir = normalize(-a * cos(c) + w * sin(c));
    } else {
        l.p = p.camera.xyz + w * c;
        l.dir = -a;
    }
    return l;
}

fn occluder_depth(p: Params, col: f32, o: vec3<f32>) -> f32 {
    let v = o - p.camera.xyz;
    if p.mode == RECT_PROJECTIVE {
        let x = line_of_column(p, col);
        return clamp((dot(v, p.axes[2].xyz) / x - p.ranges.z) / (p.ranges.w - p.ranges.z), 0.0, 1.0);
    }
    let len = length(v);
    if len < 1e-6 {
        return 0.0;
    }
    let theta = angle_between(v, p.axes[2].xyz);
    return clamp((theta - p.ranges.z) / (p.ranges.w - p.ranges.z), 0.0, 1.0);
}
