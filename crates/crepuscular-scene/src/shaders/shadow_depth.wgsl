// host / shadow_depth: rasterizes the scene into one shadow-map layer (depth only).

struct Layer {
    view_proj: mat4x4<f32>,
}

@group(0) @binding(0) var<uniform> layer: Layer;

@vertex
fn vs(@location(0) position: vec3<f32>) -> @builtin(position) vec4<f32> {
    return layer.view_proj * vec4<f32>(position, 1.0);
}
