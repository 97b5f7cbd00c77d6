// host / rectified_depth: rasterizes the scene's depth into one region (a viewport) of the
// rectified shadow map of `prefiltered`, with depth clamping instead of near/far clipping.
//
// `vs` is for a pipeline with `unclipped_depth` (DEPTH_CLIP_CONTROL): the hardware clamps.
// `vs_clamped` + `fs_clamped` is the fallback without that feature: clip z is 0.5·w, so the
// near and far planes never clip (they reduce to w ≥ 0, which the x and y planes already
// imply), and the fragment shader writes the real NDC depth, clamped to [0, 1]. The clip z and
// w are interpolated perspective-correctly, so their ratio is the NDC depth interpolated
// linearly in screen space, as the rasterizer interpolates it.

struct Region {
    view_proj: mat4x4<f32>,
}

@group(0) @binding(0) var<uniform> region: Region;

@vertex
fn vs(@location(0) position: vec3<f32>) -> @builtin(position) vec4<f32> {
    return region.view_proj * vec4<f32>(position, 1.0);
}

struct Clamped {
    @builtin(position) position: vec4<f32>,
    // Clip z and w.
    @location(0) zw: vec2<f32>,
}

@vertex
fn vs_clamped(@location(0) position: vec3<f32>) -> Clamped {
    let c = region.view_proj * vec4<f32>(position, 1.0);
    return Clamped(vec4<f32>(c.xy, 0.5 * c.w, c.w), c.zw);
}

@fragment
fn fs_clamped(in: Clamped) -> @builtin(frag_depth) f32 {
    return clamp(in.zw.x / in.zw.y, 0.0, 1.0);
}
