// minmax: the conservative level 0 of the tree where the rectified map resamples the standard
// shadow map (cpu.rs texel_bounds, UNBOUNDED, MAX_FOOTPRINT). The pass declares `shadow_map`.

const UNBOUNDED: vec2<f32> = vec2<f32>(-1.0, 2.0);
const MAX_FOOTPRINT: u32 = 4096u;

// One of a texel's nine sample lines: its column coordinate, point, direction, and the clip
// position of the point the light's map projects.
struct SampleLine {
    col: f32,
    p: vec3<f32>,
    dir: vec3<f32>,
    q: vec4<f32>,
}

// The rectified depth of the occluder at light depth `stored` on line `s` (cpu.rs
// texel_bounds's `depth`).
fn line_depth(p: Params, l: Light, s: SampleLine, stored: f32) -> f32 {
    var o: vec3<f32>;
    if l.shadow_orthographic == 1u {
        o = s.p + s.dir * (stored - shadow_linear_depth(l, s.q.z / s.q.w));
    } else {
        o = l.position.xyz + s.dir * (stored / s.q.w);
    }
    return occluder_depth(p, s.col, o + s.dir * l.shadow_bias);
}

// cpu.rs texel_bounds: bounds on the rectified depth of the occluders of every light line
// through rectified texel (col, row).
fn texel_bounds(p: Params, l: Light, col: u32, row: u32) -> vec2<f32> {
    let centre = texel_line(p, f32(col) + 0.5, f32(row) + 0.5);
    var layer = 0u;
    if l.shadow_layers == CUBE_LAYERS {
        layer = cube_face(centre.dir);
    }
    let m = light_view_proj(l, layer);
    let n = f32(l.shadow_size);
    var lo = vec2<f32>(3.0e38);
    var hi = vec2<f32>(-3.0e38);
    var lines: array<SampleLine, 9>;
    for (var k = 0u; k < 9u; k++) {
        let c = f32(col) + 0.5 * f32(k % 3u);
        let li = texel_line(p, c, f32(row) + 0.5 * f32(k / 3u));
        var layer_k = 0u;
        if l.shadow_layers == CUBE_LAYERS {
            layer_k = cube_face(li.dir);
        }
        var pt = li.p;
        if l.shadow_orthographic != 1u {
            pt = l.position.xyz + li.dir;
        }
        let q = m * vec4<f32>(pt, 1.0);
        if q.w <= 0.0 || layer_k != layer {
            return UNBOUNDED;
        }
        let uv = vec2<f32>((q.x / q.w * 0.5 + 0.5) * n, (0.5 - q.y / q.w * 0.5) * n);
        lo = min(lo, uv);
        hi = max(hi, uv);
        lines[k] = SampleLine(c, li.p, li.dir, q);
    }
    var near = 3.0e38;
    var far = -3.0e38;
    var open = lo.x < 0.0 || lo.y < 0.0 || hi.x > n || hi.y > n;
    if !(hi.x < 0.0 || hi.y < 0.0 || lo.x >= n || lo.y >= n) {
        // The texels a lookup inside the box can read: the one it falls in (nearest), or the
        // 2×2 around it (bilinear).
        var reach = 0.0;
        var extra = 0.0;
        if l.shadow_filter == SHADOW_FILTER_BILINEAR {
            reach = 0.5;
            extra = 1.0;
        }
        let t0 = vec2<u32>(clamp(floor(lo - reach), vec2<f32>(0.0), vec2<f32>(n - 1.0)));
        let t1 = vec2<u32>(clamp(floor(hi - reach) + extra, vec2<f32>(0.0), vec2<f32>(n - 1.0)));
        if (t1.x - t0.x + 1u) * (t1.y - t0.y + 1u) > MAX_FOOTPRINT {
            return UNBOUNDED;
        }
        for (var y = t0.y; y <= t1.y; y++) {
            for (var x = t0.x; x <= t1.x; x++) {
                let d = textureLoad(shadow_map, vec2<i32>(i32(x), i32(y)), i32(l.shadow_first_layer + layer), 0).r;
                // The shadow map's clear value (1, or 0 for a reversed-Z map): no occluder.
                if (l.shadow_clear == 1.0 && d >= 1.0) || (l.shadow_clear == 0.0 && d <= 0.0) {
                    open = true;
                } else {
                    let stored = shadow_linear_depth(l, d);
                    near = min(near, stored);
                    far = max(far, stored);
                }
            }
        }
    }
    var b = vec2<f32>(3.0e38, -3.0e38);
    if open {
        b = vec2<f32>(1.0, 1.0);
    }
    if near <= far {
        for (var k = 0u; k < 9u; k++) {
            b = vec2<f32>(min(b.x, line_depth(p, l, lines[k], near)), max(b.y, line_depth(p, l, lines[k], far)));
        }
    }
    return b;
}
