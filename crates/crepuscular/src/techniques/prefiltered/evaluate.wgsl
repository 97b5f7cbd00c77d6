// prefiltered pass `evaluate` (cpu.rs evaluate, prefiltered_visibility, unoccluded_inscatter):
// Klehm et al. 2014 Listing 4. Per pixel: the surface point into the rectified map, the ray's
// coefficients a(z), one bilinear lookup of the filtered bases per region, a dot product + ½,
// clamped (Appendix A), times the unoccluded in-scattering; pixels in a small disc around a
// visible light are ray-marched instead (§5, Fig. 8).

@group(0) @binding(0) var<uniform> frame: Frame;
@group(0) @binding(1) var<uniform> params: Params;
@group(0) @binding(2) var depth_tex: texture_2d<f32>;
@group(0) @binding(3) var shadow_map: texture_2d_array<f32>;
@group(0) @binding(4) var spot_tex: texture_2d_array<f32>;
@group(0) @binding(5) var out_tex: texture_storage_2d<rgba32float, write>;
@group(0) @binding(6) var<storage, read> rows: array<f32>;
@group(0) @binding(7) var basis_tex: texture_2d_array<f32>;
@group(0) @binding(8) var basis_sampler: sampler;
@group(0) @binding(9) var cumw_tex: texture_2d_array<f32>;

fn band_value(i: u32) -> f32 {
    return rows[i];
}

// cpu.rs footprint: the lookup position (texel space) of the prefix ending at column `col`.
fn lookup_pos(p: Params, col: f32, row: f32, c0: u32, c1: u32) -> vec2<f32> {
    return vec2<f32>(clamp(col - 1.0, f32(c0), f32(c1 - 1u)), row - 0.5);
}

fn load_cumw(p: Params, wset: u32, pos: vec2<f32>) -> f32 {
    let x0 = floor(pos.x);
    let y0 = floor(pos.y);
    let fr = pos - vec2<f32>(x0, y0);
    let h = i32(p.height);
    let xa = i32(x0);
    let xb = min(xa + 1, i32(p.width) - 1);
    var ya = i32(y0);
    var yb = ya + 1;
    if (p.flags & FLAG_FULL_CIRCLE) != 0u {
        ya = ((ya % h) + h) % h;
        yb = ((yb % h) + h) % h;
    } else {
        ya = clamp(ya, 0, h - 1);
        yb = clamp(yb, 0, h - 1);
    }
    let s = i32(wset);
    let a = mix(textureLoad(cumw_tex, vec2<i32>(xa, ya), s, 0).r, textureLoad(cumw_tex, vec2<i32>(xb, ya), s, 0).r, fr.x);
    let b = mix(textureLoad(cumw_tex, vec2<i32>(xa, yb), s, 0).r, textureLoad(cumw_tex, vec2<i32>(xb, yb), s, 0).r, fr.x);
    return mix(a, b, fr.y);
}

fn vis_at(p: Params, wset: u32, pos: vec2<f32>, zs: f32) -> f32 {
    let uv = (pos + 0.5) / vec2<f32>(f32(p.width), f32(p.height));
    var v = 0.5;
    let layers = p.bases / 4u;
    for (var l = 0u; l < layers; l++) {
        let b = textureSampleLevel(basis_tex, basis_sampler, uv, i32(wset * layers + l), 0.0);
        v += dot(coeff4(zs, l), 2.0 * b - 1.0);
    }
    return v;
}

fn prefiltered_visibility(p: Params, wset: u32, row: f32, col: f32, region: u32, z: f32) -> f32 {
    let zs = basis_z(z);
    var num = 0.0;
    var den = 0.0;
    for (var r = 0u; r <= region; r++) {
        let cols = region_columns(p, r);
        var at = f32(cols.y);
        if r == region {
            at = col;
        }
        let pos = lookup_pos(p, at, row, cols.x, cols.y);
        let v = vis_at(p, wset, pos, zs);
        if p.regions == 1u {
            return clamp(v, 0.0, 1.0);
        }
        let wt = load_cumw(p, wset, pos);
        num += wt * v;
        den += wt;
    }
    var v = 0.5;
    if den > 0.0 {
        v = num / den;
    }
    return clamp(v, 0.0, 1.0);
}

// cpu.rs ray_visibility: the two bands around the ray, blended; per channel with RGB weights.
fn ray_visibility(p: Params, pt: vec3<f32>, dir: vec3<f32>) -> vec3<f32> {
    let rp = rectify_point(p, pt, dir);
    let row = min(u32(max(rp.row, 0.0)), p.height - 1u);
    let br = band_bracket(p, row, dir);
    let ch = p.channels;
    var out = vec3<f32>(0.0);
    for (var c = 0u; c < ch; c++) {
        var v = prefiltered_visibility(p, br.b0 * ch + c, rp.row, rp.col, rp.region, rp.z);
        if br.b1 != br.b0 {
            let v1 = prefiltered_visibility(p, br.b1 * ch + c, rp.row, rp.col, rp.region, rp.z);
            v = v + (v1 - v) * br.f;
        }
        out[c] = v;
    }
    if ch == 1u {
        return vec3<f32>(out.x);
    }
    return out;
}

fn unoccluded_inscatter(f: Frame, p: Params, dir: vec3<f32>, s: f32) -> vec3<f32> {
    let st = extinction(f);
    let light = lights.items[0];
    if light.kind == LIGHT_DIRECTIONAL {
        let inc = light_incident(f, light, spot_tex, f.camera_pos.xyz);
        return f.sigma_s.xyz * phase(f, dot(inc.dir, -dir)) * inc.radiance * segment_transmittance(st, s);
    }
    let o = f.camera_pos.xyz;
    let iv = march_interval(f, light, o, dir, s, p.spot_steps, p.epipole.w);
    if iv.y <= iv.x {
        return vec3<f32>(0.0);
    }
    let steps = own_steps(light, iv, p.light_steps, o, dir, p.spot_steps);
    let uni = uniform_step(steps, st, 0.5);
    var sum = vec3<f32>(0.0);
    for (var i = 0u; i < steps.n; i++) {
        let step = march_step(steps, i, st, 0.5, uni);
        let inc = light_incident(f, light, spot_tex, o + dir * (step.t0 + step.off));
        sum += f.sigma_s.xyz * phase(f, dot(inc.dir, -dir)) * inc.radiance * step.scale * exp(-st * step.t0) * step.seg;
    }
    return sum;
}

@compute @workgroup_size(8, 8)
fn evaluate(@builtin(global_invocation_id) id: vec3<u32>) {
    if id.x >= frame.width || id.y >= frame.height {
        return;
    }
    let px = id.xy;
    // The epipole disc is the `epipole` pass's.
    if in_epipole_disc(params, px) {
        return;
    }
    let dir = pixel_ray(frame, px);
    let s = view_distance(frame, textureLoad(depth_tex, vec2<i32>(px), 0).r, dir);
    let l = unoccluded_inscatter(frame, params, dir, s) * ray_visibility(params, frame.camera_pos.xyz + dir * s, dir);
    textureStore(out_tex, vec2<i32>(px), vec4<f32>(l, 1.0));
}
