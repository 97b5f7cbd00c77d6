// host / surface: camera depth and Lambert-lit surface radiance with filtered shadow lookups
// and ambient (docs/MODEL.md §1). Composed after common.wgsl.

@group(0) @binding(0) var<uniform> frame: Frame;
@group(0) @binding(1) var shadow_map: texture_2d_array<f32>;
@group(0) @binding(2) var spot_tex: texture_2d_array<f32>;
// The host's SurfaceShading: ambient (rgb), normal offset in shadow texels (w).
@group(0) @binding(3) var<uniform> shading: vec4<f32>;

struct VertexOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) world: vec3<f32>,
    @location(1) normal: vec3<f32>,
    @location(2) albedo: vec3<f32>,
}

@vertex
fn vs(@location(0) position: vec3<f32>, @location(1) normal: vec3<f32>, @location(2) albedo: vec3<f32>) -> VertexOut {
    var out: VertexOut;
    out.clip = frame.view_proj * vec4<f32>(position, 1.0);
    out.world = position;
    out.normal = normal;
    out.albedo = albedo;
    return out;
}

@fragment
fn fs(in: VertexOut) -> @location(0) vec4<f32> {
    return vec4<f32>(surface_radiance(frame, shading, shadow_map, spot_tex, in.world, in.normal, in.albedo), 1.0);
}
