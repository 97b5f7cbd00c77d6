// Temporal accumulation after any technique (docs/MODEL.md §7; temporal.rs, whose `resolve_pixel`
// is this pass's CPU mirror, line for line). Per pixel: the current in-scattering c; the
// surface point (or, where nothing was drawn, the view direction) reprojected into the previous
// frame through its view-projection; the history there rejected where it is outside the
// previous image, where the previous frame saw another surface at that spot (its stored view
// distance differs from the point's distance to the previous eye by more than the tolerance) or
// sky where this frame sees a surface (or the reverse); the history, read bilinearly, clipped to
// the current frame's 3×3 neighbourhood (mean ± clip_sigma standard deviations, inside its min
// and max); and the blend out = c + w·(h − c) with w = min(history_weight, n / (n + 1)), n the
// frames the history holds: the plain mean of the first frames, then an exponential average.

struct Temporal {
    prev_view_proj: mat4x4<f32>,
    prev_camera_pos: vec4<f32>,
    history_weight: f32,
    clip_sigma: f32,
    depth_tolerance: f32,
    // 1 when the history holds a previous frame of this size, lights and medium.
    valid: u32,
    // 1 to clip the history to the neighbourhood.
    clip: u32,
    _pad0: u32,
    _pad1: u32,
    _pad2: u32,
}

// temporal.rs MAX_FRAMES: the frame count the history saturates at.
const MAX_FRAMES: f32 = 1024.0;

@group(0) @binding(0) var<uniform> frame: Frame;
@group(0) @binding(1) var<uniform> params: Temporal;
@group(0) @binding(2) var depth_tex: texture_2d<f32>;
@group(0) @binding(3) var current_tex: texture_2d<f32>;
@group(0) @binding(4) var history_tex: texture_2d<f32>;
@group(0) @binding(5) var distance_tex: texture_2d<f32>;
@group(0) @binding(6) var out_tex: texture_storage_2d<rgba32float, write>;
@group(0) @binding(7) var history_out: texture_storage_2d<rgba32float, write>;
@group(0) @binding(8) var distance_out: texture_storage_2d<r32float, write>;
@group(0) @binding(9) var weight_out: texture_storage_2d<r32float, write>;

fn load_current(p: vec2<i32>, size: vec2<i32>) -> vec3<f32> {
    return textureLoad(current_tex, clamp(p, vec2<i32>(0), size - 1), 0).rgb;
}

fn load_history(p: vec2<i32>, size: vec2<i32>) -> vec4<f32> {
    return textureLoad(history_tex, clamp(p, vec2<i32>(0), size - 1), 0);
}

@compute @workgroup_size(8, 8)
fn resolve(@builtin(global_invocation_id) gid: vec3<u32>) {
    let size = vec2<i32>(i32(frame.width), i32(frame.height));
    if i32(gid.x) >= size.x || i32(gid.y) >= size.y {
        return;
    }
    let px = vec2<i32>(gid.xy);
    let cur = textureLoad(current_tex, px, 0);
    let c = cur.rgb;

    // This frame's view distance (negative: nothing drawn), stored for the next frame.
    let d = textureLoad(depth_tex, px, 0).r;
    let dir = pixel_ray(frame, gid.xy);
    let sky = d == frame.depth_params.z;
    var dist = -1.0;
    if !sky {
        dist = view_distance(frame, d, dir);
    }
    textureStore(distance_out, px, vec4<f32>(dist, 0.0, 0.0, 0.0));

    var w = 0.0;
    var n = 0.0;
    var h = c;
    if params.valid == 1u {
        // The point (or direction) in the previous frame.
        var x4 = vec4<f32>(dir, 0.0);
        if !sky {
            x4 = vec4<f32>(frame.camera_pos.xyz + dir * dist, 1.0);
        }
        let clip = params.prev_view_proj * x4;
        if clip.w > 0.0 {
            let ndc = clip.xy / clip.w;
            if abs(ndc.x) <= 1.0 && abs(ndc.y) <= 1.0 {
                let q = vec2<f32>((ndc.x * 0.5 + 0.5) * f32(size.x) - 0.5, (0.5 - ndc.y * 0.5) * f32(size.y) - 0.5);
                let nearest = clamp(vec2<i32>(floor(q + 0.5)), vec2<i32>(0), size - 1);
                let stored = textureLoad(distance_tex, nearest, 0).r;
                var valid = false;
                if sky {
                    valid = stored < 0.0;
                } else {
                    let expected = length(x4.xyz - params.prev_camera_pos.xyz);
                    valid = stored >= 0.0 && abs(stored - expected) <= params.depth_tolerance * expected;
                }
                if valid {
                    let b = floor(q);
                    let f = q - b;
                    let i = vec2<i32>(b);
                    let h00 = load_history(i, size);
                    let h10 = load_history(i + vec2<i32>(1, 0), size);
                    let h01 = load_history(i + vec2<i32>(0, 1), size);
                    let h11 = load_history(i + vec2<i32>(1, 1), size);
                    h = mix(mix(h00.rgb, h10.rgb, f.x), mix(h01.rgb, h11.rgb, f.x), f.y);
                    n = load_history(nearest, size).a;
                    w = min(params.history_weight, n / (n + 1.0));
                }
            }
        }
    }
    if w > 0.0 && params.clip == 1u {
        // Variance clip (neighbourhood mean ± clip_sigma·σ), inside the neighbourhood's range.
        var lo = c;
        var hi = c;
        var m1 = vec3<f32>(0.0);
        var m2 = vec3<f32>(0.0);
        for (var dy = -1; dy <= 1; dy++) {
            for (var dx = -1; dx <= 1; dx++) {
                let s = load_current(px + vec2<i32>(dx, dy), size);
                lo = min(lo, s);
                hi = max(hi, s);
                m1 += s;
                m2 += s * s;
            }
        }
        let mean = m1 / 9.0;
        let sigma = sqrt(max(m2 / 9.0 - mean * mean, vec3<f32>(0.0)));
        let box_lo = max(lo, mean - params.clip_sigma * sigma);
        let box_hi = min(hi, mean + params.clip_sigma * sigma);
        h = clamp(h, box_lo, box_hi);
    }
    let res = c + w * (h - c);
    textureStore(out_tex, px, vec4<f32>(res, cur.a));
    textureStore(history_out, px, vec4<f32>(res, min(n + 1.0, MAX_FRAMES)));
    textureStore(weight_out, px, vec4<f32>(w, 0.0, 0.0, 0.0));
}
