// subsampled / march: naïve image-space subsampling (Wyman & Ramsey 2008; Engelhardt &
// Dachsbacher 2010, §6 and Fig. 9, "naïve subsampling and ray marching with 256×256 samples").
// One thread per low-resolution sample: the sample takes the ray and the depth of one real
// full-resolution pixel, the centre of its footprint, and marches it exactly as brute-force
// marches that pixel (Tóth & Umenhoffer 2009, eq. 1). Stores the in-scattering (rgb) and the
// view distance s (alpha) for the depth-aware upsampling. Mirrored by
// techniques/subsampled/cpu.rs (`source_pixel`, `march_ray`, `march`).

struct Params {
    steps: u32,
    jitter: u32,
    frame_index: u32,
    spot_steps: u32,
    spot_denominator: f32,
    grid_width: u32,
    grid_height: u32,
    depth_tolerance: f32,
    edge_remarch: u32,
    cone_aware: u32,
    _pad1: u32,
    _pad2: u32,
}

@group(0) @binding(0) var<uniform> frame: Frame;
@group(0) @binding(1) var<uniform> params: Params;
@group(0) @binding(2) var depth_tex: texture_2d<f32>;
@group(0) @binding(3) var shadow_map: texture_2d_array<f32>;
@group(0) @binding(4) var spot_tex: texture_2d_array<f32>;
@group(0) @binding(5) var grid_tex: texture_storage_2d<rgba32float, write>;

// The full-resolution pixel (along one axis of `full` pixels) whose ray low-res sample i of
// `grid` takes: the centre of its footprint, floor((i + 0.5)·full/grid), in exact integers.
fn source_pixel(i: u32, full: u32, grid: u32) -> u32 {
    return ((2u * i + 1u) * full) / (2u * grid);
}

// Brute-force's march of pixel px (eq. 1 over the spot-step policy's interval, N steps).
fn march_ray(px: vec2<u32>, dir: vec3<f32>, s: f32) -> vec3<f32> {
    let p = params;
    return march_pixel(
        frame, shadow_map, spot_tex, px, dir, s, p.steps, p.jitter, p.frame_index, p.spot_steps, p.spot_denominator,
    ).xyz;
}

@compute @workgroup_size(8, 8)
fn march(@builtin(global_invocation_id) gid: vec3<u32>) {
    if gid.x >= params.grid_width || gid.y >= params.grid_height {
        return;
    }
    let px = vec2<u32>(
        source_pixel(gid.x, frame.width, params.grid_width),
        source_pixel(gid.y, frame.height, params.grid_height),
    );
    let dir = pixel_ray(frame, px);
    let d = textureLoad(depth_tex, vec2<i32>(px), 0).r;
    let s = view_distance(frame, d, dir);
    textureStore(grid_tex, vec2<i32>(gid.xy), vec4<f32>(march_ray(px, dir, s), s));
}
