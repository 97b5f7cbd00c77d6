// Temporal accumulation after any technique (docs/MODEL.md §7; temporal.rs, whose `resolve_pixel`
// is this pass's CPU mirror, line for line). Per pixel: the current in-scattering c; the
// point at its scattering distance where the input gives one (a negative alpha, minus that
// distance), else the surface point (or, where nothing was drawn, the view direction) reprojected into the previous
// frame through its view-projection; the history there read (bilinear, or Catmull-Rom where all
// 16 texels agree) from the texels where
// the previous frame saw the same surface (its stored view distance within the tolerance of the
// point's distance to the previous eye; sky for sky), renormalised, and rejected where none
// did or the point is outside the previous image; the history clipped to
// the current frame's 3×3 neighbourhood on the same surface (mean ± clip_sigma standard
// deviations, inside its min and max); and the blend out = c + w·(h − c) with
// w = min(history_weight, n / (n + 1)), n the frames the history holds: the plain mean of the
// first frames, then an exponential average, its weight lowered where the pixel's input drifts
// more than its noise explains (adapted_weight). While a history holds fewer than young_frames
// frames (1 where it starts: a reset, a rejection), the output leans on the neighbourhood's mean
// as far as the pixel's own changes say its running mean is still noisy (young_mean_weight).

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
    // 1 for the Catmull-Rom history read (temporal.rs HistoryFilter::CatmullRom).
    catmull_rom: u32,
    // 1 when motion_tex holds the frame's motion vectors (temporal.rs MOTION_VECTORS).
    motion: u32,
    // 1 to adapt the weight to the pixel's noise and drift (temporal.rs
    // TemporalSettings::adaptive_weight).
    adaptive: u32,
    // temporal.rs TemporalSettings::young_frames, as a float (0 or 1: off).
    young_frames: f32,
    // How many of `lamps` are set; the disc radius in pixels (temporal.rs
    // TemporalSettings::light_disc_radius).
    lamp_count: u32,
    lamp_radius: f32,
    // 1 to reproject by the input's scattering distance where its alpha is negative (minus
    // that distance; temporal.rs TemporalSettings::scattering_distance).
    scattering: u32,
    // The point and spot lights in front of the eye: their projection in pixels (xy) and their
    // distance from the eye (z) (temporal.rs lamp_discs).
    lamps: array<vec4<f32>, MAX_LIGHTS>,
}

// temporal.rs in_lamp_disc: within lamp_radius of a light nearer than the pixel's surface.
fn in_lamp_disc(p: vec2<u32>, dist: f32) -> bool {
    let q = vec2<f32>(p) + 0.5;
    for (var i = 0u; i < params.lamp_count; i++) {
        let l = params.lamps[i];
        if length(q - l.xy) < params.lamp_radius && (dist < 0.0 || l.z < dist) {
            return true;
        }
    }
    return false;
}

// temporal.rs catmull_rom_weights: the weights of the texels at -1, 0, 1, 2 at fraction f.
fn catmull_rom_weights(f: f32) -> vec4<f32> {
    return vec4<f32>(
        f * (-0.5 + f * (1.0 - 0.5 * f)),
        1.0 + f * f * (-2.5 + 1.5 * f),
        f * (0.5 + f * (2.0 - 1.5 * f)),
        f * f * (-0.5 + 0.5 * f),
    );
}

// temporal.rs MAX_FRAMES: the frame count the history saturates at.
const MAX_FRAMES: f32 = 1024.0;
// temporal.rs MOMENT_WEIGHT: the past's weight in the moments of a pixel's frame-to-frame change.
const MOMENT_WEIGHT: f32 = 0.8;
// temporal.rs ADAPT_AFTER: the frames a history must hold before its moments steer the weight.
const ADAPT_AFTER: f32 = 4.5;
// temporal.rs NOISE_FLOOR: the least noise assumed, relative to the pixel's value.
const NOISE_FLOOR: f32 = 0.00390625;

// temporal.rs YOUNG_NOISE_MARGIN: how much a young history's noise estimate is widened.
const YOUNG_NOISE_MARGIN: f32 = 2.0;

// temporal.rs young_mean_weight: the weight of the frame's 3×3 same-surface mean in a young
// history's output (k = youth ≥ 2 frames held): the noise T keeps, m2/2/k widened by
// YOUNG_NOISE_MARGIN, against it plus the squared bias between M and T; at most (N − k)/(N − 1).
fn young_mean_weight(m2: f32, youth: f32, bias: f32, young_frames: f32) -> f32 {
    let noise = 0.5 * m2 / youth * (1.0 + YOUNG_NOISE_MARGIN / (youth - 1.0));
    let total = noise + bias * bias;
    var m = 0.0;
    if total > 0.0 {
        m = noise / total;
    }
    return min(m, (young_frames - youth) / (young_frames - 1.0));
}

// temporal.rs adapted_weight: the weight where the squared error of the noise the average
// leaves, σ²·(1 − w)/(1 + w) (σ² at least (NOISE_FLOOR·x)²), plus that of its lag behind the
// drift, (δ·w/(1 − w))², is least: δ²·w·(1 + w)² = σ²·(1 − w)³, by 16 halvings below w (w
// itself where the root is above it).
fn balance(drift2: f32, noise: f32, v: f32) -> f32 {
    return drift2 * v * (1.0 + v) * (1.0 + v) - noise * (1.0 - v) * (1.0 - v) * (1.0 - v);
}

fn adapted_weight(w: f32, m1: f32, m2: f32, a: f32, x: f32) -> f32 {
    let v = max(m2 - m1 * m1, 0.0);
    let noise = 0.5 * v + (NOISE_FLOOR * x) * (NOISE_FLOOR * x);
    let drift2 = max(m1 * m1 - v * (1.0 - a) / (1.0 + a), 0.0);
    if balance(drift2, noise, w) <= 0.0 {
        return w;
    }
    var lo = 0.0;
    var hi = w;
    for (var i = 0; i < 16; i++) {
        let mid = 0.5 * (lo + hi);
        if balance(drift2, noise, mid) <= 0.0 {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    return lo;
}

@group(0) @binding(0) var<uniform> frame: Frame;
@group(0) @binding(1) var<uniform> params: Temporal;
@group(0) @binding(2) var depth_tex: texture_2d<f32>;
@group(0) @binding(3) var current_tex: texture_2d<f32>;
@group(0) @binding(4) var history_tex: texture_2d<f32>;
// Per pixel of the previous frame: the distance it was reprojected from (its view distance, or
// its scattering distance), its input's largest channel, and the running moments (mean, mean
// square) of that channel's frame-to-frame change.
@group(0) @binding(5) var stats_tex: texture_2d<f32>;
@group(0) @binding(6) var out_tex: texture_storage_2d<rgba32float, write>;
@group(0) @binding(7) var history_out: texture_storage_2d<rgba32float, write>;
@group(0) @binding(8) var stats_out: texture_storage_2d<rgba32float, write>;
@group(0) @binding(9) var weight_out: texture_storage_2d<r32float, write>;
// Current minus previous screen position, UV units (x right, y down); read only when
// params.motion is 1, and then only for drawn pixels.
@group(0) @binding(10) var motion_tex: texture_2d<f32>;

// This frame's view distance at pixel p; -1 where nothing was drawn (temporal.rs
// view_distances; one pass, so each read recomputes it).
fn current_distance(p: vec2<u32>) -> f32 {
    let d = textureLoad(depth_tex, vec2<i32>(p), 0).r;
    if d == frame.depth_params.z {
        return -1.0;
    }
    return view_distance(frame, d, pixel_ray(frame, p));
}

// temporal.rs same_surface: sky with sky, else within the tolerance of `reference`.
fn same_surface(stored: f32, reference: f32) -> bool {
    if reference < 0.0 {
        return stored < 0.0;
    }
    return stored >= 0.0 && abs(stored - reference) <= params.depth_tolerance * reference;
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

    // This frame's view distance (negative: nothing drawn).
    let dir = pixel_ray(frame, gid.xy);
    let dist = current_distance(gid.xy);
    // The distance the history is reprojected from (and stored for the next frame): the
    // input's scattering distance where it gives one, else the surface's (-1: sky, a
    // direction).
    let scattered = params.scattering == 1u && cur.a < 0.0;
    let rdist = select(dist, -cur.a, scattered);
    let sky = rdist < 0.0;
    // Within the disc of a light seen directly: the current frame as it is, and a history that
    // starts again from it.
    if in_lamp_disc(gid.xy, dist) {
        textureStore(stats_out, px, vec4<f32>(rdist, max(c.r, max(c.g, c.b)), 0.0, 0.0));
        textureStore(out_tex, px, cur);
        textureStore(history_out, px, vec4<f32>(c, 1.0));
        textureStore(weight_out, px, vec4<f32>(0.0));
        return;
    }

    var w = 0.0;
    var n = 0.0;
    var h = c;
    // The reprojected statistics: the input's largest channel and the moments of its change.
    var hs = vec3<f32>(0.0);
    if params.valid == 1u {
        // The point (or direction) in the previous frame.
        var x4 = vec4<f32>(dir, 0.0);
        if !sky {
            x4 = vec4<f32>(frame.camera_pos.xyz + dir * rdist, 1.0);
        }
        // Where the previous frame saw it: by the motion vector for a drawn pixel reprojected
        // by its surface when they are given (temporal.rs motion_source), else through the
        // previous camera; outside the previous image, nowhere.
        var q = vec2<f32>(0.0);
        var seen = false;
        if params.motion == 1u && !sky && !scattered {
            let mv = textureLoad(motion_tex, px, 0).xy;
            q = vec2<f32>(f32(px.x) - mv.x * f32(size.x), f32(px.y) - mv.y * f32(size.y));
            seen = all(q >= vec2<f32>(-0.5)) && all(q <= vec2<f32>(size) - 0.5);
        } else {
            let clip = params.prev_view_proj * x4;
            if clip.w > 0.0 {
                let ndc = clip.xy / clip.w;
                if abs(ndc.x) <= 1.0 && abs(ndc.y) <= 1.0 {
                    q = vec2<f32>((ndc.x * 0.5 + 0.5) * f32(size.x) - 0.5, (0.5 - ndc.y * 0.5) * f32(size.y) - 0.5);
                    seen = true;
                }
            }
        }
        if seen {
            // The distance the previous frame must have stored where it saw this point: the
            // point's distance to the previous eye, -1 for sky.
            let expected = select(length(x4.xyz - params.prev_camera_pos.xyz), -1.0, sky);
            // Bilinear over the four history texels around q, each kept only where the
            // previous frame saw the same surface (or sky) there.
            let b = floor(q);
            let f = q - b;
            let i = vec2<i32>(b);
            var acc = vec4<f32>(0.0);
            var acc_s = vec3<f32>(0.0);
            var total = 0.0;
            for (var k = 0; k < 4; k++) {
                let o = vec2<i32>(k & 1, k >> 1u);
                let t = clamp(i + o, vec2<i32>(0), size - 1);
                let st = textureLoad(stats_tex, t, 0);
                let same = same_surface(st.r, expected);
                let fw = select(1.0 - f.x, f.x, o.x == 1) * select(1.0 - f.y, f.y, o.y == 1);
                if same && fw > 0.0 {
                    acc += fw * textureLoad(history_tex, t, 0);
                    acc_s += fw * st.gba;
                    total += fw;
                }
            }
            if total > 1e-3 {
                h = acc.rgb / total;
                n = acc.a / total;
                hs = acc_s / total;
                w = min(params.history_weight, n / (n + 1.0));
                if params.catmull_rom == 1u {
                    // Catmull-Rom over the 4×4 texels around q, where all show the same
                    // surface (a cubic's negative lobes cannot be renormalised over a
                    // partial set); its overshoot clamped at 0.
                    let wx = catmull_rom_weights(f.x);
                    let wy = catmull_rom_weights(f.y);
                    var cr = vec3<f32>(0.0);
                    var all = true;
                    for (var k = 0; k < 16; k++) {
                        let o = vec2<i32>(k & 3, k >> 2u);
                        let t = clamp(i + o - vec2<i32>(1), vec2<i32>(0), size - 1);
                        all = all && same_surface(textureLoad(stats_tex, t, 0).r, expected);
                        cr += wx[o.x] * wy[o.y] * textureLoad(history_tex, t, 0).rgb;
                    }
                    if all {
                        h = max(cr, vec3<f32>(0.0));
                    }
                }
            }
        }
    }
    // The frames this pixel's history holds with this one: 1 where it starts (the first frame,
    // a reset, a rejection).
    let youth = select(1.0, n + 1.0, w > 0.0);
    // The running moments of the input's frame-to-frame change (its largest channel),
    // restarted with the history; they steer the weight once ADAPT_AFTER frames are held.
    let xs = max(c.r, max(c.g, c.b));
    var m1 = 0.0;
    var m2 = 0.0;
    if w > 0.0 {
        let d = xs - hs.x;
        let a = min(MOMENT_WEIGHT, max(n - 1.0, 0.0) / n);
        m1 = d + a * (hs.y - d);
        m2 = d * d + a * (hs.z - d * d);
        if params.adaptive == 1u && n > ADAPT_AFTER {
            w = adapted_weight(w, m1, m2, a, xs);
        }
    }
    textureStore(stats_out, px, vec4<f32>(rdist, xs, m1, m2));
    // The current frame's 3×3 neighbourhood on the same surface (the pixels whose view distance
    // is within the tolerance of this one's, or sky with sky): its spread clips the history,
    // its mean stands in for a young history (temporal.rs TemporalSettings::young_frames).
    let young = youth < params.young_frames;
    var mean = c;
    if (w > 0.0 && params.clip == 1u) || young {
        var lo = c;
        var hi = c;
        var s1 = vec3<f32>(0.0);
        var s2 = vec3<f32>(0.0);
        var count = 0.0;
        for (var dy = -1; dy <= 1; dy++) {
            for (var dx = -1; dx <= 1; dx++) {
                let p = clamp(px + vec2<i32>(dx, dy), vec2<i32>(0), size - 1);
                if same_surface(current_distance(vec2<u32>(p)), dist) {
                    let s = textureLoad(current_tex, p, 0).rgb;
                    lo = min(lo, s);
                    hi = max(hi, s);
                    s1 += s;
                    s2 += s * s;
                    count += 1.0;
                }
            }
        }
        mean = s1 / count;
        if w > 0.0 && params.clip == 1u {
            // Variance clip (mean ± clip_sigma·σ), inside the neighbourhood's range.
            let sigma = sqrt(max(s2 / count - mean * mean, vec3<f32>(0.0)));
            let box_lo = max(lo, mean - params.clip_sigma * sigma);
            let box_hi = min(hi, mean + params.clip_sigma * sigma);
            h = clamp(h, box_lo, box_hi);
        }
    }
    // The running mean, kept as the history; shown through the neighbourhood's mean while young.
    let res = c + w * (h - c);
    var out = res;
    if young {
        var m = 1.0;
        if w > 0.0 {
            m = young_mean_weight(m2, youth, max(mean.r, max(mean.g, mean.b)) - max(res.r, max(res.g, res.b)), params.young_frames);
        }
        out = res + m * (mean - res);
    }
    textureStore(out_tex, px, vec4<f32>(out, cur.a));
    textureStore(history_out, px, vec4<f32>(res, min(n + 1.0, MAX_FRAMES)));
    textureStore(weight_out, px, vec4<f32>(w, 0.0, 0.0, 0.0));
}
