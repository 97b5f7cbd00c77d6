// prefiltered pass `rectify` (cpu.rs rectify; rectify.rs texel_line, occluder_depth,
// line_occluder): per texel of the rectified map, the first occluder on its light line from the
// standard shadow map, as a normalised depth (Klehm et al. 2014 §4.1: "Each light ray, defined by
// the texel position in the rectified shadow map, can be mapped to world space and then to the
// shadow map to recover the necessary input shadow map texel").

@group(0) @binding(0) var<uniform> frame: Frame;
@group(0) @binding(1) var<uniform> params: Params;
@group(0) @binding(2) var shadow_map: texture_2d_array<f32>;
@group(0) @binding(3) var<storage, read> rows: array<f32>;
@group(0) @binding(4) var out_depth: texture_storage_2d<r32float, write>;

fn band_value(i: u32) -> f32 {
    return rows[i];
}

struct Occluder {
    found: bool,
    o: vec3<f32>,
}

fn line_occluder(l: Light, pt: vec3<f32>, dir: vec3<f32>, bias: f32) -> Occluder {
    var r: Occluder;
    r.found = false;
    let ortho = l.shadow_orthographic == 1u;
    var q = pt;
    if !ortho {
        q = l.position.xyz + dir;
    }
    var layer = 0u;
    if l.shadow_layers == CUBE_LAYERS {
        layer = cube_face(dir);
    }
    let c = light_view_proj(l, layer) * vec4<f32>(q, 1.0);
    if c.w <= 0.0 {
        return r;
    }
    let ndc = c.xyz / c.w;
    if abs(ndc.x) > 1.0 || abs(ndc.y) > 1.0 {
        return r;
    }
    let n = f32(l.shadow_size);
    let uv = vec2<f32>(ndc.x * 0.5 + 0.5, 0.5 - ndc.y * 0.5);
    let texel = vec2<u32>(min(floor(uv * n), vec2<f32>(n - 1.0)));
    let d = textureLoad(shadow_map, vec2<i32>(texel), i32(l.shadow_first_layer + layer), 0).r;
    // The shadow map's clear value (1, or 0 for a reversed-Z map): no occluder.
    if (l.shadow_clear == 1.0 && d >= 1.0) || (l.shadow_clear == 0.0 && d <= 0.0) {
        return r;
    }
    let stored = shadow_linear_depth(l, d);
    if ortho {
        r.o = q + dir * (stored - shadow_linear_depth(l, ndc.z));
    } else {
        r.o = l.position.xyz + dir * (stored / c.w);
    }
    r.o += dir * bias;
    r.found = true;
    return r;
}

@compute @workgroup_size(8, 8)
fn rectify(@builtin(global_invocation_id) id: vec3<u32>) {
    if id.x >= params.width || id.y >= params.height {
        return;
    }
    let c = f32(id.x) + 0.5;
    let r = f32(id.y) + 0.5;
    let line = texel_line(params, c, r);
    let light = lights.items[0];
    let occ = line_occluder(light, line.p, line.dir, light.shadow_bias);
    var z = 1.0;
    if occ.found {
        z = occluder_depth(params, c, occ.o);
    }
    textureStore(out_depth, vec2<i32>(id.xy), vec4<f32>(z, 0.0, 0.0, 0.0));
}
