// epipolar / interpolate: interpolation along the lines (Engelhardt & Dachsbacher 2010, §5.3:
// "for every texel it looks up both interpolation sources, and interpolates according to its
// relative position"). One thread per texel: the ray-march samples left and right of the
// interpolation texture, read from the marched texture at their pixels, mixed linearly by
// (t − left)/(right − left) (a ray-march sample reads itself). Writes (in-scattering, s) into the radiance texture — a second texture, since
// WebGPU core cannot read and write one rgba32float storage texture. Culled lines get 0.
// Mirrored by techniques/epipolar/cpu.rs (`interpolate_texel`, `interpolate`).

@group(0) @binding(0) var<uniform> frame: Frame;
@group(0) @binding(1) var<uniform> params: Params;
@group(0) @binding(2) var coord_tex: texture_2d<f32>;
@group(0) @binding(3) var interp_tex: texture_2d<u32>;
@group(0) @binding(4) var marched_tex: texture_2d<f32>;
@group(0) @binding(5) var radiance_tex: texture_storage_2d<rgba32float, write>;

// The marched in-scattering of texel t of line k: at its pixel.
fn marched_at(t: u32, k: u32) -> vec3<f32> {
    let px = texel_pixel(frame, textureLoad(coord_tex, vec2<i32>(i32(t), i32(k)), 0).xy);
    return textureLoad(marched_tex, vec2<i32>(px), 0).rgb;
}

@compute @workgroup_size(8, 8)
fn interpolate(@builtin(global_invocation_id) gid: vec3<u32>) {
    let t = gid.x;
    let k = gid.y;
    if t >= params.samples || k >= params.slices {
        return;
    }
    let texel = vec2<i32>(i32(t), i32(k));
    let c = textureLoad(coord_tex, texel, 0);
    if c.w == 0.0 {
        textureStore(radiance_tex, texel, vec4<f32>(0.0));
        return;
    }
    let lr = textureLoad(interp_tex, texel, 0).r;
    let left = lr & 0xffffu;
    let right = lr >> 16u;
    let a = marched_at(left, k);
    var l = a;
    if right != left {
        let b = marched_at(right, k);
        let w = f32(t - left) / f32(right - left);
        l = a * (1.0 - w) + b * w;
    }
    textureStore(radiance_tex, texel, vec4<f32>(l, c.z));
}
