// The final composite (docs/MODEL.md §1): L = T(s)·L_surface + L_scatt per pixel, with
// T(s) = exp(−σt·s) and s the distance to the visible surface rebuilt from the depth buffer
// exactly as the techniques rebuild it (`pixel_ray`, `view_distance` in common.wgsl); then,
// optionally, the display transform of tonemap.rs (exposure, Narkowicz's ACES fit, the sRGB
// OETF unless the target encodes sRGB itself). The CPU mirror is `tonemap::composite` over
// `frame::surface_transmittance`, and `ToneMap::apply`.

struct Params {
    // x: exposure; y: 1 = apply the display transform; z: 1 = encode sRGB in the shader.
    tone: vec4<f32>,
}

@group(0) @binding(0) var<uniform> f: Frame;
@group(0) @binding(1) var<uniform> params: Params;
@group(0) @binding(2) var surface_tex: texture_2d<f32>;
@group(0) @binding(3) var inscatter_tex: texture_2d<f32>;
@group(0) @binding(4) var depth_tex: texture_2d<f32>;

@vertex
fn vs(@builtin(vertex_index) i: u32) -> @builtin(position) vec4<f32> {
    let uv = vec2<f32>(f32((i << 1u) & 2u), f32(i & 2u));
    return vec4<f32>(uv * 2.0 - 1.0, 0.0, 1.0);
}

// tonemap.rs aces_narkowicz.
fn aces(x: f32) -> f32 {
    if x > 1.0e6 {
        return 1.0;
    }
    return clamp(x * (2.51 * x + 0.03) / (x * (2.43 * x + 0.59) + 0.14), 0.0, 1.0);
}

// tonemap.rs srgb_oetf.
fn srgb_oetf(c: f32) -> f32 {
    let x = clamp(c, 0.0, 1.0);
    if x <= 0.0031308 {
        return 12.92 * x;
    }
    return 1.055 * pow(x, 1.0 / 2.4) - 0.055;
}

// tonemap.rs ToneMap::curve (+ the OETF where the target does not encode).
fn display(linear: f32) -> f32 {
    var x = linear * params.tone.x;
    // NaN and negative → 0 (as `sanitize` in tonemap.rs).
    if !(x > 0.0) {
        x = 0.0;
    }
    let c = aces(x);
    return select(c, srgb_oetf(c), params.tone.z > 0.5);
}

@fragment
fn fs(@builtin(position) pos: vec4<f32>) -> @location(0) vec4<f32> {
    let px = vec2<u32>(pos.xy);
    let xy = vec2<i32>(px);
    let dir = pixel_ray(f, px);
    let s = view_distance(f, textureLoad(depth_tex, xy, 0).r, dir);
    let t = exp(-extinction(f) * s);
    let l = t * textureLoad(surface_tex, xy, 0).rgb + textureLoad(inscatter_tex, xy, 0).rgb;
    if params.tone.y > 0.5 {
        return vec4<f32>(display(l.r), display(l.g), display(l.b), 1.0);
    }
    return vec4<f32>(l, 1.0);
}
