// Pass `epipole` of `prefiltered` and `minmax` (prefiltered/cpu.rs march_epipole,
// in_epipole_disc): the pixels of a small disc around a visible light are ray-marched instead of
// read from the rectified map, where view and light rays are nearly parallel (Klehm et al. 2014
// §5, Fig. 8). Appended to the pass that owns the bindings 0–5 of the frame pass.

fn in_epipole_disc(p: Params, px: vec2<u32>) -> bool {
    let r = p.epipole_radius;
    let d = vec2<f32>(px) + 0.5 - p.epipole.xy;
    return r > 0u && dot(d, d) <= f32(r * r);
}

// The pixels of the epipole disc, ray-marched (§5): dispatched over the disc's bounding box only
// (its first pixel is the disc's, see `Prefiltered::encode`).
@compute @workgroup_size(8, 8)
fn epipole(@builtin(global_invocation_id) id: vec3<u32>) {
    let r = f32(params.epipole_radius);
    let origin = vec2<u32>(max(floor(params.epipole.xy - r), vec2<f32>(0.0)));
    let px = origin + id.xy;
    if px.x >= frame.width || px.y >= frame.height || !in_epipole_disc(params, px) {
        return;
    }
    let dir = pixel_ray(frame, px);
    let s = view_distance(frame, textureLoad(depth_tex, vec2<i32>(px), 0).r, dir);
    let l = march_pixel(frame, shadow_map, spot_tex, px, dir, s, params.epipole_steps, 0u, 0u, params.spot_steps, params.epipole.w).xyz;
    textureStore(out_tex, vec2<i32>(px), vec4<f32>(l, 1.0));
}
