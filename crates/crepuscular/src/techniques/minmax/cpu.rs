//! CPU mirror of `minmax`: the same arithmetic (f32) as build.wgsl and traverse.wgsl, function
//! for function. Each pass is public so a test can compare it with its GPU twin, and
//! [`linear_scan`] is the texel-by-texel walk the tree must reproduce.

use super::settings::MinmaxSettings;
use crate::error::Error;
use crate::frame::{CpuFrame, FrameDesc};
use crate::image::Image;
use crate::integrand::{light_incident, light_position};
use crate::march::{Step, Steps, light_reach, local_position, march_interval};
use crate::model::{ramp_coefficients, ramp_transmittance};
use crate::shadow::{ShadowFilter, ShadowMap, bilinear_blend, bilinear_footprint, cube_face};
use crate::stats::{PassTime, TechniqueStats};
use crate::techniques::prefiltered::cpu::{in_epipole_disc, march_epipole, texel_depth};
use crate::techniques::prefiltered::rectify::{Mode, Rectification, angle_between};
use crate::techniques::prefiltered::{epipole_pixel, epipole_samples};
use glam::{Vec2, Vec3, Vec4};
use rayon::prelude::*;
use std::f32::consts::PI;

/// The offset of level `level` in a row of the tree (`2·width` entries per row): level k holds
/// width/2^k nodes and starts after the levels below it, at 2·width − 2·width/2^k. Mirrors
/// `level_offset` in build.wgsl.
pub fn level_offset(width: u32, level: u32) -> usize {
    (2 * width - ((2 * width) >> level)) as usize
}

/// Bounds of a rectified texel whose footprint in the standard shadow map is not bounded (wider
/// than [`MAX_FOOTPRINT`] texels, behind a spot's plane, or across a cube face's edge): below
/// every ray's depth and above it, so the texel is mixed for every ray and its spans look the
/// standard map up (exact, only slower).
pub const UNBOUNDED: [f32; 2] = [-1.0, 2.0];

/// The most standard-map texels one rectified texel's bounds read (a cost bound on `build`): a
/// bounding box of up to 4096 texels, 64×64. A rectified map much coarser than the standard one,
/// or a texel near the camera whose light lines spread apart, covers more; such a texel is
/// [`UNBOUNDED`]. Measured on llvmpipe at 480×270 (docs/RESULTS.md, Fig. 5): at 64 (8×8) most
/// texels of a 256²–1024² map were unbounded and their spans resolved one standard texel at a
/// time — terrain's 1024² map cost 3.7 s a frame; at 4096, 1.1 s, its build 0.5 s.
pub const MAX_FOOTPRINT: u32 = 4096;

/// The visibility `walk` emits for a mixed texel within the node budget: not a visibility, a
/// request to resolve the span against the standard shadow map ([`resolve_mixed`]).
pub const MIXED: f32 = -1.0;

/// Level 0 of the tree where the rectified map resamples the standard shadow map (the issue's
/// "conservative level 0"): bounds on the normalised depth of the occluders of every light line
/// through rectified texel (`col`, `row`). The texel's patch of light lines (columns
/// [col, col + 1], rows [row, row + 1]) is sampled at its corners, edge midpoints and centre;
/// each line projects to one point of the shadow map (a directional light's line in its
/// orthographic map, a ray from a local light in its perspective one). Every standard texel in
/// the bounding box of those nine points is read: the nearest and farthest occluder depths
/// (light space; the clear value, or a footprint partly outside the map, adds "no occluder",
/// 1). Along any light line the rectified depth grows with the light depth, so the bounds are
/// the least rectified depth of the nearest occluder and the greatest of the farthest over the
/// nine lines. A ray whose depth is at most the minimum is lit at every standard texel it
/// crosses inside the texel, one above the maximum shadowed at every one — up to the
/// curvature of the rectified depth across one texel between the nine lines (docs/MODEL.md
/// §8). Under the bilinear `filter` a point reads the 2×2 texels around it, so the box grows
/// by one texel's reach (the texels from ⌊lo − ½⌋ to ⌊hi − ½⌋ + 1). Mirrors `texel_bounds` in
/// bounds.wgsl.
pub fn texel_bounds(
    rect: &Rectification,
    shadow: &ShadowMap,
    light_pos: Vec3,
    bias: f32,
    filter: ShadowFilter,
    col: u32,
    row: u32,
) -> [f32; 2] {
    let pr = &shadow.projection;
    let (_, centre) = rect.texel_line(col as f32 + 0.5, row as f32 + 0.5);
    let layer = if pr.layers == 6 { cube_face(centre) } else { 0 };
    let m = pr.view_proj[layer as usize];
    let n = pr.size as f32;
    let (mut lo, mut hi) = (Vec2::splat(f32::MAX), Vec2::splat(f32::MIN));
    // The nine lines: column coordinate, point, direction, clip position of the point the map
    // projects (the line point itself in an orthographic map, a unit step from a local light).
    let mut lines = [(0.0f32, Vec3::ZERO, Vec3::ZERO, Vec4::ZERO); 9];
    for (k, line) in lines.iter_mut().enumerate() {
        let c = col as f32 + 0.5 * (k % 3) as f32;
        let (p, dir) = rect.texel_line(c, row as f32 + 0.5 * (k / 3) as f32);
        let layer_k = if pr.layers == 6 { cube_face(dir) } else { 0 };
        let q = m * (if pr.orthographic { p } else { light_pos + dir }).extend(1.0);
        if q.w <= 0.0 || layer_k != layer {
            return UNBOUNDED;
        }
        let uv = Vec2::new((q.x / q.w * 0.5 + 0.5) * n, (0.5 - q.y / q.w * 0.5) * n);
        lo = lo.min(uv);
        hi = hi.max(uv);
        *line = (c, p, dir, q);
    }
    // The occluder depths (light space) of the footprint, and whether some line has none.
    let (mut near, mut far) = (f32::MAX, f32::MIN);
    let mut open = lo.x < 0.0 || lo.y < 0.0 || hi.x > n || hi.y > n;
    if !(hi.x < 0.0 || hi.y < 0.0 || lo.x >= n || lo.y >= n) {
        // The texels a lookup inside the box can read: the one it falls in (nearest), or the
        // 2×2 around it (bilinear).
        let (reach, extra) = if filter == ShadowFilter::Bilinear { (0.5, 1.0) } else { (0.0, 0.0) };
        let [x0, y0] = [lo.x, lo.y].map(|v| (v - reach).floor().clamp(0.0, n - 1.0) as u32);
        let [x1, y1] = [hi.x, hi.y].map(|v| ((v - reach).floor() + extra).clamp(0.0, n - 1.0) as u32);
        if (x1 - x0 + 1) * (y1 - y0 + 1) > MAX_FOOTPRINT {
            return UNBOUNDED;
        }
        for y in y0..=y1 {
            for x in x0..=x1 {
                let d = shadow.texel(layer, x, y);
                if pr.is_empty(d) {
                    open = true;
                } else {
                    let stored = pr.linear(d);
                    near = near.min(stored);
                    far = far.max(stored);
                }
            }
        }
    }
    let mut bounds = [f32::MAX, f32::MIN];
    if open {
        bounds = [1.0, 1.0];
    }
    if near <= far {
        // The rectified depth of the occluder at light depth `stored` on line (c, p, dir, q).
        let depth = |(c, p, dir, q): (f32, Vec3, Vec3, Vec4), stored: f32| {
            let o = if pr.orthographic {
                p + dir * (stored - pr.linear(q.z / q.w))
            } else {
                light_pos + dir * (stored / q.w)
            };
            rect.occluder_depth(c, o + dir * bias)
        };
        for line in lines {
            bounds = [bounds[0].min(depth(line, near)), bounds[1].max(depth(line, far))];
        }
    }
    bounds
}

/// Pass `build` (Chen et al. 2011 §3.1, "1D min-max mipmap"): per row of the rectified map,
/// level 0 the host's rasterized depths (`host_depth`, with the volume bias, as `prefiltered`
/// adds it; min = max) or, where the map resamples the standard shadow map, the conservative
/// [`texel_bounds`] of each texel; each of the `levels` coarser levels the (min, max) of two
/// children. `2·width` (min, max) pairs per row, row-major. Mirrors build.wgsl.
pub fn build(frame: &CpuFrame, rect: &Rectification, host_depth: Option<&[f32]>, levels: u32) -> Vec<[f32; 2]> {
    let w = rect.width as usize;
    let fl = &frame.desc.lights[0];
    match host_depth {
        Some(depth) => build_rows(rect.width, rect.height, levels, |row, c| {
            let d = texel_depth(rect, depth[row * w + c], c as u32, Some(fl.shadow_bias));
            [d, d]
        }),
        None => {
            let (shadow, light_pos) = (&frame.shadow_maps[0], light_position(&fl.light));
            build_rows(rect.width, rect.height, levels, |row, c| {
                texel_bounds(rect, shadow, light_pos, fl.shadow_bias, fl.shadow_filter, c as u32, row as u32)
            })
        }
    }
}

/// [`build`] from the level-0 (min, max) of each (row, column).
pub fn build_rows(
    width: u32,
    height: u32,
    levels: u32,
    texel: impl Fn(usize, usize) -> [f32; 2] + Sync,
) -> Vec<[f32; 2]> {
    let w = width as usize;
    let mut tree = vec![[0.0f32; 2]; 2 * w * height as usize];
    tree.par_chunks_mut(2 * w).enumerate().for_each(|(row, nodes)| {
        for c in 0..w {
            nodes[c] = texel(row, c);
        }
        for l in 1..=levels {
            let (below, at) = (level_offset(width, l - 1), level_offset(width, l));
            for i in 0..(w >> l) {
                let (a, b) = (nodes[below + 2 * i], nodes[below + 2 * i + 1]);
                nodes[at + i] = [a[0].min(b[0]), a[1].max(b[1])];
            }
        }
    });
    tree
}

/// What one view ray's walk did (the technique's stats add them up).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Walk {
    /// Tree nodes visited.
    pub nodes: u32,
    /// Nodes found entirely lit (their span integrated).
    pub lit: u32,
    /// Nodes found entirely shadowed (their span skipped).
    pub shadowed: u32,
    /// 1 when the ray reached `max_nodes` and the rest of its row was not refined.
    pub over_budget: u32,
    /// Mixed texels (level 0, within the budget) whose span was resolved against the standard
    /// shadow map ([`resolve_mixed`]).
    pub mixed: u32,
}

/// The view ray's row (the nearest; wrapped when the slices cover the full circle). Mirrors
/// `ray_row` in traverse.wgsl.
pub fn ray_row(rect: &Rectification, row: f32) -> u32 {
    let h = rect.height as i32;
    let r = row.floor() as i32;
    if rect.full_circle { r.rem_euclid(h) as u32 } else { r.clamp(0, h - 1) as u32 }
}

/// The walk of Chen et al. 2011 (§3.2) along row `row` of `tree` (`levels` at most log2 of the
/// power-of-two `width`; more are clamped) for a ray of normalised depth
/// `z` over the column interval [`c_a`, `c_b`]: a node whose minimum is at least `z` is lit over
/// its whole span, one whose maximum is below `z` is shadowed, any other is descended into
/// down to the texels. After a span the walk moves to the next node and climbs while that node is
/// a left child (the parent starts where it does), so a ray visits O(log width) nodes per change
/// of visibility. `emit(c0, c1, v)` receives each non-shadowed span clipped to [c_a, c_b], in
/// order, with its visibility v: 1; ½ for a mixed node left unrefined once `max_nodes` is
/// reached; [`MIXED`] for a texel whose bounds (conservative, [`texel_bounds`]) hold the ray's
/// depth, which the caller resolves against the standard map. Mirrors `shade` in walk.wgsl.
#[allow(clippy::too_many_arguments)]
pub fn walk(
    tree: &[[f32; 2]],
    width: u32,
    levels: u32,
    max_nodes: u32,
    row: u32,
    z: f32,
    c_a: f32,
    c_b: f32,
    mut emit: impl FnMut(f32, f32, f32),
) -> Walk {
    let mut out = Walk::default();
    if width == 0 {
        return out;
    }
    // A tree has at most log2(width) levels above the texels.
    let levels = levels.min(width.trailing_zeros());
    let base = row as usize * 2 * width as usize;
    let mut level = 0u32;
    let mut i = (c_a.max(0.0) as u32).min(width - 1);
    while level < levels && i % 2 == 0 {
        i /= 2;
        level += 1;
    }
    loop {
        let start = i << level;
        if start >= width || start as f32 >= c_b {
            break;
        }
        let coarse = out.nodes >= max_nodes;
        out.over_budget |= coarse as u32;
        out.nodes += 1;
        let [lo, hi] = tree[base + level_offset(width, level) + i as usize];
        let c0 = (start as f32).max(c_a);
        let c1 = (((i + 1) << level) as f32).min(c_b);
        if z <= lo {
            out.lit += 1;
            emit(c0, c1, 1.0);
        } else if z > hi {
            out.shadowed += 1;
        } else if coarse {
            emit(c0, c1, 0.5);
        } else if level == 0 {
            out.mixed += 1;
            emit(c0, c1, MIXED);
        } else {
            level -= 1;
            i *= 2;
            continue;
        }
        i += 1;
        while level < levels && i % 2 == 0 {
            i /= 2;
            level += 1;
        }
    }
    out
}

/// The texel-by-texel walk (no tree): every column of a row of `width` texels the ray crosses,
/// lit where the texel's depth (`texel(column)`) is at least the ray's. What [`walk`] must
/// reproduce span for span (tests).
pub fn linear_scan(
    width: u32,
    texel: impl Fn(u32) -> f32,
    z: f32,
    c_a: f32,
    c_b: f32,
    mut emit: impl FnMut(f32, f32, f32),
) {
    let mut c = (c_a.max(0.0) as u32).min(width.saturating_sub(1));
    while c < width && (c as f32) < c_b {
        if z <= texel(c) {
            emit((c as f32).max(c_a), ((c + 1) as f32).min(c_b), 1.0);
        }
        c += 1;
    }
}

/// The distance along the view ray of unit direction `dir` (at angle `theta` to the axis in the
/// epipolar map) at which it crosses the boundary of column coordinate `col`: 0 at column 0
/// (the camera's texel reaches back to it), infinite where it never does (a local light's line
/// behind the ray). Projective: x = t·(dir·x̂); epipolar, directional: the distance from the axis
/// is t·sin θ; epipolar, local: the angle ψ at the light, t = D·sin ψ / sin(θ + ψ) (law of
/// sines in the camera–light–point triangle). Mirrors `column_distance` in traverse.wgsl.
pub fn column_distance(rect: &Rectification, dir: Vec3, theta: f32, col: f32) -> f32 {
    if col <= 0.0 {
        return 0.0;
    }
    let c = rect.line_of_column(col);
    match rect.mode {
        Mode::Projective => c / dir.dot(rect.axes[0]).max(1e-6),
        Mode::Epipolar if !rect.local => c / theta.sin().max(1e-6),
        Mode::Epipolar => {
            if theta + c >= PI - 1e-6 {
                return f32::INFINITY;
            }
            rect.light_distance * c.sin() / (theta + c).sin().max(1e-9)
        }
    }
}

/// The in-scattering of the lit spans of one view ray, accumulated span by span in order.
/// Directional light: σs·p·E·e^(−σt·t₀)·(1 − e^(−σt·(t₁ − t₀)))/σt per span, exact (the phase
/// and E are constant along the ray; docs/MODEL.md §8). Spot and point: the ray's lit interval
/// ([`march_interval`]) cut into `light_steps` segments; each segment's light, cone, texture
/// and phase are evaluated once, at its transmittance-weighted midpoint (with the segment's
/// [`Step::scale`]), and multiply the exact transmittance integral of each lit piece of it. The segments are `brute-force`'s steps
/// ([`Steps::of_light`]: equiangular under the default `local_steps`). Mirrors `Spans` in
/// walk.wgsl.
pub struct Spans<'a> {
    desc: &'a FrameDesc,
    dir: Vec3,
    st: Vec3,
    /// Directional: σs·p·E. Local: unused.
    constant: Option<Vec3>,
    /// Local: the segments of the lit interval, and what a uniform one shares.
    segments: Steps,
    uni: Step,
    /// The segment whose light is cached, and that light.
    seg: Option<(u32, Vec3)>,
    /// The in-scattering so far.
    pub sum: Vec3,
}

impl<'a> Spans<'a> {
    /// The accumulator of the view ray of unit direction `dir` that ends at distance `s`.
    pub fn new(desc: &'a FrameDesc, settings: &MinmaxSettings, dir: Vec3, s: f32) -> Self {
        let st = desc.medium.extinction();
        let fl = &desc.lights[0];
        let mut out = Spans {
            desc,
            dir,
            st,
            constant: None,
            segments: Steps::uniform((0.0, 0.0), settings.light_steps),
            uni: Step { t0: 0.0, off: 0.0, seg: Vec3::ZERO, scale: 1.0 },
            seg: None,
            sum: Vec3::ZERO,
        };
        if matches!(fl.light, crate::Light::Directional { .. }) {
            let (l_in, wl) = light_incident(fl, &desc.medium, desc.camera.position);
            out.constant = Some(desc.medium.scattering * desc.medium.phase.eval(wl.dot(-dir)) * l_in);
            return out;
        }
        let cone = crate::march::SpotCone::of(&fl.light);
        let (o, policy) = (desc.camera.position, settings.policy);
        let iv = march_interval(cone.as_ref(), light_reach(fl, &desc.medium), o, dir, s, policy);
        out.segments = Steps::of_light(local_position(&fl.light), iv, settings.light_steps, o, dir, policy);
        out.uni = out.segments.uniform_step(st, 0.5);
        out
    }

    /// Adds the span [t0, t1] (distances along the ray) with visibility `v`.
    pub fn add(&mut self, t0: f32, t1: f32, v: f32) {
        self.add_ramp(t0, t1, [v; 3]);
    }

    /// Adds the span [t0, t1] whose visibility is the quadratic in t through `v` = its values
    /// at t0, the middle and t1 (a mixed texel under the bilinear filter, [`resolve_mixed`]),
    /// integrated against the transmittance exactly ([`ramp_transmittance`]).
    pub fn add_ramp(&mut self, t0: f32, t1: f32, v: [f32; 3]) {
        if let Some(c) = self.constant {
            if t1 > t0 {
                self.sum += c * (-self.st * t0).exp() * ramp_transmittance(self.st, t1 - t0, v);
            }
            return;
        }
        let (iv, n) = (self.segments.iv, self.segments.n);
        let (mut a, b) = (t0.max(iv.0), t1.min(iv.1));
        if !(b > a) || !(self.segments.delta > 0.0) {
            return;
        }
        // The quadratic at t, from its three values over [t0, t1].
        let [v0, ..] = v;
        let (c1, c2) = ramp_coefficients(v);
        let q = |t: f32| {
            let r = (t - t0) / (t1 - t0);
            v0 + r * (c1 + r * c2)
        };
        let constant = c1 == 0.0 && c2 == 0.0;
        let mut k = self.segments.index_of(a);
        while a < b {
            let end = b.min(self.segments.boundary(k + 1));
            if end > a {
                let f = self.segment_light(k);
                let va = if constant { v } else { [q(a), q(0.5 * (a + end)), q(end)] };
                self.sum += f * (-self.st * a).exp() * ramp_transmittance(self.st, end - a, va);
            }
            a = a.max(end);
            k += 1;
            if k >= n {
                break;
            }
        }
    }

    /// σs·p·L_in of segment `k` at its sample point, times the segment's [`Step::scale`] (1 for
    /// uniform segments; for equiangular ones the 1/d² falloff averaged over the segment instead
    /// of taken at the sample, docs/MODEL.md §9), cached while the walk stays in it.
    fn segment_light(&mut self, k: u32) -> Vec3 {
        if let Some((sk, f)) = self.seg
            && sk == k
        {
            return f;
        }
        let step = self.segments.step(k, self.st, 0.5, &self.uni);
        let p = self.desc.camera.position + self.dir * (step.t0 + step.off);
        let (l, wl) = light_incident(&self.desc.lights[0], &self.desc.medium, p);
        let f = self.desc.medium.scattering * self.desc.medium.phase.eval(wl.dot(-self.dir)) * l * step.scale;
        self.seg = Some((k, f));
        f
    }
}

/// Merges adjacent spans of equal visibility before they are integrated (fewer exponentials,
/// and an unbroken lit run integrates as one span; a run of mixed texels is resolved in one
/// [`resolve_mixed`] call, its face planes and clip-space line found once). Mirrors the pending
/// span in walk.wgsl.
pub struct Merge {
    pending: Option<(f32, f32, f32)>,
}

impl Merge {
    /// Nothing pending.
    pub fn new() -> Self {
        Self { pending: None }
    }
    /// Adds span [c0, c1] of visibility v; returns the finished span it closes, if any.
    pub fn push(&mut self, c0: f32, c1: f32, v: f32) -> Option<(f32, f32, f32)> {
        match self.pending {
            Some((a, b, pv)) if b == c0 && pv == v => {
                self.pending = Some((a, c1, v));
                None
            }
            prev => {
                self.pending = Some((c0, c1, v));
                prev
            }
        }
    }
    /// The last span.
    pub fn finish(self) -> Option<(f32, f32, f32)> {
        self.pending
    }
}

impl Default for Merge {
    fn default() -> Self {
        Self::new()
    }
}

/// The most texel-edge steps [`resolve_mixed`] takes per mixed texel of a run (a run of n
/// texels takes at most n·64): a cost bound. A run that crosses more standard-texel edges (a
/// rectified texel covering a long stretch of the standard map along the ray) has the rest of
/// each of its pieces decided by one lookup at the rest's midpoint.
pub const MAX_PIECES: u32 = 64;

/// The ray point o + t·dir's position in the light's clip space, linear in t: (C, D) with
/// clip(t) = C + t·D for layer `layer`'s view-projection.
fn clip_line(shadow: &ShadowMap, layer: u32, o: Vec3, dir: Vec3) -> (Vec4, Vec4) {
    let m = shadow.projection.view_proj[layer as usize];
    (m * o.extend(1.0), m * dir.extend(0.0))
}

/// The t at which a + b·t = 0 (infinite when b = 0).
fn root(a: f32, b: f32) -> f32 {
    if b != 0.0 { -a / b } else { f32::INFINITY }
}

/// Where the span [t0, t1] of the ray o + t·dir may change the face or the validity of its
/// shadow-map lookup, sorted, inside (t0, t1): the light's w = 0 plane, the map's depth planes
/// ndc z = 0 and 1 (linear in t in clip space), and for a cube map the six planes through the
/// light where the dominant axis changes (|x| = |y|, |x| = |z|, |y| = |z|). Between two of them
/// the texel column and row the ray falls in are monotonic in t. Mirrors `span_breaks` in
/// walk.wgsl.
pub fn span_breaks(shadow: &ShadowMap, light_pos: Vec3, o: Vec3, dir: Vec3, t0: f32, t1: f32) -> ([f32; 9], usize) {
    let pr = &shadow.projection;
    let mut out = [0.0f32; 9];
    let mut n = 0;
    let mut push = |t: f32| {
        if t > t0 && t < t1 {
            out[n] = t;
            n += 1;
        }
    };
    // A one-layer map's planes; a cube map's face changes (its faces' w stays positive, and its
    // near and far planes, a light-sized sphere and the scene's bounds, are not breaks: a piece
    // across one is decided at its midpoint).
    if pr.layers == 1 {
        let (c, d) = clip_line(shadow, 0, o, dir);
        push(root(c.w, d.w));
        push(root(c.z, d.z));
        push(root(c.z - c.w, d.z - d.w));
    } else {
        let (q, v) = (o - light_pos, dir);
        for (i, j) in [(0, 1), (0, 2), (1, 2)] {
            push(root(q[i] - q[j], v[i] - v[j]));
            push(root(q[i] + q[j], v[i] + v[j]));
        }
    }
    // Insertion sort (at most nine values).
    for i in 1..n {
        let mut k = i;
        while k > 0 && out[k - 1] > out[k] {
            out.swap(k - 1, k);
            k -= 1;
        }
    }
    (out, n)
}

/// The next texel edge after `u` (texel coordinates, u·n) in direction `s` (±1) along one
/// axis: where the lookup's texels change. Nearest: the texel edges 0, 1, …, n. Bilinear: the
/// lines between texel centres k + ½ (where the 2×2 footprint moves on), and the map's own
/// edges 0 and n (outside it every point is lit). Past the last edge it returns one beyond
/// the map (> n or < 0). Mirrors `next_edge` in walk.wgsl.
pub fn next_edge(u: f32, s: f32, size: f32, filter: ShadowFilter) -> f32 {
    let bilinear = filter == ShadowFilter::Bilinear;
    if s > 0.0 {
        if !bilinear {
            return (u.floor() + 1.0).max(0.0);
        }
        if u < 0.0 {
            return 0.0;
        }
        let e = (u - 0.5).floor() + 1.5;
        if e > size && u < size { size } else { e }
    } else {
        if !bilinear {
            return (u.ceil() - 1.0).min(size);
        }
        if u > size {
            return size;
        }
        let e = (u - 0.5).ceil() - 0.5;
        if e < 0.0 && u > 0.0 { 0.0 } else { e }
    }
}

/// The exact visibility of a mixed texel's span [t0, t1] of the ray from `origin` along `dir`
/// (distances) against the standard shadow map, the test the reference makes at every point
/// (`ShadowMap::visibility` under the light's `filter`; outside the map lit). The span is cut
/// where its lookup can change face or validity ([`span_breaks`]) and where it crosses a
/// texel edge ([`next_edge`]; the texel column and row are monotonic in t between breaks,
/// each edge x = k solved in clip space, linear in t). In each piece the texels are fixed and
/// the light depth linear in t, so each texel's lit part is one interval, found in closed
/// form. Nearest: the piece's one texel decides, and its lit part is added exactly. Bilinear:
/// the four texels' lit parts cut the piece further; on each part the visibility is the sum
/// of the bilinear weights of the texels lit there, a product of two coordinates linear in t
/// under an orthographic map (a quadratic in t, which its values at both ends and the middle
/// give exactly, [`Spans::add_ramp`]) and ratios of linear functions under a perspective one
/// (where that quadratic is a fit, off by the weights' curvature across one texel,
/// docs/MODEL.md §8). At most [`MAX_PIECES`] edge steps per texel of the run (`texels`).
/// Mirrors `resolve_mixed` in walk.wgsl.
#[allow(clippy::too_many_arguments)]
pub fn resolve_mixed(
    spans: &mut Spans,
    shadow: &ShadowMap,
    light_pos: Vec3,
    bias: f32,
    filter: ShadowFilter,
    origin: Vec3,
    dir: Vec3,
    t0: f32,
    t1: f32,
    texels: u32,
) {
    if !(t1 > t0) {
        return;
    }
    let pr = &shadow.projection;
    let size = pr.size as f32;
    let (breaks, nb) = span_breaks(shadow, light_pos, origin, dir, t0, t1);
    // The edge steps taken: at most MAX_PIECES per texel, then the rest of each piece is one.
    let max_steps = MAX_PIECES.saturating_mul(texels.max(1));
    let mut steps = 0u32;
    // Lit parts that touch are integrated as one span: fewer exponentials, the same integral.
    let mut run = LitRun::default();
    // The lit part of [a, b] at texel (x, y) on face `layer` (clip line c + t·d).
    let lit_part = |x: u32, y: u32, a: f32, b: f32, layer: u32, c: Vec4, d: Vec4| -> (f32, f32) {
        let stored = shadow.texel(layer, x, y);
        // An empty texel lights the whole piece, beyond the far plane too (clip_coord).
        if pr.is_empty(stored) {
            return (a, b);
        }
        let limit = pr.linear(stored) + bias;
        let depth = |t: f32| {
            let q = c + d * t;
            pr.linear(q.z / q.w)
        };
        let (da, db) = (depth(a), depth(b));
        match (da <= limit, db <= limit) {
            (true, true) => (a, b),
            (false, false) => (b, b),
            (lit_a, _) => {
                let t = (a + (b - a) * (limit - da) / (db - da)).clamp(a, b);
                if lit_a { (a, t) } else { (t, b) }
            }
        }
    };
    let mut a = t0;
    for k in 0..=nb {
        let b = if k < nb { breaks[k] } else { t1 };
        if !(b > a) {
            continue;
        }
        // Between breaks: the face is fixed and w > 0 or w ≤ 0 throughout.
        let mid = origin + dir * (0.5 * (a + b));
        let layer = if pr.layers == 6 { cube_face(mid - light_pos) } else { 0 };
        let (c, d) = clip_line(shadow, layer, origin, dir);
        if (c + d * (0.5 * (a + b))).w <= 0.0 {
            run.add(spans, a, b);
            a = b;
            continue;
        }
        // Texel coordinates X = n·(x/w·½ + ½), Y = n·(½ − y/w·½) at t; the edge X = k is at
        // x = (2k/n − 1)·w, Y = k at y = (1 − 2k/n)·w, both linear in t.
        let xy = |t: f32| {
            let q = c + d * t;
            Vec2::new(size * (q.x / q.w * 0.5 + 0.5), size * (0.5 - q.y / q.w * 0.5))
        };
        // One piece [p0, p1] of fixed texels: its lit parts into `run` and `spans`. The texels
        // are those at the piece's midpoint (ShadowMap::clip_coord, on the clip line).
        let piece = |p0: f32, p1: f32, run: &mut LitRun, spans: &mut Spans| {
            let Some(sc) = shadow.clip_coord(layer, c + d * (0.5 * (p0 + p1))) else {
                run.add(spans, p0, p1);
                return;
            };
            if filter != ShadowFilter::Bilinear {
                let (la, lb) = lit_part(sc.texel.x, sc.texel.y, p0, p1, layer, c, d);
                run.add(spans, la, lb);
                return;
            }
            let ([x0, y0, x1, y1], _) = bilinear_footprint(sc.uv, pr.size);
            // The weights of x1 and y1 along the piece, from its fixed footprint corner.
            let corner = (sc.uv * size - 0.5).floor();
            let weights = |t: f32| (xy(t) - 0.5 - corner).clamp(Vec2::ZERO, Vec2::ONE);
            let texels = [(x0, y0), (x1, y0), (x0, y1), (x1, y1)];
            let lit = texels.map(|(x, y)| lit_part(x, y, p0, p1, layer, c, d));
            // Most pieces of a mixed texel are lit or shadowed by all four texels throughout.
            if lit.iter().all(|&(la, lb)| la == p0 && lb == p1) {
                run.add(spans, p0, p1);
                return;
            }
            if lit.iter().all(|&(la, lb)| !(lb > la)) {
                return;
            }
            // Each lit part starts at p0 or ends at p1 (`lit_part`), so it has at most one end
            // inside the piece: four cuts (p1 where a part has none), sorted. Between two
            // cuts the set of lit texels is fixed.
            let inner_end = |(la, lb): (f32, f32)| {
                if lb > la && la > p0 {
                    la
                } else if lb > la && lb < p1 {
                    lb
                } else {
                    p1
                }
            };
            let mut k = lit.map(inner_end);
            k.sort_by(f32::total_cmp);
            let ends = [p0, k[0], k[1], k[2], k[3], p1];
            for w in ends.windows(2) {
                let (s0, s1) = (w[0], w[1]);
                if !(s1 > s0) {
                    continue;
                }
                let sm = 0.5 * (s0 + s1);
                let on = lit.map(|(la, lb)| lb > la && la <= sm && sm <= lb);
                if on.iter().all(|&o| o) {
                    run.add(spans, s0, s1);
                } else if on.iter().any(|&o| o) {
                    // The bilinear blend of the lit texels' tests (ShadowMap::visibility).
                    let v = |t: f32| bilinear_blend(on.map(|o| o as u32 as f32), weights(t));
                    spans.add_ramp(s0, s1, [v(s0), v(sm), v(s1)]);
                }
            }
        };
        let (pa, pb) = (xy(a), xy(b));
        // The next edge after the start in each axis, and its step.
        let (sx, sy) = (if pb.x > pa.x { 1.0 } else { -1.0 }, if pb.y > pa.y { 1.0 } else { -1.0 });
        let (mut kx, mut ky) = (next_edge(pa.x, sx, size, filter), next_edge(pa.y, sy, size, filter));
        let edge_x = |k: f32| root(c.x - (2.0 * k / size - 1.0) * c.w, d.x - (2.0 * k / size - 1.0) * d.w);
        let edge_y = |k: f32| root(c.y - (1.0 - 2.0 * k / size) * c.w, d.y - (1.0 - 2.0 * k / size) * d.w);
        // Only the edges 0..=n matter: outside the map every point is lit.
        let past = |k: f32, s: f32, end: f32| if s > 0.0 { k >= end || k > size } else { k <= end || k < 0.0 };
        let mut t = a;
        loop {
            let tx = if past(kx, sx, pb.x) { f32::INFINITY } else { edge_x(kx) };
            let ty = if past(ky, sy, pb.y) { f32::INFINITY } else { edge_y(ky) };
            let mut e = tx.min(ty).min(b);
            if !(e > t) {
                // An edge at or before t (rounding): step past it.
                e = t;
            }
            steps += 1;
            if steps >= max_steps {
                e = b;
            }
            if e > t {
                piece(t, e, &mut run, spans);
                t = e;
            }
            if t >= b {
                break;
            }
            if tx <= ty {
                kx = next_edge(kx, sx, size, filter);
            } else {
                ky = next_edge(ky, sy, size, filter);
            }
        }
        a = b;
    }
    run.finish(spans);
}

/// The pending lit span of [`resolve_mixed`]: a lit part that starts where the pending one ends
/// extends it; any other is integrated.
#[derive(Default)]
struct LitRun {
    a: f32,
    b: f32,
}

impl LitRun {
    fn add(&mut self, spans: &mut Spans, a: f32, b: f32) {
        if !(b > a) {
            return;
        }
        if a == self.b && self.b > self.a {
            self.b = b;
            return;
        }
        self.finish(spans);
        *self = LitRun { a, b };
    }
    fn finish(&mut self, spans: &mut Spans) {
        if self.b > self.a {
            spans.add(self.a, self.b, 1.0);
        }
        *self = LitRun::default();
    }
}

/// One pixel: its ray into the rectified map (row, depth, the columns it crosses), the walk,
/// and its in-scattering; mixed texels are resolved against the frame's standard shadow map.
/// Mirrors `shade` in walk.wgsl.
pub fn shade(
    frame: &CpuFrame,
    settings: &MinmaxSettings,
    rect: &Rectification,
    tree: &[[f32; 2]],
    dir: Vec3,
    s: f32,
) -> (Vec3, Walk) {
    let desc = frame.desc;
    let fl = &desc.lights[0];
    let (shadow, light_pos) = (&frame.shadow_maps[0], light_position(&fl.light));
    let origin = desc.camera.position;
    let (row, c_b, _, z) = rect.rectify_point(origin + dir * s, dir);
    let theta = if rect.mode == Mode::Epipolar { angle_between(dir, rect.axes[2]) } else { 0.0 };
    // A finished span (c0, c1, v) of columns, as distances along the ray (the last one ends at
    // the surface, s), into `spans`.
    let integrate = |(c0, c1, v): (f32, f32, f32), spans: &mut Spans| {
        let t0 = column_distance(rect, dir, theta, c0).min(s);
        let t1 = if c1 >= c_b { s } else { column_distance(rect, dir, theta, c1).min(s) };
        if v == MIXED {
            // A run of level-0 texels: whole columns, the last one cut at c_b.
            let texels = (c1.ceil() - c0.floor()).max(1.0) as u32;
            resolve_mixed(spans, shadow, light_pos, fl.shadow_bias, fl.shadow_filter, origin, dir, t0, t1, texels);
        } else {
            spans.add(t0, t1, v);
        }
    };
    let mut spans = Spans::new(desc, settings, dir, s);
    let mut merge = Merge::new();
    let walk = walk(
        tree,
        rect.width,
        settings.tree_levels(),
        settings.max_nodes,
        ray_row(rect, row),
        z,
        0.0,
        c_b,
        |c0, c1, v| {
            if let Some(span) = merge.push(c0, c1, v) {
                integrate(span, &mut spans);
            }
        },
    );
    if let Some(span) = merge.finish() {
        integrate(span, &mut spans);
    }
    (spans.sum, walk)
}

/// The outputs of every pass of one frame.
#[derive(Clone, Debug)]
pub struct Passes {
    /// The rectification of the frame.
    pub rect: Rectification,
    /// The min-max tree ([`build`]).
    pub tree: Vec<[f32; 2]>,
    /// The in-scattering.
    pub image: Image,
    /// The walks' totals: rays, nodes, lit nodes, shadowed nodes, mixed texels, rays over
    /// budget, and the most nodes one ray visited.
    pub totals: WalkTotals,
    /// The nodes each pixel's walk visited (`u32::MAX` in the epipole disc): the `nodes` debug
    /// view. Row-major, the frame's size.
    pub nodes: Vec<u32>,
}

/// The walks of a frame, added up.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct WalkTotals {
    /// Rays walked (pixels outside the epipole disc).
    pub rays: u64,
    /// Nodes visited, all rays.
    pub nodes: u64,
    /// The most nodes one ray visited.
    pub max_nodes: u32,
    /// Lit nodes (spans integrated).
    pub lit: u64,
    /// Shadowed nodes (spans skipped).
    pub shadowed: u64,
    /// Rays that reached `max_nodes`.
    pub over_budget: u64,
    /// Mixed texels resolved against the standard shadow map.
    pub mixed: u64,
}

impl WalkTotals {
    fn add(&mut self, w: Walk) {
        self.rays += 1;
        self.nodes += w.nodes as u64;
        self.max_nodes = self.max_nodes.max(w.nodes);
        self.lit += w.lit as u64;
        self.shadowed += w.shadowed as u64;
        self.over_budget += w.over_budget as u64;
        self.mixed += w.mixed as u64;
    }
    fn merge(mut self, o: WalkTotals) -> WalkTotals {
        self.rays += o.rays;
        self.nodes += o.nodes;
        self.max_nodes = self.max_nodes.max(o.max_nodes);
        self.lit += o.lit;
        self.shadowed += o.shadowed;
        self.over_budget += o.over_budget;
        self.mixed += o.mixed;
        self
    }
}

/// Pass `traverse`: every pixel outside the epipole disc shaded by [`shade`]; also the nodes
/// each pixel's walk visited (`u32::MAX` in the epipole disc, which is ray-marched), what the
/// `nodes` debug view draws. Mirrors traverse.wgsl.
pub fn traverse(
    frame: &CpuFrame,
    settings: &MinmaxSettings,
    rect: &Rectification,
    tree: &[[f32; 2]],
    epipole: Option<[f32; 2]>,
) -> (Image, WalkTotals, Vec<u32>) {
    let desc = frame.desc;
    let w = desc.width as usize;
    let mut image = Image::new(desc.width, desc.height);
    let mut nodes = vec![u32::MAX; w * desc.height as usize];
    let totals = image
        .pixels
        .par_chunks_mut(w)
        .zip(nodes.par_chunks_mut(w))
        .enumerate()
        .map(|(y, (line, counts))| {
            let mut t = WalkTotals::default();
            for (x, (out, count)) in line.iter_mut().zip(counts).enumerate() {
                let (x, y) = (x as u32, y as u32);
                if in_epipole_disc(epipole, settings.epipole_radius, x, y) {
                    continue;
                }
                let dir = desc.pixel_ray(x, y);
                let s = desc.view_distance(frame.depth[(y * desc.width + x) as usize], dir);
                let (l, walk) = shade(frame, settings, rect, tree, dir, s);
                t.add(walk);
                *count = walk.nodes;
                *out = [l.x, l.y, l.z, 1.0];
            }
            t
        })
        .reduce(WalkTotals::default, WalkTotals::merge);
    (image, totals, nodes)
}

/// Every pass of a frame; `host_depth` is a rectified map the host rasterized (projective frames
/// only), else level 0 of the tree bounds the standard shadow map's texels ([`texel_bounds`]).
pub fn passes(
    frame: &CpuFrame,
    settings: &MinmaxSettings,
    host_depth: Option<&[f32]>,
) -> Result<(Passes, Vec<PassTime>), Error> {
    settings.validate()?;
    let desc = frame.desc;
    let settings = &settings.for_frame(desc);
    let mut times = vec![];
    let mut timed = |name: &str, t: std::time::Instant| {
        times.push(PassTime { name: name.into(), ms: t.elapsed().as_secs_f64() * 1e3 })
    };
    let t = std::time::Instant::now();
    let rect = Rectification::new(desc, &settings.rectify_options());
    let host = host_depth.filter(|_| super::reads_host_raster(desc, &rect));
    if let Some(d) = host
        && d.len() != (rect.width * rect.height) as usize
    {
        return Err(Error::invalid("minmax host depth", d.len(), "must hold map_size[0]·map_size[1] texels"));
    }
    let tree = build(frame, &rect, host, settings.tree_levels());
    timed("build", t);
    let t = std::time::Instant::now();
    let epipole = epipole_pixel(desc, settings.epipole_radius);
    let (mut image, totals, nodes) = traverse(frame, settings, &rect, &tree, epipole);
    timed("traverse", t);
    if epipole.is_some() {
        let t = std::time::Instant::now();
        march_epipole(frame, &settings.rectified(), epipole, &mut image);
        timed("epipole", t);
    }
    Ok((Passes { rect, tree, image, totals, nodes }, times))
}

/// Renders `frame` on the CPU (one light); the result matches `super::MinMax::encode` up to
/// f32 rounding where a ray's depth meets a texel's.
pub fn render_with(
    frame: &CpuFrame,
    settings: &MinmaxSettings,
    host_depth: Option<&[f32]>,
) -> Result<(Image, TechniqueStats), Error> {
    frame.desc.single_light()?;
    let settings = &settings.for_frame(frame.desc);
    let (p, times) = passes(frame, settings, host_depth)?;
    let epipole = epipole_pixel(frame.desc, settings.epipole_radius);
    let host = host_depth.is_some() && super::reads_host_raster(frame.desc, &p.rect);
    let stats = TechniqueStats {
        technique: "minmax".into(),
        backend: "cpu".into(),
        timing: "wall-clock".into(),
        passes: times,
        raymarched_samples: epipole_samples(frame.desc, &settings.rectified(), epipole),
        gpu_memory_bytes: 0,
        extra: super::stats_extra(settings, &p.rect, host, Some(&p.totals)),
    };
    Ok((p.image, stats))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A deterministic pseudo-random row set: runs of occluded and unoccluded texels of random
    /// lengths and depths (a canopy), some rows empty (all 1.0).
    fn rows(width: u32, height: u32, seed: u32) -> Vec<f32> {
        let mut state = seed.wrapping_mul(2654435761).wrapping_add(1);
        let mut next = move || {
            state ^= state << 13;
            state ^= state >> 17;
            state ^= state << 5;
            (state >> 8) as f32 / 16777216.0
        };
        let mut out = Vec::with_capacity((width * height) as usize);
        for r in 0..height {
            let mut c = 0;
            while c < width {
                let run = 1 + (next() * 24.0) as u32;
                let d = if r % 7 == 3 || next() < 0.4 { 1.0 } else { next() };
                for _ in 0..run.min(width - c) {
                    out.push(if d < 1.0 { (d + 0.05 * next()).min(0.999) } else { 1.0 });
                }
                c += run;
            }
        }
        out
    }

    /// Every node of every level bounds its span exactly: its (min, max) is the min and max of
    /// the texels it covers, computed independently.
    #[test]
    fn every_node_bounds_its_span_exactly() {
        let (w, h) = (256u32, 9u32);
        let depth = rows(w, h, 7);
        let levels = 8;
        let tree = build_rows(w, h, levels, |r, c| [depth[r * w as usize + c]; 2]);
        for r in 0..h as usize {
            for l in 0..=levels {
                for i in 0..(w >> l) as usize {
                    let span = &depth[r * w as usize + (i << l)..r * w as usize + ((i + 1) << l)];
                    let lo = span.iter().copied().fold(f32::MAX, f32::min);
                    let hi = span.iter().copied().fold(f32::MIN, f32::max);
                    assert_eq!(
                        tree[r * 2 * w as usize + level_offset(w, l) + i],
                        [lo, hi],
                        "row {r} level {l} node {i}"
                    );
                }
            }
        }
    }

    fn merged(mut f: impl FnMut(&mut dyn FnMut(f32, f32, f32))) -> Vec<(f32, f32, f32)> {
        let mut m = Merge::new();
        let mut out = vec![];
        f(&mut |c0, c1, v| out.extend(m.push(c0, c1, v)));
        out.extend(m.finish());
        out
    }

    /// The tree walk finds exactly the lit spans of the texel-by-texel scan, at every number of
    /// levels, for rays of every depth ending anywhere in the row; and it visits far fewer nodes
    /// than the columns it covers.
    #[test]
    fn the_walk_equals_the_linear_scan_span_for_span() {
        let (w, h) = (512u32, 12u32);
        let depth = rows(w, h, 3);
        let mut nodes_full = 0u64;
        let mut columns = 0u64;
        for levels in [0, 1, 3, 9] {
            let tree = build_rows(w, h, levels, |r, c| [depth[r * w as usize + c]; 2]);
            for r in 0..h {
                for (z, c_b) in [(0.0, 512.0), (0.3, 511.5), (0.5, 100.25), (0.95, 37.0), (1.0, 512.0), (0.62, 0.5)] {
                    let texel = |c: u32| depth[(r * w + c) as usize];
                    let scan = merged(|e| linear_scan(w, texel, z, 0.0, c_b, e));
                    let mut walk_out = Walk::default();
                    let tree_spans = merged(|e| walk_out = walk(&tree, w, levels, u32::MAX, r, z, 0.0, c_b, e));
                    assert_eq!(tree_spans, scan, "levels {levels} row {r} z {z} end {c_b}");
                    assert_eq!(walk_out.over_budget, 0);
                    if levels == 9 {
                        nodes_full += walk_out.nodes as u64;
                        columns += c_b.ceil() as u64;
                    }
                }
            }
        }
        assert!(nodes_full * 2 < columns, "the tree visited {nodes_full} nodes for {columns} columns");
    }

    /// With a node budget the walk stops refining: it still ends, visits at most the budget plus
    /// one climb's worth of nodes, flags the ray, and every column it gives a visibility is one
    /// the row allows (a mixed node counts ½, never a lit one as shadowed or the reverse).
    #[test]
    fn the_node_budget_bounds_the_walk() {
        let (w, h) = (512u32, 4u32);
        let depth = rows(w, h, 11);
        let levels = 9;
        let tree = build_rows(w, h, levels, |r, c| [depth[r * w as usize + c]; 2]);
        for budget in [1u32, 4, 16] {
            for r in 0..h {
                let z = 0.5;
                let mut spans = vec![];
                let walk_out = walk(&tree, w, levels, budget, r, z, 0.0, 512.0, |a, b, v| spans.push((a, b, v)));
                let full = walk(&tree, w, levels, u32::MAX, r, z, 0.0, 512.0, |_, _, _| {});
                assert!(walk_out.nodes <= budget + 2 * levels + 2, "budget {budget}: {} nodes", walk_out.nodes);
                assert_eq!(walk_out.over_budget, (full.nodes > budget) as u32);
                for (a, b, v) in spans {
                    let cols = &depth[(r * w) as usize + a as usize..(r * w) as usize + b as usize];
                    let lit = cols.iter().filter(|&&d| z <= d).count();
                    match v {
                        1.0 => assert_eq!(lit, cols.len()),
                        0.5 => assert!(lit > 0 && lit < cols.len()),
                        _ => panic!("visibility {v}"),
                    }
                }
            }
        }
    }
}
