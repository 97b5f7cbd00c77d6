//! A CPU triangle rasterizer with the GPU's (wgpu / Vulkan) conventions, so CPU and GPU depth
//! buffers and shadow maps agree pixel for pixel except for rare edge pixels.
//!
//! Conventions, as the GPU applies them:
//! - Clip space as wgpu: x, y ∈ [−w, w], z ∈ [0, w]. Triangles are clipped in homogeneous
//!   space (Sutherland–Hodgman) against the near plane z ≥ 0 and the far plane z ≤ w, and
//!   against a guard band far outside the viewport (which changes no covered pixel but keeps
//!   screen coordinates bounded), then split into a fan.
//! - Viewport: pixel (x, y) covers [x, x+1]×[y, y+1] and is sampled at its centre; screen
//!   x = (ndc.x·0.5 + 0.5)·width, screen y = (0.5 − ndc.y·0.5)·height (row 0 at the top).
//! - Vertex positions are snapped to 1/256 pixel (8 sub-pixel bits, as hardware does); edge
//!   functions are then evaluated in f64, where they are exact, so the top-left fill rule
//!   draws every pixel on an edge shared by two triangles exactly once.
//! - No face culling. Depth is NDC z interpolated linearly in screen space, clamped to [0, 1];
//!   the depth test is LESS against a buffer cleared to 1.0, in primitive order.
//! - [`rasterize_rectified`] draws with depth clamping instead (wgpu's `unclipped_depth`):
//!   no near/far clipping, the interpolated depth clamped to [0, 1] per pixel.
//!
//! The work runs on rayon: triangles are transformed and clipped in parallel chunks, binned
//! into horizontal bands of [`BAND_ROWS`] rows, and the bands are rasterized in parallel.

use crate::scene::Geometry;
use crepuscular::DepthConvention;
use crepuscular::techniques::prefiltered::raster::RectifiedRaster;
use crepuscular::{ShadowMap, ShadowProjection};
use glam::{Mat4, Vec4};
use rayon::prelude::*;

/// Rows per band of the parallel rasterizer.
pub const BAND_ROWS: usize = 16;

/// Sub-pixel precision: vertex positions are snapped to 1 / `SUBPIXEL` pixel.
const SUBPIXEL: f64 = 256.0;
/// Smallest nonzero edge-function magnitude for snapped vertices and pixel-centre samples
/// (products of two values with 8 fractional bits): a strict `e > 0` is `e >= EDGE_EPS`.
const EDGE_EPS: f64 = 1.0 / 65536.0;
/// Guard band in pixels beyond each side of the viewport.
const GUARD_PIXELS: f64 = 8192.0;
/// Triangles per parallel setup chunk.
const SETUP_CHUNK: usize = 2048;
/// Largest clipped polygon: 3 vertices + one per clip plane.
const MAX_POLY: usize = 9;

/// The result of [`rasterize`]: depth, visible triangle and its barycentrics per pixel, all
/// row-major from the top-left pixel.
#[derive(Clone, Debug, PartialEq)]
pub struct DepthBuffer {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// [0, 1] NDC depth of the nearest surface, 1.0 where nothing was drawn.
    pub depth: Vec<f32>,
    /// Index of the visible triangle in the geometry (`indices[3t..3t+3]`), `u32::MAX` where
    /// nothing was drawn.
    pub triangle: Vec<u32>,
    /// Perspective-correct barycentric coordinates of the pixel centre with respect to the
    /// visible triangle's three original vertices (in index order); they sum to 1. Zero where
    /// nothing was drawn.
    pub bary: Vec<[f32; 3]>,
}

impl DepthBuffer {
    /// Row-major index of pixel (x, y).
    pub fn index(&self, x: u32, y: u32) -> usize {
        y as usize * self.width as usize + x as usize
    }
    /// Whether anything was drawn at pixel (x, y).
    pub fn covered(&self, x: u32, y: u32) -> bool {
        self.triangle[self.index(x, y)] != u32::MAX
    }
}

/// A vertex of a clipped polygon: homogeneous clip position and barycentrics with respect to
/// the original triangle.
#[derive(Clone, Copy, Default)]
struct ClipVert {
    c: [f64; 4],
    b: [f64; 3],
}

/// A screen-space triangle after clipping, snapping and orienting (positive area).
#[derive(Clone, Copy)]
struct ScreenTri {
    x: [f64; 3],
    y: [f64; 3],
    z: [f64; 3],
    inv_area: f64,
    tri: u32,
    /// Inclusive pixel bounds: x0, x1, y0, y1.
    bbox: [u32; 4],
}

/// Per-vertex data for perspective-correct barycentrics of a [`ScreenTri`].
#[derive(Clone, Copy)]
struct Persp {
    inv_w: [f64; 3],
    /// Original-triangle barycentrics divided by w, per screen vertex.
    b_over_w: [[f64; 3]; 3],
}

/// Clip planes as (x, y, z, w) coefficients; a point is inside when the dot product is ≥ 0.
fn clip_planes(width: u32, height: u32) -> [[f64; 4]; 6] {
    let gx = 1.0 + 2.0 * GUARD_PIXELS / width as f64;
    let gy = 1.0 + 2.0 * GUARD_PIXELS / height as f64;
    [
        [0.0, 0.0, 1.0, 0.0],  // near: z ≥ 0
        [0.0, 0.0, -1.0, 1.0], // far: z ≤ w
        [1.0, 0.0, 0.0, gx],   // x ≥ −gx·w
        [-1.0, 0.0, 0.0, gx],  // x ≤ gx·w
        [0.0, 1.0, 0.0, gy],   // y ≥ −gy·w
        [0.0, -1.0, 0.0, gy],  // y ≤ gy·w
    ]
}

fn plane_dist(p: &[f64; 4], c: &[f64; 4]) -> f64 {
    p[0] * c[0] + p[1] * c[1] + p[2] * c[2] + p[3] * c[3]
}

/// Clips a convex polygon against one plane (Sutherland–Hodgman). Vertices exactly on the
/// plane count as inside.
fn clip_polygon(input: &[ClipVert], plane: &[f64; 4], out: &mut [ClipVert; MAX_POLY], is_near: bool) -> usize {
    let mut n = 0;
    let count = input.len();
    for i in 0..count {
        let a = &input[i];
        let b = &input[(i + 1) % count];
        let da = plane_dist(plane, &a.c);
        let db = plane_dist(plane, &b.c);
        if da >= 0.0 && n < MAX_POLY {
            out[n] = *a;
            n += 1;
        }
        if (da >= 0.0) != (db >= 0.0) && n < MAX_POLY {
            let t = da / (da - db);
            let mut v = ClipVert::default();
            for k in 0..4 {
                v.c[k] = a.c[k] + t * (b.c[k] - a.c[k]);
            }
            for k in 0..3 {
                v.b[k] = a.b[k] + t * (b.b[k] - a.b[k]);
            }
            if is_near {
                v.c[2] = 0.0;
            }
            out[n] = v;
            n += 1;
        }
    }
    n
}

fn snap(v: f64) -> f64 {
    (v * SUBPIXEL).round_ties_even() / SUBPIXEL
}

/// Whether triangles are clipped against the near and far planes (the GPU default) or only
/// against x, y (and so w > 0), their depth clamped to [0, 1] instead (`unclipped_depth`).
#[derive(Clone, Copy, PartialEq, Eq)]
enum DepthMode {
    Clip,
    Clamp,
}

/// Transforms, clips and snaps one triangle, pushing its screen triangles.
#[allow(clippy::too_many_arguments)]
fn setup_triangle(
    geometry: &Geometry,
    view_proj: &Mat4,
    planes: &[[f64; 4]; 6],
    depth_mode: DepthMode,
    width: u32,
    height: u32,
    t: u32,
    want_persp: bool,
    tris: &mut Vec<ScreenTri>,
    persps: &mut Vec<Persp>,
) {
    // The near and far planes are the first two: skipped when depth is clamped. The x and y
    // planes alone keep w ≥ 0 (|x| ≤ g·w).
    let first_plane = if depth_mode == DepthMode::Clamp { 2 } else { 0 };
    let base = 3 * t as usize;
    let mut verts = [ClipVert::default(); 3];
    for (k, vert) in verts.iter_mut().enumerate() {
        let Some(v) = geometry.vertices.get(geometry.indices[base + k] as usize) else {
            return;
        };
        let p = v.position;
        let c = *view_proj * Vec4::new(p[0], p[1], p[2], 1.0);
        if !c.is_finite() {
            return;
        }
        vert.c = [c.x as f64, c.y as f64, c.z as f64, c.w as f64];
        vert.b[k] = 1.0;
    }

    // Outcodes: trivially reject, and clip only against the planes that cut the triangle.
    let mut cut = [false; 6];
    for (p, plane) in planes.iter().enumerate().skip(first_plane) {
        let d = verts.map(|v| plane_dist(plane, &v.c));
        let outside = d.map(|d| d < 0.0);
        if outside.iter().all(|&o| o) {
            return;
        }
        cut[p] = outside.iter().any(|&o| o);
    }
    let mut poly = [ClipVert::default(); MAX_POLY];
    poly[..3].copy_from_slice(&verts);
    let mut n = 3;
    let mut tmp = [ClipVert::default(); MAX_POLY];
    for (p, plane) in planes.iter().enumerate().skip(first_plane) {
        if cut[p] {
            n = clip_polygon(&poly[..n], plane, &mut tmp, p == 0);
            std::mem::swap(&mut poly, &mut tmp);
            if n < 3 {
                return;
            }
        }
    }

    // Project to the (snapped) screen.
    let (wf, hf) = (width as f64, height as f64);
    let mut sx = [0.0; MAX_POLY];
    let mut sy = [0.0; MAX_POLY];
    let mut sz = [0.0; MAX_POLY];
    let mut iw = [0.0; MAX_POLY];
    // Unsnapped screen positions (for the depth plane of clamped depth).
    let mut ux = [0.0; MAX_POLY];
    let mut uy = [0.0; MAX_POLY];
    for i in 0..n {
        let c = &poly[i].c;
        if c[3] <= 0.0 || c[3].is_nan() {
            return;
        }
        let inv = 1.0 / c[3];
        ux[i] = (c[0] * inv * 0.5 + 0.5) * wf;
        uy[i] = (0.5 - c[1] * inv * 0.5) * hf;
        sx[i] = snap(ux[i]);
        sy[i] = snap(uy[i]);
        // Clipped depth is already in [0, 1] (up to rounding); clamped depth is clamped after
        // interpolation, per pixel, as the GPU clamps it.
        sz[i] = match depth_mode {
            DepthMode::Clip => (c[2] * inv).clamp(0.0, 1.0),
            DepthMode::Clamp => c[2] * inv,
        };
        iw[i] = inv;
        if !(sx[i].is_finite() && sy[i].is_finite() && sz[i].is_finite() && inv.is_finite()) {
            return;
        }
    }
    if depth_mode == DepthMode::Clamp {
        // Without near clipping, vertices next to the eye plane (w → 0) keep depths with
        // |z/w| ≫ 1, and snapping their screen positions would tilt the depth plane by up to
        // ~1e-4 over the visible part. Keep the exact plane, from the unsnapped positions (of
        // the best-conditioned fan triangle), and evaluate it at the snapped vertices.
        let mut best = (0.0, 1);
        for i in 1..n - 1 {
            let area = ((ux[i] - ux[0]) * (uy[i + 1] - uy[0]) - (uy[i] - uy[0]) * (ux[i + 1] - ux[0])).abs();
            if area > best.0 {
                best = (area, i);
            }
        }
        let (area, i) = best;
        if area > 0.0 && area.is_finite() {
            let (dx1, dy1, dz1) = (ux[i] - ux[0], uy[i] - uy[0], sz[i] - sz[0]);
            let (dx2, dy2, dz2) = (ux[i + 1] - ux[0], uy[i + 1] - uy[0], sz[i + 1] - sz[0]);
            let det = dx1 * dy2 - dy1 * dx2;
            let a = (dz1 * dy2 - dy1 * dz2) / det;
            let b = (dx1 * dz2 - dz1 * dx2) / det;
            let (x0, y0, z0) = (ux[0], uy[0], sz[0]);
            if a.is_finite() && b.is_finite() {
                for j in 0..n {
                    sz[j] = z0 + a * (sx[j] - x0) + b * (sy[j] - y0);
                }
            }
        }
    }

    // Fan.
    for i in 1..n - 1 {
        let mut idx = [0, i, i + 1];
        let area = (sx[idx[1]] - sx[idx[0]]) * (sy[idx[2]] - sy[idx[0]])
            - (sy[idx[1]] - sy[idx[0]]) * (sx[idx[2]] - sx[idx[0]]);
        if area == 0.0 || !area.is_finite() {
            continue;
        }
        if area < 0.0 {
            idx.swap(1, 2);
        }
        let x = idx.map(|j| sx[j]);
        let y = idx.map(|j| sy[j]);
        let min_x = x[0].min(x[1]).min(x[2]);
        let max_x = x[0].max(x[1]).max(x[2]);
        let min_y = y[0].min(y[1]).min(y[2]);
        let max_y = y[0].max(y[1]).max(y[2]);
        // Pixel centres inside the bounds.
        let x0 = (min_x - 0.5).ceil().max(0.0);
        let x1 = (max_x - 0.5).floor().min(wf - 1.0);
        let y0 = (min_y - 0.5).ceil().max(0.0);
        let y1 = (max_y - 0.5).floor().min(hf - 1.0);
        if x0 > x1 || y0 > y1 {
            continue;
        }
        tris.push(ScreenTri {
            x,
            y,
            z: idx.map(|j| sz[j]),
            inv_area: 1.0 / area.abs(),
            tri: t,
            bbox: [x0 as u32, x1 as u32, y0 as u32, y1 as u32],
        });
        if want_persp {
            persps.push(Persp { inv_w: idx.map(|j| iw[j]), b_over_w: idx.map(|j| poly[j].b.map(|b| b * iw[j])) });
        }
    }
}

/// Transforms, clips and snaps every triangle (in parallel, keeping primitive order).
fn setup(
    geometry: &Geometry,
    view_proj: Mat4,
    depth_mode: DepthMode,
    width: u32,
    height: u32,
    want_persp: bool,
) -> (Vec<ScreenTri>, Vec<Persp>) {
    let planes = clip_planes(width, height);
    let count = geometry.triangle_count() as u32;
    let chunks: Vec<(Vec<ScreenTri>, Vec<Persp>)> = (0..count.div_ceil(SETUP_CHUNK as u32))
        .into_par_iter()
        .map(|c| {
            let start = c * SETUP_CHUNK as u32;
            let end = (start + SETUP_CHUNK as u32).min(count);
            let mut tris = Vec::with_capacity((end - start) as usize);
            let mut persps = Vec::new();
            for t in start..end {
                setup_triangle(
                    geometry,
                    &view_proj,
                    &planes,
                    depth_mode,
                    width,
                    height,
                    t,
                    want_persp,
                    &mut tris,
                    &mut persps,
                );
            }
            (tris, persps)
        })
        .collect();
    let total = chunks.iter().map(|c| c.0.len()).sum();
    let mut tris = Vec::with_capacity(total);
    let mut persps = Vec::with_capacity(if want_persp { total } else { 0 });
    for (t, p) in chunks {
        tris.extend(t);
        persps.extend(p);
    }
    (tris, persps)
}

/// Per-band lists of screen-triangle indices (CSR), in primitive order.
fn bin(tris: &[ScreenTri], bands: usize) -> (Vec<usize>, Vec<u32>) {
    let mut offsets = vec![0usize; bands + 1];
    for t in tris {
        for b in t.bbox[2] as usize / BAND_ROWS..=t.bbox[3] as usize / BAND_ROWS {
            offsets[b + 1] += 1;
        }
    }
    for b in 0..bands {
        offsets[b + 1] += offsets[b];
    }
    let mut cursor = offsets.clone();
    let mut items = vec![0u32; offsets[bands]];
    for (i, t) in tris.iter().enumerate() {
        for b in t.bbox[2] as usize / BAND_ROWS..=t.bbox[3] as usize / BAND_ROWS {
            items[cursor[b]] = i as u32;
            cursor[b] += 1;
        }
    }
    (offsets, items)
}

/// Edge setup of a screen triangle. Edge k is opposite vertex k, from vertex k+1 to k+2;
/// e_k(px, py) = dx·(py − ay) − dy·(px − ax), positive inside.
struct Edges {
    ax: [f64; 3],
    ay: [f64; 3],
    dx: [f64; 3],
    dy: [f64; 3],
    /// Minimum value of e_k for coverage: 0 on top-left edges, `EDGE_EPS` (strict) otherwise.
    min: [f64; 3],
}

impl Edges {
    fn new(t: &ScreenTri) -> Self {
        let mut e = Edges { ax: [0.0; 3], ay: [0.0; 3], dx: [0.0; 3], dy: [0.0; 3], min: [0.0; 3] };
        for k in 0..3 {
            let (a, b) = ((k + 1) % 3, (k + 2) % 3);
            e.ax[k] = t.x[a];
            e.ay[k] = t.y[a];
            e.dx[k] = t.x[b] - t.x[a];
            e.dy[k] = t.y[b] - t.y[a];
            // With positive area in y-down screen space the interior lies to the right of
            // a → b: a left edge goes up (dy < 0), a top edge goes right (dy = 0, dx > 0).
            let top_left = e.dy[k] < 0.0 || (e.dy[k] == 0.0 && e.dx[k] > 0.0);
            e.min[k] = if top_left { 0.0 } else { EDGE_EPS };
        }
        e
    }
    fn eval(&self, k: usize, px: f64, py: f64) -> f64 {
        self.dx[k] * (py - self.ay[k]) - self.dy[k] * (px - self.ax[k])
    }
}

/// Rasterizes the triangles of one band into `depth` (and `ids`: screen-triangle indices).
#[allow(clippy::too_many_arguments)]
fn raster_band(
    tris: &[ScreenTri],
    list: &[u32],
    width: usize,
    band_y0: usize,
    rows: usize,
    depth: &mut [f32],
    mut ids: Option<&mut [u32]>,
    convention: DepthConvention,
) {
    let band_y1 = band_y0 + rows - 1;
    for &ti in list {
        let t = &tris[ti as usize];
        let e = Edges::new(t);
        let ys = (t.bbox[2] as usize).max(band_y0);
        let ye = (t.bbox[3] as usize).min(band_y1);
        let (bx0, bx1) = (t.bbox[0] as i64, t.bbox[1] as i64);
        for y in ys..=ye {
            let py = y as f64 + 0.5;
            // Conservative span of the row from the three edges, then exact tests.
            let (mut lo, mut hi) = (bx0, bx1);
            let mut row = [0.0; 3];
            for (k, r) in row.iter_mut().enumerate() {
                // e_k(px) = c + a·(px − ax), with c = dx·(py − ay) and a = −dy.
                let c = e.dx[k] * (py - e.ay[k]);
                *r = c;
                let a = -e.dy[k];
                if a == 0.0 {
                    if c < e.min[k] {
                        lo = 1;
                        hi = 0;
                    }
                } else {
                    // e_k(x + 0.5) = c + a·(x + 0.5 − ax) ≥ min.
                    let bound = e.ax[k] - 0.5 + (e.min[k] - c) / a;
                    if !bound.is_finite() {
                        continue;
                    }
                    if a > 0.0 {
                        lo = lo.max(bound.ceil() as i64 - 1);
                    } else {
                        hi = hi.min(bound.floor() as i64 + 1);
                    }
                }
            }
            if lo > hi {
                continue;
            }
            let px0 = lo as f64 + 0.5;
            let mut ev = [0.0; 3];
            for k in 0..3 {
                ev[k] = row[k] - e.dy[k] * (px0 - e.ax[k]);
            }
            let step = [-e.dy[0], -e.dy[1], -e.dy[2]];
            let row_off = (y - band_y0) * width;
            for x in lo..=hi {
                if ev[0] >= e.min[0] && ev[1] >= e.min[1] && ev[2] >= e.min[2] {
                    let d = ((ev[0] * t.z[0] + ev[1] * t.z[1] + ev[2] * t.z[2]) * t.inv_area).clamp(0.0, 1.0) as f32;
                    let i = row_off + x as usize;
                    if convention.nearer(d, depth[i]) {
                        depth[i] = d;
                        if let Some(ids) = ids.as_deref_mut() {
                            ids[i] = ti;
                        }
                    }
                }
                ev[0] += step[0];
                ev[1] += step[1];
                ev[2] += step[2];
            }
        }
    }
}

/// Rasterizes `geometry` (a world-space triangle list) with the world → clip matrix
/// `view_proj` into a `width × height` depth buffer, with the visible triangle and its
/// perspective-correct barycentrics at every pixel centre. GPU conventions: see the module
/// documentation. Degenerate triangles, triangles with non-finite vertices and out-of-range
/// indices are skipped.
pub fn rasterize(geometry: &Geometry, view_proj: Mat4, width: u32, height: u32) -> DepthBuffer {
    rasterize_with(geometry, view_proj, width, height, DepthConvention::Standard)
}

/// [`rasterize`] for a depth buffer of the given convention: cleared to its far value, the
/// nearer surface kept by its depth test (reversed-Z: the larger depth).
pub fn rasterize_with(
    geometry: &Geometry,
    view_proj: Mat4,
    width: u32,
    height: u32,
    convention: DepthConvention,
) -> DepthBuffer {
    let pixels = width as usize * height as usize;
    let mut out = DepthBuffer {
        width,
        height,
        depth: vec![convention.far_value(); pixels],
        triangle: vec![u32::MAX; pixels],
        bary: vec![[0.0; 3]; pixels],
    };
    if pixels == 0 {
        return out;
    }
    let (tris, persps) = setup(geometry, view_proj, DepthMode::Clip, width, height, true);
    let w = width as usize;
    let bands = (height as usize).div_ceil(BAND_ROWS);
    let (offsets, items) = bin(&tris, bands);
    let chunk = BAND_ROWS * w;
    out.depth
        .par_chunks_mut(chunk)
        .zip(out.triangle.par_chunks_mut(chunk))
        .zip(out.bary.par_chunks_mut(chunk))
        .enumerate()
        .for_each(|(b, ((depth, triangle), bary))| {
            let rows = depth.len() / w;
            let y0 = b * BAND_ROWS;
            let mut ids = vec![u32::MAX; depth.len()];
            raster_band(&tris, &items[offsets[b]..offsets[b + 1]], w, y0, rows, depth, Some(&mut ids), convention);
            for (i, &id) in ids.iter().enumerate() {
                if id == u32::MAX {
                    continue;
                }
                let t = &tris[id as usize];
                let p = &persps[id as usize];
                let e = Edges::new(t);
                let px = (i % w) as f64 + 0.5;
                let py = (y0 + i / w) as f64 + 0.5;
                let l = [0, 1, 2].map(|k| e.eval(k, px, py) * t.inv_area);
                let denom = l[0] * p.inv_w[0] + l[1] * p.inv_w[1] + l[2] * p.inv_w[2];
                let mut bc = [0.0f64; 3];
                for (j, b) in bc.iter_mut().enumerate() {
                    *b = (l[0] * p.b_over_w[0][j] + l[1] * p.b_over_w[1][j] + l[2] * p.b_over_w[2][j]) / denom;
                }
                triangle[i] = t.tri;
                bary[i] = bc.map(|b| b as f32);
            }
        });
    out
}

/// The motion vectors an engine's prepass writes, for the surfaces `buffer` shows
/// ([`rasterize_with`] of `geometry` through the current camera): per pixel, its UV now minus
/// the UV of the same surface point in the previous frame (x right, y down, 1 = the image's
/// width or height), the convention of `crepuscular::temporal::motion_source`. The point is
/// the visible triangle's previous vertices, `previous[i]` for vertex i of `geometry` (the
/// same triangles, moved), weighted by the pixel's barycentrics, seen through the previous
/// frame's world → clip matrix `previous_view_proj`. Pixels where nothing was drawn get zero
/// (the temporal stage reprojects them through the camera); a point behind the previous
/// camera gets a vector that leaves the image.
///
/// Panics if `previous` does not hold one position per vertex of `geometry` (a caller's bug:
/// the previous frame is the same geometry, moved).
pub fn motion_vectors(
    buffer: &DepthBuffer,
    geometry: &Geometry,
    previous: &[[f32; 3]],
    previous_view_proj: Mat4,
) -> Vec<[f32; 2]> {
    assert_eq!(previous.len(), geometry.vertices.len(), "one previous position per vertex");
    let (w, h) = (buffer.width as f32, buffer.height as f32);
    (0..buffer.depth.len())
        .into_par_iter()
        .map(|i| {
            let tri = buffer.triangle[i];
            if tri == u32::MAX {
                return [0.0, 0.0];
            }
            let b = buffer.bary[i];
            let idx = &geometry.indices[tri as usize * 3..tri as usize * 3 + 3];
            let p =
                (0..3).map(|k| glam::Vec3::from(previous[idx[k] as usize]) * b[k]).fold(glam::Vec3::ZERO, |a, v| a + v);
            let clip = previous_view_proj * p.extend(1.0);
            if clip.w <= 0.0 {
                return [10.0, 10.0];
            }
            let (x, y) = ((i % buffer.width as usize) as f32, (i / buffer.width as usize) as f32);
            let then = [clip.x / clip.w * 0.5 + 0.5, 0.5 - clip.y / clip.w * 0.5];
            [(x + 0.5) / w - then[0], (y + 0.5) / h - then[1]]
        })
        .collect()
}

/// Depth only: like [`rasterize`] without triangle ids and barycentrics (faster). Returns
/// `size_w × size_h` [0, 1] depths, row-major from the top-left pixel, 1.0 where nothing was
/// drawn.
pub fn rasterize_depth_only(geometry: &Geometry, view_proj: Mat4, size_w: u32, size_h: u32) -> Vec<f32> {
    depth_only(geometry, view_proj, DepthMode::Clip, size_w, size_h, DepthConvention::Standard)
}

/// [`rasterize_depth_only`] with near/far clipping or depth clamping.
fn depth_only(
    geometry: &Geometry,
    view_proj: Mat4,
    depth_mode: DepthMode,
    size_w: u32,
    size_h: u32,
    convention: DepthConvention,
) -> Vec<f32> {
    let pixels = size_w as usize * size_h as usize;
    let mut depth = vec![convention.far_value(); pixels];
    if pixels == 0 {
        return depth;
    }
    let (tris, _) = setup(geometry, view_proj, depth_mode, size_w, size_h, false);
    let w = size_w as usize;
    let bands = (size_h as usize).div_ceil(BAND_ROWS);
    let (offsets, items) = bin(&tris, bands);
    depth.par_chunks_mut(BAND_ROWS * w).enumerate().for_each(|(b, depth)| {
        let rows = depth.len() / w;
        raster_band(&tris, &items[offsets[b]..offsets[b + 1]], w, b * BAND_ROWS, rows, depth, None, convention);
    });
    depth
}

/// Renders the shadow map of `projection`: each of its `layers` layers (at most six) with
/// `view_proj[layer]`, `size × size` texels, concatenated layer after layer.
pub fn render_shadow_map(geometry: &Geometry, projection: &ShadowProjection) -> ShadowMap {
    let layers = projection.layers.min(6) as usize;
    let n = projection.size;
    let mut depth = Vec::with_capacity(layers * n as usize * n as usize);
    for vp in &projection.view_proj[..layers] {
        depth.extend(depth_only(geometry, *vp, DepthMode::Clip, n, n, projection.depth));
    }
    ShadowMap { projection: projection.clone(), depth }
}

/// Rasterizes the rectified shadow map that the `prefiltered` technique asks for (see
/// [`RectifiedRaster`] for the conventions): each region is drawn as its own viewport of
/// `columns[1] − columns[0]` × `height` texels at column `columns[0]`, with depth clamping: the
/// triangles are clipped against x and y only (and so to w > 0), not against the near and far
/// planes, and the interpolated depth is clamped to [0, 1] at each texel centre. Returns
/// `width × height` depths, row-major from the top-left texel, 1.0 where nothing was drawn.
/// Column ranges are clipped to `0..width`; an empty range draws nothing.
pub fn rasterize_rectified(geometry: &Geometry, request: &RectifiedRaster) -> Vec<f32> {
    let (w, h) = (request.width as usize, request.height as usize);
    let mut depth = vec![1.0f32; w * h];
    for region in &request.regions {
        let c0 = region.columns[0].min(request.width);
        let c1 = region.columns[1].min(request.width);
        if c1 <= c0 {
            continue;
        }
        let rw = (c1 - c0) as usize;
        let part = depth_only(
            geometry,
            region.view_proj,
            DepthMode::Clamp,
            rw as u32,
            request.height,
            DepthConvention::Standard,
        );
        // Overlapping regions keep the nearer depth, as the depth test of one GPU pass does.
        for (row, src) in depth.chunks_exact_mut(w).zip(part.chunks_exact(rw)) {
            for (d, &s) in row[c0 as usize..c1 as usize].iter_mut().zip(src) {
                *d = d.min(s);
            }
        }
    }
    depth
}
