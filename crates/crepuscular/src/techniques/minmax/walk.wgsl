// minmax: the walk and its integration (cpu.rs ray_row, column_distance, Spans, Merge, shade):
// per view ray, its row and depth in the rectified map, the walk of Chen et al. 2011 §3.2 down
// the row's min-max tree, the exact in-scattering of its lit spans, and the standard-map lookups
// of its mixed texels. Shared by minmax's `traverse` pass and epipolar's min-max march; the pass
// declares `tree`, `shadow_map`, `spot_tex`, `frame` and `params`.

// cpu.rs MIXED: a texel whose bounds hold the ray's depth, resolved by `resolve_mixed`.
const MIXED: f32 = -1.0;
// No span (a shadowed node, or nothing pending).
const NO_SPAN: f32 = -2.0;

fn band_value(i: u32) -> f32 {
    return 0.0;
}

fn level_offset(width: u32, level: u32) -> u32 {
    return 2u * width - ((2u * width) >> level);
}

// cpu.rs ray_row.
fn ray_row(p: Params, row: f32) -> u32 {
    let h = i32(p.height);
    let r = i32(floor(row));
    if (p.flags & FLAG_FULL_CIRCLE) != 0u {
        return u32(((r % h) + h) % h);
    }
    return u32(clamp(r, 0, h - 1));
}

// cpu.rs column_distance.
fn column_distance(p: Params, dir: vec3<f32>, theta: f32, col: f32) -> f32 {
    if col <= 0.0 {
        return 0.0;
    }
    let c = line_of_column(p, col);
    if p.mode == RECT_PROJECTIVE {
        return c / max(dot(dir, p.axes[0].xyz), 1e-6);
    }
    if p.local == 0u {
        return c / max(sin(theta), 1e-6);
    }
    if theta + c >= PI - 1e-6 {
        return INF;
    }
    return p.light.w * sin(c) / max(sin(theta + c), 1e-9);
}

// cpu.rs Spans: the in-scattering of the lit spans of one ray.
struct Spans {
    dir: vec3<f32>,
    directional: bool,
    constant: vec3<f32>,
    segments: Steps,
    uni: Step,
    seg: u32,
    seg_light: vec3<f32>,
    sum: vec3<f32>,
}

fn spans_new(f: Frame, p: Params, dir: vec3<f32>, s: f32) -> Spans {
    var sp: Spans;
    sp.dir = dir;
    sp.sum = vec3<f32>(0.0);
    sp.seg = 0xffffffffu;
    let light = lights.items[0];
    sp.directional = light.kind == LIGHT_DIRECTIONAL;
    if sp.directional {
        let inc = light_incident(f, light, spot_tex, f.camera_pos.xyz);
        sp.constant = f.sigma_s.xyz * phase(f, dot(inc.dir, -dir)) * inc.radiance;
        return sp;
    }
    let o = f.camera_pos.xyz;
    let iv = march_interval(f, light, o, dir, s, p.spot_steps, p.epipole.w);
    sp.segments = own_steps(light, iv, p.light_steps, o, dir, p.spot_steps);
    sp.uni = uniform_step(sp.segments, extinction(f), 0.5);
    return sp;
}

fn segment_light(f: Frame, sp: ptr<function, Spans>, k: u32) -> vec3<f32> {
    if (*sp).seg == k {
        return (*sp).seg_light;
    }
    let step = march_step((*sp).segments, k, extinction(f), 0.5, (*sp).uni);
    let inc = light_incident(f, lights.items[0], spot_tex, f.camera_pos.xyz + (*sp).dir * (step.t0 + step.off));
    let l = f.sigma_s.xyz * phase(f, dot(inc.dir, -(*sp).dir)) * inc.radiance * step.scale;
    (*sp).seg = k;
    (*sp).seg_light = l;
    return l;
}

// model.rs ramp_transmittance: ∫₀^Δ q(t)·exp(−σt·t) dt for the quadratic q through
// v = (q(0), q(Δ/2), q(Δ)); J₁ and J₂ by their power series below x = 1, in closed form above.
fn ramp_moment(s: f32, delta: f32, c1: f32, c2: f32) -> f32 {
    let x = s * delta;
    var j1 = 0.0;
    var j2 = 0.0;
    if x < 1.0 {
        var term = 1.0;
        for (var m = 0u; m < 10u; m++) {
            j1 += term / (f32(m) + 2.0);
            j2 += term / (f32(m) + 3.0);
            term *= -x / (f32(m) + 1.0);
        }
    } else {
        let e = exp(-x);
        j1 = (1.0 - e * (1.0 + x)) / (x * x);
        j2 = (2.0 - e * (2.0 + x * (2.0 + x))) / (x * x * x);
    }
    return delta * (c1 * j1 + c2 * j2);
}

// model.rs ramp_coefficients: (c₁, c₂) of the quadratic through v = (q(0), q(½), q(1)).
fn ramp_coefficients(v: vec3<f32>) -> vec2<f32> {
    return vec2<f32>(4.0 * (v.y - v.x) - (v.z - v.x), 2.0 * (v.z - v.x) - 4.0 * (v.y - v.x));
}

fn ramp_transmittance(st: vec3<f32>, delta: f32, v: vec3<f32>) -> vec3<f32> {
    let coef = ramp_coefficients(v);
    let c1 = coef.x;
    let c2 = coef.y;
    let base = segment_transmittance(st, delta) * v.x;
    if c1 == 0.0 && c2 == 0.0 {
        return base;
    }
    return base + vec3<f32>(
        ramp_moment(st.x, delta, c1, c2),
        ramp_moment(st.y, delta, c1, c2),
        ramp_moment(st.z, delta, c1, c2),
    );
}

// cpu.rs Spans::add_ramp: the span [t0, t1] whose visibility is the quadratic through v (its
// values at t0, the middle and t1).
fn spans_add_ramp(f: Frame, p: Params, sp: ptr<function, Spans>, t0: f32, t1: f32, v: vec3<f32>) {
    let st = extinction(f);
    if (*sp).directional {
        if t1 > t0 {
            (*sp).sum += (*sp).constant * exp(-st * t0) * ramp_transmittance(st, t1 - t0, v);
        }
        return;
    }
    let segs = (*sp).segments;
    var a = max(t0, segs.iv.x);
    let b = min(t1, segs.iv.y);
    if !(b > a) || !(segs.delta > 0.0) {
        return;
    }
    let coef = ramp_coefficients(v);
    let c1 = coef.x;
    let c2 = coef.y;
    let constant = c1 == 0.0 && c2 == 0.0;
    let steps = segs.n;
    var k = step_index(segs, a);
    loop {
        if !(a < b) {
            break;
        }
        let end = min(b, step_boundary(segs, k + 1u));
        if end > a {
            let l = segment_light(f, sp, k);
            var va = v;
            if !constant {
                let r = (vec3<f32>(a, 0.5 * (a + end), end) - t0) / (t1 - t0);
                va = v.x + r * (c1 + r * c2);
            }
            (*sp).sum += l * exp(-st * a) * ramp_transmittance(st, end - a, va);
        }
        a = max(a, end);
        k += 1u;
        if k >= steps {
            break;
        }
    }
}

fn spans_add(f: Frame, p: Params, sp: ptr<function, Spans>, t0: f32, t1: f32, v: f32) {
    spans_add_ramp(f, p, sp, t0, t1, vec3<f32>(v));
}

// cpu.rs MAX_PIECES: the most texel-edge steps per mixed texel of a run.
const MAX_PIECES: u32 = 64u;

// cpu.rs root: the t at which a + b·t = 0.
fn root(a: f32, b: f32) -> f32 {
    if b != 0.0 {
        return -a / b;
    }
    return INF;
}

struct Breaks {
    t: array<f32, 9>,
    n: u32,
}

fn push_break(br: ptr<function, Breaks>, t: f32, t0: f32, t1: f32) {
    if t > t0 && t < t1 {
        (*br).t[(*br).n] = t;
        (*br).n += 1u;
    }
}

// cpu.rs span_breaks.
fn span_breaks(l: Light, o: vec3<f32>, dir: vec3<f32>, t0: f32, t1: f32) -> Breaks {
    var br: Breaks;
    br.n = 0u;
    if l.shadow_layers == 1u {
        let m = light_view_proj(l, 0u);
        let c = m * vec4<f32>(o, 1.0);
        let d = m * vec4<f32>(dir, 0.0);
        push_break(&br, root(c.w, d.w), t0, t1);
        push_break(&br, root(c.z, d.z), t0, t1);
        push_break(&br, root(c.z - c.w, d.z - d.w), t0, t1);
    } else {
        let q = o - l.position.xyz;
        push_break(&br, root(q.x - q.y, dir.x - dir.y), t0, t1);
        push_break(&br, root(q.x + q.y, dir.x + dir.y), t0, t1);
        push_break(&br, root(q.x - q.z, dir.x - dir.z), t0, t1);
        push_break(&br, root(q.x + q.z, dir.x + dir.z), t0, t1);
        push_break(&br, root(q.y - q.z, dir.y - dir.z), t0, t1);
        push_break(&br, root(q.y + q.z, dir.y + dir.z), t0, t1);
    }
    for (var i = 1u; i < br.n; i++) {
        var k = i;
        while k > 0u && br.t[k - 1u] > br.t[k] {
            let x = br.t[k];
            br.t[k] = br.t[k - 1u];
            br.t[k - 1u] = x;
            k -= 1u;
        }
    }
    return br;
}

// cpu.rs resolve_mixed's `lit_part`: the lit part of [a, b] at texel `texel` on face `layer`
// (clip line c + t·d).
fn lit_part(l: Light, texel: vec2<u32>, a: f32, b: f32, layer: u32, c: vec4<f32>, d: vec4<f32>) -> vec2<f32> {
    // An empty texel lights the whole piece, beyond the far plane too (shadow_coord_clip).
    let raw = textureLoad(shadow_map, vec2<i32>(texel), i32(l.shadow_first_layer + layer), 0).r;
    if (l.shadow_clear == 1.0 && raw >= 1.0) || (l.shadow_clear == 0.0 && raw <= 0.0) {
        return vec2<f32>(a, b);
    }
    let limit = shadow_linear_depth(l, raw) + l.shadow_bias;
    let qa = c + d * a;
    let qb = c + d * b;
    let da = shadow_linear_depth(l, qa.z / qa.w);
    let db = shadow_linear_depth(l, qb.z / qb.w);
    let lit_a = da <= limit;
    let lit_b = db <= limit;
    if lit_a && lit_b {
        return vec2<f32>(a, b);
    } else if lit_a || lit_b {
        let t = clamp(a + (b - a) * (limit - da) / (db - da), a, b);
        if lit_a {
            return vec2<f32>(a, t);
        }
        return vec2<f32>(t, b);
    }
    return vec2<f32>(b, b);
}

// cpu.rs next_edge: the next texel edge after u in direction s along one axis (nearest: the
// texel edges; bilinear: the lines between texel centres and the map's own edges).
fn next_edge(u: f32, s: f32, size: f32, bilinear: bool) -> f32 {
    if s > 0.0 {
        if !bilinear {
            return max(floor(u) + 1.0, 0.0);
        }
        if u < 0.0 {
            return 0.0;
        }
        let e = floor(u - 0.5) + 1.5;
        if e > size && u < size {
            return size;
        }
        return e;
    }
    if !bilinear {
        return min(ceil(u) - 1.0, size);
    }
    if u > size {
        return size;
    }
    let e = ceil(u - 0.5) - 0.5;
    if e < 0.0 && u > 0.0 {
        return 0.0;
    }
    return e;
}

// cpu.rs texel coordinates (X, Y) = n·(x/w·½ + ½, ½ − y/w·½) of the clip line c + t·d.
fn line_texel(c: vec4<f32>, d: vec4<f32>, t: f32, size: f32) -> vec2<f32> {
    let q = c + d * t;
    return vec2<f32>(size * (q.x / q.w * 0.5 + 0.5), size * (0.5 - q.y / q.w * 0.5));
}

// cpu.rs LitRun: the pending lit span (x, y) of resolve_mixed; a lit part (a, b) that starts
// where it ends extends it, any other is integrated.
fn lit_run_add(f: Frame, p: Params, sp: ptr<function, Spans>, run: ptr<function, vec2<f32>>, a: f32, b: f32) {
    if !(b > a) {
        return;
    }
    if a == (*run).y && (*run).y > (*run).x {
        (*run).y = b;
        return;
    }
    if (*run).y > (*run).x {
        spans_add(f, p, sp, (*run).x, (*run).y, 1.0);
    }
    *run = vec2<f32>(a, b);
}

// 1 where the lit part `lit` (x, y) holds t, else 0.
fn lit_at(lit: vec2<f32>, t: f32) -> f32 {
    return select(0.0, 1.0, lit.y > lit.x && lit.x <= t && t <= lit.y);
}

// cpu.rs resolve_mixed's `weights`: the bilinear weights of x1 and y1 at t, from the piece's
// fixed footprint corner, clamped to [0, 1].
fn piece_weights(c: vec4<f32>, d: vec4<f32>, t: f32, size: f32, corner: vec2<f32>) -> vec2<f32> {
    return clamp(line_texel(c, d, t, size) - 0.5 - corner, vec2<f32>(0.0), vec2<f32>(1.0));
}

// cpu.rs resolve_mixed's `piece`: the lit parts of [p0, p1], its texels fixed (those at its
// midpoint), into `run` and `sp`; under the bilinear filter the four texels' lit parts cut it
// further and each part adds the bilinear blend of the texels lit there as a quadratic ramp.
fn resolve_piece(f: Frame, p: Params, sp: ptr<function, Spans>, run: ptr<function, vec2<f32>>, p0: f32, p1: f32, layer: u32, c: vec4<f32>, d: vec4<f32>) {
    let l = lights.items[0];
    let sc = shadow_coord_clip(l, layer, c + d * (0.5 * (p0 + p1)));
    if !sc.valid {
        lit_run_add(f, p, sp, run, p0, p1);
        return;
    }
    if l.shadow_filter != SHADOW_FILTER_BILINEAR {
        let lit = lit_part(l, sc.texel, p0, p1, layer, c, d);
        lit_run_add(f, p, sp, run, lit.x, lit.y);
        return;
    }
    let size = f32(l.shadow_size);
    let fp = bilinear_footprint(sc.uv, l.shadow_size);
    let q = fp.corner;
    let corner = floor(sc.uv * size - 0.5);
    var lit: array<vec2<f32>, 4>;
    lit[0] = lit_part(l, q.xy, p0, p1, layer, c, d);
    lit[1] = lit_part(l, q.zy, p0, p1, layer, c, d);
    lit[2] = lit_part(l, q.xw, p0, p1, layer, c, d);
    lit[3] = lit_part(l, q.zw, p0, p1, layer, c, d);
    // Most pieces of a mixed texel are lit or shadowed by all four texels throughout.
    var whole = 0u;
    var none = 0u;
    for (var i = 0u; i < 4u; i++) {
        whole += u32(lit[i].x == p0 && lit[i].y == p1);
        none += u32(!(lit[i].y > lit[i].x));
    }
    if whole == 4u {
        lit_run_add(f, p, sp, run, p0, p1);
        return;
    }
    if none == 4u {
        return;
    }
    // Each lit part starts at p0 or ends at p1 (lit_part), so it has at most one end inside
    // the piece: four cuts (p1 where a part has none), sorted by a network of five
    // compare-exchanges.
    var k = vec4<f32>(inner_end(lit[0], p0, p1), inner_end(lit[1], p0, p1), inner_end(lit[2], p0, p1), inner_end(lit[3], p0, p1));
    k = vec4<f32>(min(k.x, k.y), max(k.x, k.y), min(k.z, k.w), max(k.z, k.w));
    k = vec4<f32>(min(k.x, k.z), min(k.y, k.w), max(k.x, k.z), max(k.y, k.w));
    k = vec4<f32>(k.x, min(k.y, k.z), max(k.y, k.z), k.w);
    resolve_part(f, p, sp, run, p0, k.x, lit, corner, c, d, size);
    resolve_part(f, p, sp, run, k.x, k.y, lit, corner, c, d, size);
    resolve_part(f, p, sp, run, k.y, k.z, lit, corner, c, d, size);
    resolve_part(f, p, sp, run, k.z, k.w, lit, corner, c, d, size);
    resolve_part(f, p, sp, run, k.w, p1, lit, corner, c, d, size);
}

// cpu.rs resolve_mixed's `inner_end`: the end of lit part `lit` strictly inside (p0, p1), or p1.
fn inner_end(lit: vec2<f32>, p0: f32, p1: f32) -> f32 {
    if lit.y > lit.x && lit.x > p0 {
        return lit.x;
    }
    if lit.y > lit.x && lit.y < p1 {
        return lit.y;
    }
    return p1;
}

// One part [s0, s1] of a piece under the bilinear filter, its lit texels fixed: lit by all
// four, by none, or the blend of those lit as a quadratic ramp.
fn resolve_part(f: Frame, p: Params, sp: ptr<function, Spans>, run: ptr<function, vec2<f32>>, s0: f32, s1: f32, lit: array<vec2<f32>, 4>, corner: vec2<f32>, c: vec4<f32>, d: vec4<f32>, size: f32) {
    if !(s1 > s0) {
        return;
    }
    let sm = 0.5 * (s0 + s1);
    let m = vec4<f32>(lit_at(lit[0], sm), lit_at(lit[1], sm), lit_at(lit[2], sm), lit_at(lit[3], sm));
    if all(m == vec4<f32>(1.0)) {
        lit_run_add(f, p, sp, run, s0, s1);
    } else if any(m != vec4<f32>(0.0)) {
        // The bilinear blend of the lit texels' tests (shadow_visibility), at s0, sm, s1.
        let v = vec3<f32>(
            bilinear_blend(m, piece_weights(c, d, s0, size, corner)),
            bilinear_blend(m, piece_weights(c, d, sm, size, corner)),
            bilinear_blend(m, piece_weights(c, d, s1, size, corner)),
        );
        spans_add_ramp(f, p, sp, s0, s1, v);
    }
}

// cpu.rs resolve_mixed: the exact visibility of a mixed texel's span [t0, t1] against the
// standard shadow map, piece by piece between texel edges; at most MAX_PIECES edge steps per
// texel of the run (`texels`).
fn resolve_mixed(f: Frame, p: Params, sp: ptr<function, Spans>, t0: f32, t1: f32, texels: u32) {
    if !(t1 > t0) {
        return;
    }
    let l = lights.items[0];
    let o = f.camera_pos.xyz;
    let dir = (*sp).dir;
    let size = f32(l.shadow_size);
    let bilinear = l.shadow_filter == SHADOW_FILTER_BILINEAR;
    let br = span_breaks(l, o, dir, t0, t1);
    let max_steps = MAX_PIECES * max(texels, 1u);
    var steps = 0u;
    // Lit parts that touch are integrated as one span: fewer exponentials, the same integral.
    var run = vec2<f32>(0.0, 0.0);
    var a = t0;
    for (var k = 0u; k <= br.n; k++) {
        var b = t1;
        if k < br.n {
            b = br.t[k];
        }
        if !(b > a) {
            continue;
        }
        let tm = 0.5 * (a + b);
        var layer = 0u;
        if l.shadow_layers == CUBE_LAYERS {
            layer = cube_face(o + dir * tm - l.position.xyz);
        }
        let m = light_view_proj(l, layer);
        let c = m * vec4<f32>(o, 1.0);
        let d = m * vec4<f32>(dir, 0.0);
        if (c + d * tm).w <= 0.0 {
            lit_run_add(f, p, sp, &run, a, b);
            a = b;
            continue;
        }
        let pa = line_texel(c, d, a, size);
        let pb = line_texel(c, d, b, size);
        // Only the edges 0..=n matter: outside the map every point is lit.
        let sx = select(-1.0, 1.0, pb.x > pa.x);
        let sy = select(-1.0, 1.0, pb.y > pa.y);
        var kx = next_edge(pa.x, sx, size, bilinear);
        var ky = next_edge(pa.y, sy, size, bilinear);
        var t = a;
        loop {
            var tx = INF;
            if !((sx > 0.0 && (kx >= pb.x || kx > size)) || (sx < 0.0 && (kx <= pb.x || kx < 0.0))) {
                let kk = 2.0 * kx / size - 1.0;
                tx = root(c.x - kk * c.w, d.x - kk * d.w);
            }
            var ty = INF;
            if !((sy > 0.0 && (ky >= pb.y || ky > size)) || (sy < 0.0 && (ky <= pb.y || ky < 0.0))) {
                let kk = 1.0 - 2.0 * ky / size;
                ty = root(c.y - kk * c.w, d.y - kk * d.w);
            }
            var e = min(min(tx, ty), b);
            if !(e > t) {
                e = t;
            }
            steps += 1u;
            if steps >= max_steps {
                e = b;
            }
            if e > t {
                resolve_piece(f, p, sp, &run, t, e, layer, c, d);
                t = e;
            }
            if t >= b {
                break;
            }
            if tx <= ty {
                kx = next_edge(kx, sx, size, bilinear);
            } else {
                ky = next_edge(ky, sy, size, bilinear);
            }
        }
        a = b;
    }
    if run.y > run.x {
        spans_add(f, p, sp, run.x, run.y, 1.0);
    }
}

struct Walk {
    nodes: u32,
    lit: u32,
    shadowed: u32,
    over_budget: u32,
    mixed: u32,
}

struct Shaded {
    l: vec3<f32>,
    walk: Walk,
}

// cpu.rs shade's `integrate`: a finished span (c0, c1, v) of columns, as distances along the ray
// (the last one ends at the surface, s), into `sp`.
fn flush(f: Frame, p: Params, sp: ptr<function, Spans>, span: vec3<f32>, theta: f32, c_b: f32, s: f32) {
    if span.z == NO_SPAN {
        return;
    }
    let t0 = min(column_distance(p, (*sp).dir, theta, span.x), s);
    var t1 = s;
    if span.y < c_b {
        t1 = min(column_distance(p, (*sp).dir, theta, span.y), s);
    }
    if span.z == MIXED {
        // A run of level-0 texels: whole columns, the last one cut at c_b.
        let texels = u32(max(ceil(span.y) - floor(span.x), 1.0));
        resolve_mixed(f, p, sp, t0, t1, texels);
    } else {
        spans_add(f, p, sp, t0, t1, span.z);
    }
}

// cpu.rs shade and walk, with cpu.rs Merge as the pending span (c0, c1, v).
fn shade(f: Frame, p: Params, dir: vec3<f32>, s: f32) -> Shaded {
    let rp = rectify_point(p, f.camera_pos.xyz + dir * s, dir);
    var theta = 0.0;
    if p.mode == RECT_EPIPOLAR {
        theta = angle_between(dir, p.axes[2].xyz);
    }
    let c_b = rp.col;
    let z = rp.z;
    var sp = spans_new(f, p, dir, s);
    var w: Walk;
    let width = p.width;
    let levels = p.tree_levels;
    let max_nodes = p.max_nodes;
    let base = ray_row(p, rp.row) * 2u * width;
    var pending = vec3<f32>(0.0, 0.0, NO_SPAN);
    var level = 0u;
    var i = 0u;
    while level < levels && i % 2u == 0u {
        i /= 2u;
        level += 1u;
    }
    loop {
        let start = i << level;
        if start >= width || f32(start) >= c_b {
            break;
        }
        let coarse = w.nodes >= max_nodes;
        if coarse {
            w.over_budget = 1u;
        }
        w.nodes += 1u;
        let node = tree[base + level_offset(width, level) + i];
        let c0 = f32(start);
        let c1 = min(f32((i + 1u) << level), c_b);
        var v = NO_SPAN;
        if z <= node.x {
            w.lit += 1u;
            v = 1.0;
        } else if z > node.y {
            w.shadowed += 1u;
        } else if coarse {
            v = 0.5;
        } else if level == 0u {
            w.mixed += 1u;
            v = MIXED;
        } else {
            level -= 1u;
            i *= 2u;
            continue;
        }
        if v != NO_SPAN {
            if pending.z == v && pending.y == c0 {
                pending.y = c1;
            } else {
                flush(f, p, &sp, pending, theta, c_b, s);
                pending = vec3<f32>(c0, c1, v);
            }
        }
        i += 1u;
        while level < levels && i % 2u == 0u {
            i /= 2u;
            level += 1u;
        }
    }
    flush(f, p, &sp, pending, theta, c_b, s);
    var out: Shaded;
    out.l = sp.sum;
    out.walk = w;
    return out;
}

