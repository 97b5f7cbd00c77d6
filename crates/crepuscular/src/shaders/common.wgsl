// Shared WGSL for every pass: the frame uniforms, phase functions, lights, shadow lookups and
// the single-scattering integrand (docs/MODEL.md §1). Every function has a Rust twin of the same
// name (model.rs, shadow.rs, integrand.rs, frame.rs) that the CPU mirror calls.
// Composition: this file is prepended to each pass shader (see shaders.rs).

const PI: f32 = 3.14159265358979;

struct Frame {
    inv_view_proj: mat4x4<f32>,
    inv_projection: mat4x4<f32>,
    inv_view: mat4x4<f32>,
    view_proj: mat4x4<f32>,
    camera_pos: vec4<f32>,
    camera_fwd: vec4<f32>,
    sigma_s: vec4<f32>,
    sigma_a: vec4<f32>,
    rayleigh_fraction: vec4<f32>,
    depth_params: vec4<f32>,
    width: u32,
    height: u32,
    phase_kind: u32,
    _pad: u32,
}

// One light (frame.rs LightUniforms).
struct Light {
    shadow_view_proj: array<mat4x4<f32>, 6>,
    position: vec4<f32>,
    direction: vec4<f32>, // xyz; w: cos of the spot's outer angle
    color: vec4<f32>,     // rgb: colour × intensity × scattering; w: cos of the spot's inner angle
    shadow_near: f32,
    shadow_far: f32,
    shadow_bias: f32,
    shadow_texel: f32,
    kind: u32,
    shadow_layers: u32,
    shadow_size: u32,
    shadow_orthographic: u32,
    shadow_first_layer: u32,
    shadow_clear: f32,
    texture_layer: u32,
    slot: u32, // this light's index in `lights` (light_view_proj)
    texture_size: vec2<u32>,
    shadow_filter: u32, // SHADOW_FILTER_*
    _pad1: u32,
}

// frame.rs MAX_LIGHTS, LightsUniforms.
const MAX_LIGHTS: u32 = 16u;
const NO_TEXTURE: u32 = 0xffffffffu;

struct Lights {
    count: u32,
    _pad0: u32,
    _pad1: u32,
    _pad2: u32,
    items: array<Light, 16>,
}

// The frame's lights that reach the view (pass.rs LIGHTS_BINDING): bound by every pass that
// evaluates a light.
@group(0) @binding(15) var<uniform> lights: Lights;

// The shader variant (pass.rs ShaderVariant, pipeline-overridable): whether the frame may hold
// a spot or point light (LOCAL_LIGHTS) and a spot with a projected texture (SPOT_TEXTURES). A
// pipeline built with one false has the code for those lights compiled out: the result is the
// same for a frame without them, and a device that runs untaken branches (llvmpipe) or sizes
// its registers for them no longer pays for them. Every light function tests them first.
override LOCAL_LIGHTS: bool = true;
override SPOT_TEXTURES: bool = true;

// Light::kind and Frame::phase_kind (frame.rs LIGHT_* and PHASE_*).
const LIGHT_DIRECTIONAL: u32 = 0u;
const LIGHT_SPOT: u32 = 1u;
const LIGHT_POINT: u32 = 2u;
// A point light's shadow map: one layer per cube face (shadow.rs CUBE_FACES).
const CUBE_LAYERS: u32 = 6u;
// Light::shadow_filter (shadow.rs ShadowFilter::code).
const SHADOW_FILTER_NEAREST: u32 = 0u;
const SHADOW_FILTER_BILINEAR: u32 = 1u;
const PHASE_ISOTROPIC: u32 = 0u;
const PHASE_HENYEY_GREENSTEIN: u32 = 1u;
const PHASE_RAYLEIGH: u32 = 2u;
const PHASE_HOFFMAN_PREETHAM: u32 = 3u;

fn extinction(f: Frame) -> vec3<f32> {
    return f.sigma_s.xyz + f.sigma_a.xyz;
}

// model.rs linear_depth: [0,1] perspective depth → view-axis distance.
fn linear_depth(d: f32, near: f32, far: f32) -> f32 {
    return near * far / (far - d * (far - near));
}

fn phase_hg(c: f32, g: f32) -> f32 {
    let denom = max(1.0 + g * g - 2.0 * g * c, 1e-6);
    return (1.0 - g * g) / (4.0 * PI * denom * sqrt(denom));
}

fn phase_rayleigh(c: f32) -> f32 {
    return 3.0 / (16.0 * PI) * (1.0 + c * c);
}

// model.rs Phase::eval.
fn phase(f: Frame, c: f32) -> vec3<f32> {
    let kind = f.phase_kind;
    let g = f.sigma_s.w;
    if kind == PHASE_ISOTROPIC {
        return vec3<f32>(1.0 / (4.0 * PI));
    } else if kind == PHASE_HENYEY_GREENSTEIN {
        return vec3<f32>(phase_hg(c, g));
    } else if kind == PHASE_RAYLEIGH {
        return vec3<f32>(phase_rayleigh(c));
    }
    let fr = f.rayleigh_fraction.xyz;
    return fr * phase_rayleigh(c) + (vec3<f32>(1.0) - fr) * phase_hg(c, g);
}

// model.rs segment_transmittance: ∫₀^Δ exp(−σt t) dt per channel, stable as σt → 0.
fn segment_transmittance1(s: f32, delta: f32) -> f32 {
    let x = s * delta;
    if x < 1e-4 {
        return delta * (1.0 - 0.5 * x);
    }
    return (1.0 - exp(-x)) / s;
}

fn segment_transmittance(st: vec3<f32>, delta: f32) -> vec3<f32> {
    return vec3<f32>(
        segment_transmittance1(st.x, delta),
        segment_transmittance1(st.y, delta),
        segment_transmittance1(st.z, delta),
    );
}

// camera.rs FrameCamera::ndc_ray: the near-plane point unprojected in view space (the eye at
// the origin keeps f32 precision), rotated to world. Any perspective projection (docs/MODEL.md §5).
fn ndc_ray(f: Frame, ndc: vec2<f32>) -> vec3<f32> {
    let h = f.inv_projection * vec4<f32>(ndc, 1.0 - f.depth_params.z, 1.0);
    let p = normalize(h.xyz / h.w);
    return normalize((f.inv_view * vec4<f32>(p, 0.0)).xyz);
}

// frame.rs FrameDesc::pixel_ray.
fn pixel_ray(f: Frame, px: vec2<u32>) -> vec3<f32> {
    let size = vec2<f32>(f32(f.width), f32(f.height));
    let ndc = vec2<f32>((f32(px.x) + 0.5) / size.x * 2.0 - 1.0, 1.0 - (f32(px.y) + 0.5) / size.y * 2.0);
    return ndc_ray(f, ndc);
}

// camera.rs FrameCamera::view_depth: distance along the view axis for depth-buffer value d,
// lin = b / (d + a); the far distance where nothing was drawn (d = the far value), beyond it,
// or at infinity.
fn view_depth(f: Frame, d: f32) -> f32 {
    let far = f.camera_fwd.w;
    if d == f.depth_params.z {
        return far;
    }
    let lin = f.depth_params.y / (d + f.depth_params.x);
    // NaN, ∞ or ≤ 0 (a depth value beyond an infinite projection's horizon) → the far distance.
    if !(lin > 0.0 && lin < far) {
        return far;
    }
    return lin;
}

// frame.rs FrameDesc::view_distance.
fn view_distance(f: Frame, d: f32, dir: vec3<f32>) -> f32 {
    return view_depth(f, d) / max(dot(dir, f.camera_fwd.xyz), 1e-4);
}

// frame.rs FrameDesc::far_distance: to the far distance along dir.
fn far_distance(f: Frame, dir: vec3<f32>) -> f32 {
    return f.camera_fwd.w / max(dot(dir, f.camera_fwd.xyz), 1e-4);
}

// shadow.rs cube_face.
fn cube_face(v: vec3<f32>) -> u32 {
    let a = abs(v);
    if a.x >= a.y && a.x >= a.z {
        return select(1u, 0u, v.x >= 0.0);
    } else if a.y >= a.z {
        return select(3u, 2u, v.y >= 0.0);
    }
    return select(5u, 4u, v.z >= 0.0);
}

// shadow.rs ShadowProjection::linear.
fn shadow_linear_depth(l: Light, d: f32) -> f32 {
    // A reversed-Z shadow map (clear value 0) swaps near and far.
    var near = l.shadow_near;
    var far = l.shadow_far;
    if l.shadow_clear == 0.0 {
        near = l.shadow_far;
        far = l.shadow_near;
    }
    if l.shadow_orthographic == 1u {
        return near + d * (far - near);
    }
    return linear_depth(d, near, far);
}

struct ShadowCoord {
    valid: bool,
    layer: u32, // the light's own layer (0, or a cube face)
    texel: vec2<u32>,
    depth: f32, // linear light-space depth of the point
    uv: vec2<f32>,
}

// The light's view-projection of `layer` (0, or a cube face), read through the uniform block
// (`lights.items[l.slot]`) on purpose: indexing the by-value copy `l.shadow_view_proj` with a
// run-time layer makes naga spill all six matrices (384 bytes) to a local array at every call,
// which made every march sample 7x slower on llvmpipe (brute-force, colonnade 320x180, 64
// steps: 1717 ms; 244 ms through the block). Every `Light` a pass holds is a copy of
// `lights.items[slot]` (frame.rs LightsUniforms).
fn light_view_proj(l: Light, layer: u32) -> mat4x4<f32> {
    return lights.items[l.slot].shadow_view_proj[layer];
}

// shadow.rs ShadowMap::coord.
fn shadow_coord(l: Light, p: vec3<f32>) -> ShadowCoord {
    var layer = 0u;
    if LOCAL_LIGHTS && l.shadow_layers == CUBE_LAYERS {
        layer = cube_face(p - l.position.xyz);
    }
    return shadow_coord_clip(l, layer, light_view_proj(l, layer) * vec4<f32>(p, 1.0));
}

// shadow_coord of a point already in layer `layer`'s clip space (shadow.rs
// ShadowMap::clip_coord).
fn shadow_coord_clip(l: Light, layer: u32, c: vec4<f32>) -> ShadowCoord {
    var sc: ShadowCoord;
    sc.valid = false;
    sc.layer = layer;
    if c.w <= 0.0 {
        return sc;
    }
    let ndc = c.xyz / c.w;
    if abs(ndc.x) > 1.0 || abs(ndc.y) > 1.0 {
        return sc;
    }
    // Depth from the near plane (0) to the far plane (1); a reversed-Z map (clear 0) swaps them.
    var from_near = ndc.z;
    if l.shadow_clear == 0.0 {
        from_near = 1.0 - ndc.z;
    }
    // Nearer the light than the near plane: lit. Beyond the far plane: tested at the far plane
    // (shadowed where the texel holds an occluder).
    if from_near < 0.0 {
        return sc;
    }
    var z = ndc.z;
    if from_near > 1.0 {
        z = l.shadow_clear;
    }
    let n = f32(l.shadow_size);
    sc.uv = vec2<f32>(ndc.x * 0.5 + 0.5, 0.5 - ndc.y * 0.5);
    sc.texel = vec2<u32>(min(floor(sc.uv * n), vec2<f32>(n - 1.0)));
    sc.depth = shadow_linear_depth(l, z);
    sc.valid = true;
    return sc;
}

// The stored linear depth at texel t of the light's layer (shadow.rs ShadowMap::texel).
fn shadow_stored(l: Light, shadow_map: texture_2d_array<f32>, t: vec2<i32>, layer: u32) -> f32 {
    return shadow_linear_depth(l, textureLoad(shadow_map, t, i32(l.shadow_first_layer + layer), 0).r);
}

// 1 where the point at linear depth `depth` is lit at texel t of the light's layer, else 0.
fn shadow_lit(l: Light, shadow_map: texture_2d_array<f32>, t: vec2<u32>, layer: u32, depth: f32) -> f32 {
    return select(0.0, 1.0, depth <= shadow_stored(l, shadow_map, vec2<i32>(t), layer) + l.shadow_bias);
}

// shadow.rs bilinear_footprint: the 2×2 texels around uv (x0, y0, x1, y1, clamped to the map)
// and the bilinear weights of x1 and y1 between their centres.
struct Footprint {
    corner: vec4<u32>,
    w: vec2<f32>,
}

fn bilinear_footprint(uv: vec2<f32>, size: u32) -> Footprint {
    let x = uv * f32(size) - 0.5;
    let x0 = floor(x);
    let i = vec2<i32>(x0);
    let hi = i32(size) - 1;
    let lo = clamp(i, vec2<i32>(0), vec2<i32>(hi));
    let up = clamp(i + vec2<i32>(1), vec2<i32>(0), vec2<i32>(hi));
    return Footprint(vec4<u32>(u32(lo.x), u32(lo.y), u32(up.x), u32(up.y)), x - x0);
}

// shadow.rs ShadowMap::visibility: in [0, 1] (1 lit, 0 shadowed), the nearest texel's test or
// the 2×2 bilinear percentage-closer filter (l.shadow_filter; docs/MODEL.md §1 "Visibility");
// outside the map's footprint or nearer than its near plane is lit, beyond its far plane is
// tested at the far plane (shadow_coord_clip).
fn shadow_visibility(l: Light, shadow_map: texture_2d_array<f32>, p: vec3<f32>) -> f32 {
    let sc = shadow_coord(l, p);
    if !sc.valid {
        return 1.0;
    }
    if l.shadow_filter != SHADOW_FILTER_BILINEAR {
        return shadow_lit(l, shadow_map, sc.texel, sc.layer, sc.depth);
    }
    let fp = bilinear_footprint(sc.uv, l.shadow_size);
    let c = fp.corner;
    let v00 = shadow_lit(l, shadow_map, c.xy, sc.layer, sc.depth);
    let v10 = shadow_lit(l, shadow_map, c.zy, sc.layer, sc.depth);
    let v01 = shadow_lit(l, shadow_map, c.xw, sc.layer, sc.depth);
    let v11 = shadow_lit(l, shadow_map, c.zw, sc.layer, sc.depth);
    return bilinear_blend(vec4<f32>(v00, v10, v01, v11), fp.w);
}

// shadow.rs bilinear_blend: the 2×2 texels' tests v = (v00, v10, v01, v11) blended at the
// weights w of x1 and y1; a + (b − a)·w, as the Rust twin writes it (not mix(), whose rounding
// is the driver's).
fn bilinear_blend(v: vec4<f32>, w: vec2<f32>) -> f32 {
    let top = v.x + (v.y - v.x) * w.x;
    let bottom = v.z + (v.w - v.z) * w.x;
    return top + (bottom - top) * w.y;
}

// model.rs RgbTexture::sample: bilinear, clamp to edge, four loads, in the top-left `size`
// texels of layer `layer`.
fn sample_spot_texture(tex: texture_2d_array<f32>, layer: u32, size: vec2<u32>, uv: vec2<f32>) -> vec3<f32> {
    let dim = vec2<i32>(size);
    let x = uv * vec2<f32>(dim) - 0.5;
    let x0 = floor(x);
    let fr = x - x0;
    let i = vec2<i32>(x0);
    let hi = dim - vec2<i32>(1);
    let ly = i32(layer);
    let t00 = textureLoad(tex, clamp(i, vec2<i32>(0), hi), ly, 0).rgb;
    let t10 = textureLoad(tex, clamp(i + vec2<i32>(1, 0), vec2<i32>(0), hi), ly, 0).rgb;
    let t01 = textureLoad(tex, clamp(i + vec2<i32>(0, 1), vec2<i32>(0), hi), ly, 0).rgb;
    let t11 = textureLoad(tex, clamp(i + vec2<i32>(1, 1), vec2<i32>(0), hi), ly, 0).rgb;
    let a = mix(t00, t10, fr.x);
    let b = mix(t01, t11, fr.x);
    return mix(a, b, fr.y);
}

struct Incident {
    radiance: vec3<f32>,
    dir: vec3<f32>, // direction in which the light travels at the point
}

fn smooth_cone(cos_outer: f32, cos_inner: f32, c: f32) -> f32 {
    let t = clamp((c - cos_outer) / max(cos_inner - cos_outer, 1e-6), 0.0, 1.0);
    return t * t * (3.0 - 2.0 * t);
}

// integrand.rs light_incident (with the light's scattering scale in its colour).
fn light_incident(f: Frame, l: Light, spot_tex: texture_2d_array<f32>, p: vec3<f32>) -> Incident {
    var r: Incident;
    let kind = l.kind;
    if !LOCAL_LIGHTS || kind == LIGHT_DIRECTIONAL {
        r.radiance = l.color.xyz;
        r.dir = l.direction.xyz;
        return r;
    }
    let v = p - l.position.xyz;
    let d2 = max(dot(v, v), 1e-8);
    let d = sqrt(d2);
    r.dir = v / d;
    let att = exp(-extinction(f) * d) / d2;
    if kind == LIGHT_POINT {
        r.radiance = l.color.xyz * att;
        return r;
    }
    let cone = smooth_cone(l.direction.w, l.color.w, dot(r.dir, l.direction.xyz));
    if cone <= 0.0 {
        r.radiance = vec3<f32>(0.0);
        return r;
    }
    var tex = vec3<f32>(1.0);
    if SPOT_TEXTURES && l.texture_layer != NO_TEXTURE {
        let c = l.shadow_view_proj[0] * vec4<f32>(p, 1.0);
        if c.w > 0.0 {
            let ndc = c.xy / c.w;
            tex = sample_spot_texture(spot_tex, l.texture_layer, l.texture_size, vec2<f32>(ndc.x * 0.5 + 0.5, 0.5 - ndc.y * 0.5));
        }
    }
    r.radiance = l.color.xyz * cone * att * tex;
    return r;
}

// integrand.rs lit_incident: L_in(x)·V(x) and ω_l — the integrand without σs and the phase
// function, for passes that look the phase function up in a table.
fn lit_incident(f: Frame, l: Light, shadow_map: texture_2d_array<f32>, spot_tex: texture_2d_array<f32>, p: vec3<f32>) -> Incident {
    var li = light_incident(f, l, spot_tex, p);
    if all(li.radiance == vec3<f32>(0.0)) {
        return li;
    }
    li.radiance *= shadow_visibility(l, shadow_map, p);
    return li;
}

// integrand.rs inscatter_density: σs·p(cos θ)·L_in(x)·V(x) of one light.
fn inscatter_density(
    f: Frame,
    l: Light,
    shadow_map: texture_2d_array<f32>,
    spot_tex: texture_2d_array<f32>,
    view_dir: vec3<f32>,
    p: vec3<f32>,
) -> vec3<f32> {
    let li = lit_incident(f, l, shadow_map, spot_tex, p);
    if all(li.radiance == vec3<f32>(0.0)) {
        return vec3<f32>(0.0);
    }
    let cos_theta = -dot(li.dir, view_dir);
    return f.sigma_s.xyz * phase(f, cos_theta) * li.radiance;
}

// ---- Where the N steps go (march.rs; Wyman & Ramsey 2008, Appendix B) ----

// march.rs SpotCone::contains: inside the forward cone of the spot light.
fn cone_contains(l: Light, p: vec3<f32>) -> bool {
    let v = p - l.position.xyz;
    return dot(v, l.direction.xyz) >= l.direction.w * length(v);
}

// march.rs cone_interval: the part [t0, t1] of o + t·d, t in [0, s], inside the cone
// (t1 <= t0 when the ray misses it). Roots of (v·a)² = cos²·|v|², then midpoint tests.
fn cone_interval(l: Light, o: vec3<f32>, d: vec3<f32>, s: f32) -> vec2<f32> {
    if s <= 0.0 {
        return vec2<f32>(0.0);
    }
    let axis = l.direction.xyz;
    let v = o - l.position.xyz;
    let c2 = l.direction.w * l.direction.w;
    let dv = dot(d, axis);
    let va = dot(v, axis);
    let qa = dv * dv - c2;
    let qb = 2.0 * (dv * va - c2 * dot(d, v));
    let qc = va * va - c2 * dot(v, v);
    var cut0 = s;
    var cut1 = s;
    if abs(qa) > 1e-7 {
        let disc = qb * qb - 4.0 * qa * qc;
        if disc >= 0.0 {
            let q = -0.5 * (qb + sign(qb) * sqrt(disc));
            cut0 = q / qa;
            cut1 = select(cut0, qc / q, q != 0.0);
        }
    } else if qb != 0.0 {
        cut0 = -qc / qb;
    }
    let lo = clamp(min(cut0, cut1), 0.0, s);
    let hi = clamp(max(cut0, cut1), 0.0, s);
    let bounds = array<f32, 4>(0.0, lo, hi, s);
    var t0 = s;
    var t1 = 0.0;
    for (var i = 0; i < 3; i++) {
        let a = bounds[i];
        let b = bounds[i + 1];
        if b > a && cone_contains(l, o + d * (0.5 * (a + b))) {
            t0 = min(t0, a);
            t1 = max(t1, b);
        }
    }
    if t1 > t0 {
        return vec2<f32>(t0, t1);
    }
    return vec2<f32>(0.0);
}

// march.rs appendix_b_chord: (d·sin φ, sin(β − φ/2)), Wyman & Ramsey 2008 App. B eq. 3–4.
fn appendix_b_chord(d: f32, cos_beta: f32, cos_half: f32) -> vec2<f32> {
    let sin_half = sqrt(max(1.0 - cos_half * cos_half, 0.0));
    let sin_phi = 2.0 * sin_half * cos_half;
    let sin_beta = sqrt(max(1.0 - cos_beta * cos_beta, 0.0));
    return vec2<f32>(d * sin_phi, sin_beta * cos_half - cos_beta * sin_half);
}

// march.rs smooth_denominator: App. B's smoothstep clamp of the denominator to a floor k.
fn smooth_denominator(den: f32, k: f32) -> f32 {
    let t = clamp(den / (2.0 * k), 0.0, 1.0);
    let w = t * t * (3.0 - 2.0 * t);
    return k + (den - k) * w;
}

// march.rs StepPolicy::code: bits 0-1 the spot policy (SpotSteps::code), MARCH_EQUIANGULAR for
// equiangular steps.
const MARCH_SPOT_MASK: u32 = 3u;
const MARCH_EQUIANGULAR: u32 = 4u;
const SPOT_FIXED: u32 = 0u;
const SPOT_EXACT_CONE: u32 = 1u;
const SPOT_APPENDIX_B_CONSTANT: u32 = 2u;
const SPOT_APPENDIX_B_SMOOTHSTEP: u32 = 3u;

// march.rs march_interval: the interval of the view ray a technique marches with its N steps.
fn policy_interval(l: Light, o: vec3<f32>, d: vec3<f32>, s: f32, code: u32, denominator: f32) -> vec2<f32> {
    let policy = code & MARCH_SPOT_MASK;
    if !LOCAL_LIGHTS || l.kind != LIGHT_SPOT || policy == SPOT_FIXED {
        return vec2<f32>(0.0, s);
    }
    let c = cone_interval(l, o, d, s);
    if c.y <= c.x || policy == SPOT_EXACT_CONE {
        return c;
    }
    let dist = length(o + d * c.x - l.position.xyz);
    let ab = appendix_b_chord(dist, dot(d, l.direction.xyz), l.direction.w);
    var den = denominator;
    if policy == SPOT_APPENDIX_B_SMOOTHSTEP {
        den = smooth_denominator(ab.y, denominator);
    }
    return vec2<f32>(c.x, min(c.x + ab.x / den, s));
}

// march.rs REACH_OPTICAL_DEPTH and light_reach: the radius around a local light beyond which
// its light-path transmittance is below 1e-6 in every channel; 0 = unlimited.
const REACH_OPTICAL_DEPTH: f32 = 13.815511;

fn light_reach(f: Frame, l: Light) -> f32 {
    let st = extinction(f);
    let sigma = min(st.x, min(st.y, st.z));
    if !LOCAL_LIGHTS || l.kind == LIGHT_DIRECTIONAL || sigma <= 0.0 {
        return 0.0;
    }
    return REACH_OPTICAL_DEPTH / sigma;
}

// march.rs clip_to_sphere.
fn clip_to_sphere(iv: vec2<f32>, o: vec3<f32>, d: vec3<f32>, c: vec3<f32>, r: f32) -> vec2<f32> {
    let v = o - c;
    let b = dot(d, v);
    let disc = b * b - (dot(v, v) - r * r);
    if disc < 0.0 {
        return vec2<f32>(iv.x, iv.x);
    }
    let q = sqrt(disc);
    return vec2<f32>(max(iv.x, -b - q), min(iv.y, -b + q));
}

// march.rs march_interval: the policy's interval, cut to a local light's reach.
fn march_interval(f: Frame, l: Light, o: vec3<f32>, d: vec3<f32>, s: f32, policy: u32, denominator: f32) -> vec2<f32> {
    let iv = policy_interval(l, o, d, s, policy, denominator);
    let r = light_reach(f, l);
    if r > 0.0 && iv.y > iv.x {
        return clip_to_sphere(iv, o, d, l.position.xyz, r);
    }
    return iv;
}

// march.rs MarchLights::owns_interval: a spot under a cone policy, and every local light under
// equiangular steps, is marched over its own interval with its own N steps; every other light
// shares one march (docs/MODEL.md §6).
fn own_interval(l: Light, policy: u32) -> bool {
    return LOCAL_LIGHTS && ((l.kind == LIGHT_SPOT && (policy & MARCH_SPOT_MASK) != 0u)
        || (l.kind != LIGHT_DIRECTIONAL && (policy & MARCH_EQUIANGULAR) != 0u));
}

// march.rs MIN_LIGHT_DISTANCE and UNRESOLVED_DISTANCE.
const MIN_LIGHT_DISTANCE: f32 = 1e-4;
const UNRESOLVED_DISTANCE: f32 = 1e-5;

// march.rs Steps: the boundaries of a march's n steps over iv, equal in length or (angular = 1)
// equal in the angle subtended at a local light (docs/MODEL.md §9): t(φ) = along + sign·dist·cot φ,
// φ from phi0 in steps of dphi.
struct Steps {
    iv: vec2<f32>,
    n: u32,
    delta: f32,
    angular: u32,
    along: f32,
    dist: f32,
    sign: f32,
    phi0: f32,
    dphi: f32,
}

// march.rs Steps::uniform.
fn uniform_steps(iv: vec2<f32>, n: u32) -> Steps {
    var st: Steps;
    st.iv = iv;
    st.n = n;
    st.delta = (iv.y - iv.x) / f32(n);
    return st;
}

// march.rs Steps::equiangular.
fn equiangular_steps(iv: vec2<f32>, n: u32, o: vec3<f32>, d: vec3<f32>, centre: vec3<f32>) -> Steps {
    var st = uniform_steps(iv, n);
    if !(iv.y > iv.x) {
        return st;
    }
    let v = centre - o;
    st.along = dot(d, v);
    let dist = length(v - d * st.along);
    // A light on the ray to within its coordinates' precision: uniform steps (march.rs).
    let c = abs(centre);
    if dist <= UNRESOLVED_DISTANCE * (1.0 + max(c.x, max(c.y, c.z))) {
        return st;
    }
    st.dist = max(dist, MIN_LIGHT_DISTANCE);
    let xa = iv.x - st.along;
    let xb = iv.y - st.along;
    st.sign = select(-1.0, 1.0, abs(xb) >= abs(xa));
    st.phi0 = atan2(st.dist, st.sign * xa);
    st.dphi = (atan2(st.dist, st.sign * xb) - st.phi0) / f32(n);
    st.angular = 1u;
    return st;
}

// march.rs MarchLights::own_steps: the steps of light l's own march over iv.
fn own_steps(l: Light, iv: vec2<f32>, n: u32, o: vec3<f32>, d: vec3<f32>, policy: u32) -> Steps {
    if LOCAL_LIGHTS && l.kind != LIGHT_DIRECTIONAL && (policy & MARCH_EQUIANGULAR) != 0u {
        return equiangular_steps(iv, n, o, d, l.position.xyz);
    }
    return uniform_steps(iv, n);
}

// march.rs Steps::boundary: t_k, k in 0..=n (t_0 and t_n the interval's ends exactly).
fn step_boundary(st: Steps, k: u32) -> f32 {
    if k == 0u {
        return st.iv.x;
    }
    if k >= st.n {
        return st.iv.y;
    }
    if st.angular == 0u {
        return st.iv.x + f32(k) * st.delta;
    }
    let phi = st.phi0 + f32(k) * st.dphi;
    return clamp(st.along + st.sign * st.dist * cos(phi) / sin(phi), st.iv.x, st.iv.y);
}

// One step of a march (march.rs Step): its start t0, where its sample sits past t0, its
// transmittance integral ∫₀^len e^(−σt·u) du, and the scale of the integrand at the sample (1, or
// for an equiangular step (d²/D·Δφ)/len: its length under the change of variables over its length).
struct Step {
    t0: f32,
    off: f32,
    seg: vec3<f32>,
    scale: f32,
}

// The step every step of a uniform layout shares (its t0 unused): found once per march.
fn uniform_step(st: Steps, sigma: vec3<f32>, j: f32) -> Step {
    return Step(0.0, step_offset((sigma.x + sigma.y + sigma.z) / 3.0, st.delta, j), segment_transmittance(sigma, st.delta), 1.0);
}

// Step i of `st`; `uni` is uniform_step(st, sigma, j).
fn march_step(st: Steps, i: u32, sigma: vec3<f32>, j: f32, uni: Step) -> Step {
    if st.angular == 0u {
        return Step(st.iv.x + f32(i) * st.delta, uni.off, uni.seg, 1.0);
    }
    let t0 = step_boundary(st, i);
    let len = step_boundary(st, i + 1u) - t0;
    let off = step_offset((sigma.x + sigma.y + sigma.z) / 3.0, len, j);
    // dt = d²/D·dφ at the sample (march.rs Step::scale).
    let x = t0 + off - st.along;
    let scale = select(0.0, (st.dist * st.dist + x * x) / st.dist * abs(st.dphi) / len, len > 0.0);
    return Step(t0, off, segment_transmittance(sigma, len), scale);
}

// march.rs Steps::index_of: the step that holds t.
fn step_index(st: Steps, t: f32) -> u32 {
    var x = (t - st.iv.x) / st.delta;
    if st.angular == 1u {
        x = (atan2(st.dist, st.sign * (t - st.along)) - st.phi0) / st.dphi;
    }
    // NaN or ±Inf (an empty layout) reads as step 0, as in march.rs.
    if !(abs(x) <= 3.4e38) {
        return 0u;
    }
    return min(u32(max(x, 0.0)), st.n - 1u);
}

// march.rs MarchLights::shared_march: the smallest interval holding the march_interval of
// every light that shares the march, and the mask (bit k: lights.items[k]) of those whose
// interval is not empty on this ray; empty (0, 0) with mask 0 when none reaches the ray.
struct SharedMarch {
    iv: vec2<f32>,
    mask: u32,
}

fn shared_march(f: Frame, o: vec3<f32>, d: vec3<f32>, s: f32, policy: u32, denominator: f32) -> SharedMarch {
    var r: SharedMarch;
    var lo = 3.4e38;
    var hi = -3.4e38;
    var mask = 0u;
    for (var k = 0u; k < min(lights.count, MAX_LIGHTS); k++) {
        let l = lights.items[k];
        if own_interval(l, policy) {
            continue;
        }
        let iv = march_interval(f, l, o, d, s, policy, denominator);
        if iv.y > iv.x {
            lo = min(lo, iv.x);
            hi = max(hi, iv.y);
            mask |= 1u << k;
        }
    }
    if hi > lo {
        r.iv = vec2<f32>(lo, hi);
        r.mask = mask;
    }
    return r;
}

// march.rs step_offset: the j-quantile of the transmittance over a step of length delta.
fn step_offset(sigma_mean: f32, delta: f32, j: f32) -> f32 {
    let x = sigma_mean * delta;
    if x < 1e-2 {
        return j * delta * (1.0 + 0.5 * x * (1.0 - j));
    }
    return -log(1.0 - j * (1.0 - exp(-x))) / sigma_mean;
}

// A pixel's jitter in [0, 1): {x/g + y/g² + frame/φ} (docs/MODEL.md §7; the R2 sequence over
// the pixels, spatially stratified, and the golden-ratio sequence from frame to frame), in
// integers modulo 2³² so it is exact. Mirrored by `pixel_jitter` in Rust (`R2_STEPS`,
// `GOLDEN_STEP`).
fn pixel_jitter(px: vec2<u32>, frame: u32) -> f32 {
    let h = px.x * 3242174889u + px.y * 2447445413u + frame * 2654435769u;
    return f32(h >> 8u) * (1.0 / 16777216.0);
}

// shadow.rs ShadowMap::visibility_pcf: 3×3 percentage-closer filter for surfaces, with the
// point pushed along the surface normal by `normal_offset_texels` shadow texels.
fn shadow_pcf(l: Light, shadow_map: texture_2d_array<f32>, p: vec3<f32>, n: vec3<f32>, offset_texels: f32) -> f32 {
    var texel = l.shadow_texel;
    if l.shadow_orthographic == 0u {
        texel *= length(p - l.position.xyz);
    }
    let q = p + n * (offset_texels * texel);
    let sc = shadow_coord(l, q);
    if !sc.valid {
        return 1.0;
    }
    let size = i32(l.shadow_size);
    var sum = 0.0;
    for (var dy = -1; dy <= 1; dy++) {
        for (var dx = -1; dx <= 1; dx++) {
            let t = clamp(vec2<i32>(sc.texel) + vec2<i32>(dx, dy), vec2<i32>(0), vec2<i32>(size - 1));
            let stored = shadow_stored(l, shadow_map, t, sc.layer);
            sum += select(0.0, 1.0, sc.depth <= stored + l.shadow_bias);
        }
    }
    return sum / 9.0;
}

// integrand.rs surface_radiance: Lambert from every light with its shadow map, plus ambient.
// `shading`: the host's SurfaceShading, ambient (rgb) and normal offset in texels (w). The host
// binds all its lights here (scattering 1).
fn surface_radiance(
    f: Frame,
    shading: vec4<f32>,
    shadow_map: texture_2d_array<f32>,
    spot_tex: texture_2d_array<f32>,
    p: vec3<f32>,
    normal: vec3<f32>,
    albedo: vec3<f32>,
) -> vec3<f32> {
    var n = normalize(normal);
    if dot(n, f.camera_pos.xyz - p) < 0.0 {
        n = -n;
    }
    var direct = vec3<f32>(0.0);
    for (var k = 0u; k < min(lights.count, MAX_LIGHTS); k++) {
        let l = lights.items[k];
        let li = light_incident(f, l, spot_tex, p);
        let cosine = max(dot(n, -li.dir), 0.0);
        if cosine > 0.0 && any(li.radiance > vec3<f32>(0.0)) {
            direct += albedo / PI * li.radiance * cosine * shadow_pcf(l, shadow_map, p, n, shading.w);
        }
    }
    return direct + shading.xyz * albedo;
}

// march.rs march_density: σs·p·L_in·V at p summed over the lights of `mask` (bit k:
// lights.items[k]; march.rs LightSet), in increasing k. Only the lights of the mask are read.
fn march_density(
    f: Frame,
    shadow_map: texture_2d_array<f32>,
    spot_tex: texture_2d_array<f32>,
    dir: vec3<f32>,
    p: vec3<f32>,
    mask: u32,
) -> vec3<f32> {
    var sum = vec3<f32>(0.0);
    var m = mask;
    while m != 0u {
        let k = firstTrailingBit(m);
        m &= m - 1u;
        sum += inscatter_density(f, lights.items[k], shadow_map, spot_tex, dir, p);
    }
    return sum;
}

// march.rs march_steps: eq. 1 of Tóth & Umenhoffer 2009 over the n steps of `st` on the view
// ray from the eye along dir; sums the steps i = first, first + stride, … < n (brute-force: 0, 1;
// interleaved: its block offset, M²), step [t_i, t_i+1] sampled at t_i + step_offset(σ̄, its
// length, j) and weighted by the transmittance integrated exactly over it, of the lights of
// `mask` (march_density; one loop over the samples, every light of the mask at each).
fn march_steps(
    f: Frame,
    shadow_map: texture_2d_array<f32>,
    spot_tex: texture_2d_array<f32>,
    dir: vec3<f32>,
    st: Steps,
    first: u32,
    stride: u32,
    j: f32,
    mask: u32,
) -> vec4<f32> {
    if st.iv.y <= st.iv.x {
        return vec4<f32>(0.0);
    }
    let sigma = extinction(f);
    let uni = uniform_step(st, sigma, j);
    var sum = vec4<f32>(0.0);
    for (var i = first; i < st.n; i += stride) {
        let step = march_step(st, i, sigma, j, uni);
        let t = step.t0 + step.off;
        let p = f.camera_pos.xyz + dir * t;
        let term = march_density(f, shadow_map, spot_tex, dir, p, mask) * step.scale * exp(-sigma * step.t0) * step.seg;
        sum += vec4<f32>(term, luminance(term) * t);
    }
    return sum;
}

// march.rs luminance: Rec. 709 luminance of linear RGB.
fn luminance(c: vec3<f32>) -> f32 {
    return dot(c, vec3<f32>(0.2126, 0.7152, 0.0722));
}

// march.rs scattering_distance: the luminance-weighted mean distance of the terms of the
// marches over the lights' own intervals (`own`: their in-scattering in xyz, the sum of each
// term's luminance times its distance in w), where they give at least half of `total`'s
// luminance; 0 elsewhere.
fn scattering_distance(total: vec3<f32>, own: vec4<f32>) -> f32 {
    let y = luminance(own.xyz);
    if y > 0.0 && y >= 0.5 * luminance(total) {
        return max(own.w / y, 0.0);
    }
    return 0.0;
}

// march.rs march_lights: every light's in-scattering on one view ray (docs/MODEL.md §6): one
// march over the shared interval for the lights that share it, plus one over its own interval
// (own_steps) for each light that owns one; the steps i = first, first + stride, … < n of each;
// in w the ray's scattering distance from the latter.
fn march_lights(
    f: Frame,
    shadow_map: texture_2d_array<f32>,
    spot_tex: texture_2d_array<f32>,
    dir: vec3<f32>,
    s: f32,
    n: u32,
    first: u32,
    stride: u32,
    j: f32,
    policy: u32,
    denominator: f32,
) -> vec4<f32> {
    let o = f.camera_pos.xyz;
    let sm = shared_march(f, o, dir, s, policy, denominator);
    var sum = march_steps(f, shadow_map, spot_tex, dir, uniform_steps(sm.iv, n), first, stride, j, sm.mask).xyz;
    var own = vec4<f32>(0.0);
    for (var k = 0u; LOCAL_LIGHTS && k < min(lights.count, MAX_LIGHTS); k++) {
        let l = lights.items[k];
        if own_interval(l, policy) {
            let iv = march_interval(f, l, o, dir, s, policy, denominator);
            let st = own_steps(l, iv, n, o, dir, policy);
            let m = march_steps(f, shadow_map, spot_tex, dir, st, first, stride, j, 1u << k);
            sum += m.xyz;
            own += m;
        }
    }
    return vec4<f32>(sum, scattering_distance(sum, own));
}

// march.rs march_pixel: eq. 1 for pixel px's own ray (brute-force; subsampled), N steps per
// light group (march_lights), at step midpoints or at the pixel's jitter.
fn march_pixel(
    f: Frame,
    shadow_map: texture_2d_array<f32>,
    spot_tex: texture_2d_array<f32>,
    px: vec2<u32>,
    dir: vec3<f32>,
    s: f32,
    steps: u32,
    jitter: u32,
    frame_index: u32,
    spot_steps: u32,
    spot_denominator: f32,
) -> vec4<f32> {
    var j = 0.5;
    if jitter == 1u {
        j = pixel_jitter(px, frame_index);
    }
    return march_lights(f, shadow_map, spot_tex, dir, s, steps, 0u, 1u, j, spot_steps, spot_denominator);
}
