//! What the debug views of `epipolar` need, on both backends: the lines and the line textures
//! of one frame ([`EpipolarDebug`], from [`super::cpu::render_with_debug`] or
//! [`super::Epipolar::read_debug`]), and the two views — the sample classification of
//! Engelhardt & Dachsbacher 2010, Fig. 9 bottom ([`classification_view`]) and the radiance
//! texture scaled up ([`radiance_view`]).

use super::{EpipolarLine, EpipolarParams, cpu};
use crate::image::Image;

/// One frame's epipolar lines and line textures (row k = line, column t = texel; index
/// k·samples + t).
#[derive(Clone, Debug, PartialEq)]
pub struct EpipolarDebug {
    /// The uniform block of the frame (settings, epipole, degenerate flag).
    pub params: EpipolarParams,
    /// The lines, `slices` of them.
    pub lines: Vec<EpipolarLine>,
    /// The coordinate texture: (p.x, p.y, view distance s of pixel ⌊p⌋, valid).
    pub coords: Vec<[f32; 4]>,
    /// The interpolation texture: left | right << 16 (left = right = t: a ray-march sample).
    pub interp: Vec<u32>,
    /// The radiance texture: in-scattering interpolated along the lines, s in alpha.
    pub radiance: Vec<[f32; 4]>,
}

/// How the refinement classified a texel.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TexelClass {
    /// On a culled line.
    Culled,
    /// Interpolated from the ray-march samples around it.
    Interpolated,
    /// An initial ray-march sample (evenly spaced, §4.1).
    Initial,
    /// A ray-march sample placed by the refinement at a depth discontinuity (§4.2) or on either
    /// side of the edge of the re-marched disc around the epipole (`epipole_radius`).
    Discontinuity,
}

impl EpipolarDebug {
    /// Number of lines.
    pub fn slices(&self) -> u32 {
        self.params.slices
    }
    /// Texels per line.
    pub fn samples(&self) -> u32 {
        self.params.samples
    }
    /// Index of texel (t, k).
    pub fn index(&self, t: u32, k: u32) -> usize {
        (k * self.params.samples + t) as usize
    }
    /// The class of texel (t, k).
    pub fn class(&self, t: u32, k: u32) -> TexelClass {
        let line = &self.lines[k as usize];
        if line.valid == 0 {
            return TexelClass::Culled;
        }
        let v = self.interp[self.index(t, k)];
        if (v & 0xffff, v >> 16) != (t, t) {
            return TexelClass::Interpolated;
        }
        let (a, b) = cpu::segment(&self.params, t, line.initial);
        if t == a || t == b { TexelClass::Initial } else { TexelClass::Discontinuity }
    }
    /// Counts of (initial, discontinuity) ray-march samples.
    pub fn sample_counts(&self) -> (u64, u64) {
        let mut n = (0, 0);
        for k in 0..self.slices() {
            for t in 0..self.samples() {
                match self.class(t, k) {
                    TexelClass::Initial => n.0 += 1,
                    TexelClass::Discontinuity => n.1 += 1,
                    _ => {}
                }
            }
        }
        n
    }
}

/// Colour of the faint line texels of [`classification_view`] (mixed in at 25 %).
pub const LINE_COLOUR: [f32; 3] = [0.6, 0.6, 0.6];
/// Colour of the initial ray-march samples.
pub const INITIAL_COLOUR: [f32; 3] = [1.0, 0.15, 0.1];
/// Colour of the discontinuity (refinement) samples — green, as in the paper's Fig. 9.
pub const DISCONTINUITY_COLOUR: [f32; 3] = [0.1, 1.0, 0.1];

/// The paper's Fig. 9 bottom: `background` (any image of the frame's size, linear; e.g. the
/// final radiance) with every valid line's texels drawn faint at their pixels, the initial
/// ray-march samples in red and the discontinuity samples in green (drawn last, on top).
/// Returns a linear image of the background's size.
pub fn classification_view(debug: &EpipolarDebug, background: &Image) -> Image {
    let mut img = background.clone();
    let (w, h) = (img.width, img.height);
    let mut put = |c: [f32; 4], colour: [f32; 3], alpha: f32| {
        let (x, y) = (c[0].floor(), c[1].floor());
        if x < 0.0 || y < 0.0 || x >= w as f32 || y >= h as f32 {
            return;
        }
        let px = &mut img.pixels[(y as u32 * w + x as u32) as usize];
        for i in 0..3 {
            px[i] = px[i] * (1.0 - alpha) + colour[i] * alpha;
        }
    };
    let mut marked = Vec::new();
    for k in 0..debug.slices() {
        for t in 0..debug.samples() {
            let c = debug.coords[debug.index(t, k)];
            match debug.class(t, k) {
                TexelClass::Culled => {}
                TexelClass::Interpolated => put(c, LINE_COLOUR, 0.25),
                class => marked.push((c, class)),
            }
        }
    }
    // Initial samples, then discontinuity samples on top.
    for want in [TexelClass::Initial, TexelClass::Discontinuity] {
        for &(c, class) in &marked {
            if class == want {
                let colour = if class == TexelClass::Initial { INITIAL_COLOUR } else { DISCONTINUITY_COLOUR };
                put(c, colour, 1.0);
            }
        }
    }
    img
}

/// The radiance texture (lines as rows, texels as columns; culled lines black) scaled up by
/// `scale` (nearest; 0 counts as 1): a linear image of (samples·scale) × (slices·scale).
pub fn radiance_view(debug: &EpipolarDebug, scale: u32) -> Image {
    let scale = scale.max(1);
    let (s, n) = (debug.samples(), debug.slices());
    let mut img = Image::new(s * scale, n * scale);
    for y in 0..n * scale {
        for x in 0..s * scale {
            let v = debug.radiance[debug.index(x / scale, y / scale)];
            img.pixels[(y * s * scale + x) as usize] = [v[0], v[1], v[2], 1.0];
        }
    }
    img
}
