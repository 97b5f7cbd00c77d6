// `crepuscular view`: final composite L = T(s)·L_surface + L_scatt and the display transform
// (exposure, Narkowicz's ACES fit, sRGB OETF) in one fullscreen pass, written to an Rgba8Unorm
// texture. Mirrors `surface_transmittance` (frame.rs) and `ToneMap::apply` (tonemap.rs).

struct Params {
    inv_view_proj: mat4x4<f32>,
    // xyz: camera position; w: near plane.
    camera_pos: vec4<f32>,
    // xyz: camera forward; w: far plane.
    camera_fwd: vec4<f32>,
    // rgb: extinction σt; w: exposure.
    sigma_t: vec4<f32>,
    // x, y: image width and height.
    size: vec4<f32>,
};

@group(0) @binding(0) var<uniform> p: Params;
@group(0) @binding(1) var surface_tex: texture_2d<f32>;
@group(0) @binding(2) var inscatter_tex: texture_2d<f32>;
@group(0) @binding(3) var depth_tex: texture_depth_2d;

@vertex
fn vs(@builtin(vertex_index) i: u32) -> @builtin(position) vec4<f32> {
    let uv = vec2<f32>(f32((i << 1u) & 2u), f32(i & 2u));
    return vec4<f32>(uv * 2.0 - 1.0, 0.0, 1.0);
}

fn aces(x: f32) -> f32 {
    return clamp(x * (2.51 * x + 0.03) / (x * (2.43 * x + 0.59) + 0.14), 0.0, 1.0);
}

fn srgb_oetf(c: f32) -> f32 {
    if c <= 0.0031308 {
        return 12.92 * c;
    }
    return 1.055 * pow(c, 1.0 / 2.4) - 0.055;
}

fn display(linear: f32) -> f32 {
    var x = linear * p.sigma_t.w;
    // NaN and negative → 0 (as `sanitize` in tonemap.rs).
    if !(x > 0.0) {
        x = 0.0;
    }
    return srgb_oetf(aces(x));
}

@fragment
fn fs(@builtin(position) pos: vec4<f32>) -> @location(0) vec4<f32> {
    let xy = vec2<i32>(pos.xy);
    let d = textureLoad(depth_tex, xy, 0);
    let ndc = vec2<f32>(pos.x / p.size.x * 2.0 - 1.0, 1.0 - pos.y / p.size.y * 2.0);
    let far_point = p.inv_view_proj * vec4<f32>(ndc, 1.0, 1.0);
    let dir = normalize(far_point.xyz / far_point.w - p.camera_pos.xyz);
    let near = p.camera_pos.w;
    let far = p.camera_fwd.w;
    let lin = near * far / (far - d * (far - near));
    let s = lin / max(dot(dir, p.camera_fwd.xyz), 1e-4);
    let t = exp(-p.sigma_t.xyz * s);
    let l = textureLoad(surface_tex, xy, 0).rgb * t + textureLoad(inscatter_tex, xy, 0).rgb;
    return vec4<f32>(display(l.r), display(l.g), display(l.b), 1.0);
}
