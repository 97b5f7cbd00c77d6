//! Display transform: linear radiance → 8-bit sRGB, and the final composite of surface and
//! in-scattered light.
//!
//! The display transform is exposure, then the filmic curve of Krzysztof Narkowicz's ACES fit
//! ("ACES Filmic Tone Mapping Curve", 2015,
//! <https://knarkowicz.wordpress.com/2016/01/06/aces-filmic-tone-mapping-curve/>), then the sRGB
//! opto-electronic transfer function (IEC 61966-2-1), rounded to 8 bits. It is applied per
//! channel, exactly as in the original fit, so it is cheap, monotonic and deterministic.

use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::image::Image;

/// Exposure plus a filmic curve plus the sRGB encoding: how linear radiance becomes 8-bit pixels.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct ToneMap {
    /// Linear multiplier applied to radiance before the filmic curve (1.0 = unchanged, 2.0 = one
    /// stop brighter). The default is 1.0. A negative or non-finite exposure yields black.
    pub exposure: f32,
}

impl Default for ToneMap {
    fn default() -> Self {
        Self { exposure: 1.0 }
    }
}

impl ToneMap {
    /// A tone map with the given exposure multiplier.
    pub fn new(exposure: f32) -> Self {
        Self { exposure }
    }

    /// Display-referred value in `[0, 1]` (before the sRGB encoding) for one linear channel:
    /// exposure, then [`aces_narkowicz`]. Never NaN: NaN and negative inputs give 0, +∞ gives 1.
    pub fn curve(&self, linear: f32) -> f32 {
        aces_narkowicz(sanitize(linear * self.exposure))
    }

    /// Maps linear RGB radiance to 8-bit sRGB: exposure, the ACES fit, the sRGB OETF, rounding.
    ///
    /// NaN and negative channels map to 0, +∞ maps to 255; the result is never undefined.
    pub fn apply(&self, linear: [f32; 3]) -> [u8; 3] {
        linear.map(|c| quantize(srgb_oetf(self.curve(c))))
    }

    /// Tone-maps a whole image into tightly packed 8-bit RGB, row-major from the top left
    /// (`width * height * 3` bytes). Alpha is ignored.
    pub fn to_rgb8(&self, img: &Image) -> Vec<u8> {
        let mut out = vec![0u8; img.pixels.len() * 3];
        out.par_chunks_mut(3).zip(img.pixels.par_iter()).for_each(|(dst, p)| {
            dst.copy_from_slice(&self.apply([p[0], p[1], p[2]]));
        });
        out
    }
}

/// Replaces NaN and negative values (including −∞) by 0; keeps +∞ (which the curve maps to 1).
fn sanitize(x: f32) -> f32 {
    if x.is_nan() || x <= 0.0 { 0.0 } else { x }
}

/// Rounds a value in `[0, 1]` to 8 bits (values outside are clamped, NaN gives 0).
fn quantize(v: f32) -> u8 {
    if v.is_nan() {
        return 0;
    }
    (v.clamp(0.0, 1.0) * 255.0).round() as u8
}

/// Krzysztof Narkowicz's 2015 fit of the ACES filmic curve,
/// `x (2.51 x + 0.03) / (x (2.43 x + 0.59) + 0.14)`, clamped to `[0, 1]`.
///
/// Monotonic on `x ≥ 0`, `f(0) = 0`, and it saturates to 1 for `x ≳ 7.24`. NaN and negative
/// inputs give 0, +∞ gives 1. (The fit's usual 0.6 pre-exposure is left to [`ToneMap::exposure`].)
pub fn aces_narkowicz(x: f32) -> f32 {
    const A: f32 = 2.51;
    const B: f32 = 0.03;
    const C: f32 = 2.43;
    const D: f32 = 0.59;
    const E: f32 = 0.14;
    let x = sanitize(x);
    if x.is_infinite() {
        return 1.0;
    }
    // Beyond ~1e18 the squares overflow to ∞/∞; the curve has long saturated by then.
    if x > 1.0e6 {
        return 1.0;
    }
    ((x * (A * x + B)) / (x * (C * x + D) + E)).clamp(0.0, 1.0)
}

/// The sRGB opto-electronic transfer function (IEC 61966-2-1): linear `[0, 1]` → encoded
/// `[0, 1]`. The input is clamped to `[0, 1]`; NaN gives 0.
pub fn srgb_oetf(linear: f32) -> f32 {
    if linear.is_nan() {
        return 0.0;
    }
    let x = linear.clamp(0.0, 1.0);
    if x <= 0.003_130_8 { 12.92 * x } else { 1.055 * x.powf(1.0 / 2.4) - 0.055 }
}

/// The sRGB electro-optical transfer function, the inverse of [`srgb_oetf`]: encoded `[0, 1]` →
/// linear `[0, 1]`. The input is clamped to `[0, 1]`; NaN gives 0.
pub fn srgb_eotf(encoded: f32) -> f32 {
    if encoded.is_nan() {
        return 0.0;
    }
    let v = encoded.clamp(0.0, 1.0);
    if v <= 0.040_45 { v / 12.92 } else { ((v + 0.055) / 1.055).powf(2.4) }
}

/// Final composite `L = T · L_surface + L_scatt` per pixel and channel, with alpha 1.
///
/// `transmittance` holds the per-pixel RGB transmittance from the camera to the visible surface,
/// row-major like [`Image::pixels`].
///
/// # Panics
///
/// If the two images differ in size, or `transmittance` does not have one entry per pixel.
pub fn composite(surface: &Image, inscatter: &Image, transmittance: &[[f32; 3]]) -> Image {
    assert!(
        surface.width == inscatter.width && surface.height == inscatter.height,
        "composite: surface is {}x{} but in-scattering is {}x{}",
        surface.width,
        surface.height,
        inscatter.width,
        inscatter.height
    );
    assert_eq!(surface.pixels.len(), inscatter.pixels.len(), "composite: pixel counts differ");
    assert_eq!(
        transmittance.len(),
        surface.pixels.len(),
        "composite: transmittance has {} entries for {} pixels",
        transmittance.len(),
        surface.pixels.len()
    );
    let pixels = surface
        .pixels
        .par_iter()
        .zip(inscatter.pixels.par_iter())
        .zip(transmittance.par_iter())
        .map(|((s, l), t)| [t[0] * s[0] + l[0], t[1] * s[1] + l[1], t[2] * s[2] + l[2], 1.0])
        .collect();
    Image { width: surface.width, height: surface.height, pixels }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn grey(tm: &ToneMap, v: f32) -> u8 {
        let [r, g, b] = tm.apply([v, v, v]);
        assert!(r == g && g == b);
        r
    }

    #[test]
    fn zero_maps_to_zero() {
        assert_eq!(ToneMap::default().apply([0.0; 3]), [0, 0, 0]);
    }

    /// The curve's closed form, x (2.51 x + 0.03) / (x (2.43 x + 0.59) + 0.14), then the sRGB
    /// OETF 1.055·v^(1/2.4) − 0.055 (12.92·v below 0.0031308), ×255, rounded — evaluated by
    /// hand in f64: 0.18 → 0.266899 → 141.13, 1 → 0.803797 → 231.60, 0.01 → 0.0037703 →
    /// 12.27, 3 → 0.953743 → 249.74. Another curve (Reinhard's x/(1+x): 0.18 → 109) fails.
    #[test]
    fn the_curve_and_the_encoding_are_the_closed_forms() {
        for (x, curve) in [(0.18f32, 0.266_899_f32), (1.0, 0.803_797), (0.01, 0.003_770_3), (3.0, 0.953_743)] {
            let got = aces_narkowicz(x);
            assert!((got - curve).abs() < 2e-6, "ACES fit at {x}: {got}, closed form {curve}");
        }
        let tm = ToneMap::default();
        for (x, byte) in [(0.18f32, 141u8), (1.0, 232), (0.01, 12), (3.0, 250)] {
            assert_eq!(grey(&tm, x), byte, "{x} → 8-bit sRGB");
        }
        // Exposure multiplies before the curve: 0.09 at exposure 2 is 0.18.
        assert_eq!(grey(&ToneMap::new(2.0), 0.09), 141);
    }

    #[test]
    fn huge_maps_to_white() {
        let tm = ToneMap::default();
        assert_eq!(grey(&tm, 1.0e4), 255);
        assert_eq!(grey(&tm, 1.0e30), 255);
        assert_eq!(grey(&tm, f32::MAX), 255);
        assert_eq!(grey(&tm, f32::INFINITY), 255);
    }

    #[test]
    fn nan_negative_and_neg_infinity_map_to_black() {
        let tm = ToneMap::default();
        assert_eq!(tm.apply([f32::NAN, -1.0, f32::NEG_INFINITY]), [0, 0, 0]);
        assert_eq!(ToneMap::new(f32::NAN).apply([1.0; 3]), [0, 0, 0]);
        assert_eq!(ToneMap::new(0.0).apply([f32::INFINITY; 3]), [0, 0, 0]);
        assert!(!tm.curve(f32::NAN).is_nan());
    }

    #[test]
    fn monotonic() {
        let tm = ToneMap::default();
        let mut prev_u8 = 0u8;
        let mut prev_f = 0.0f32;
        for i in 0..=20_000 {
            let x = (i as f32 / 1000.0).powi(2); // 0 … 400
            let f = tm.curve(x);
            let q = grey(&tm, x);
            assert!(f >= prev_f, "curve not monotonic at {x}");
            assert!(q >= prev_u8, "8-bit output not monotonic at {x}");
            prev_f = f;
            prev_u8 = q;
        }
        assert_eq!(prev_u8, 255);
    }

    #[test]
    fn exposure_scales_input() {
        assert_eq!(ToneMap::new(2.0).apply([0.1; 3]), ToneMap::new(1.0).apply([0.2; 3]));
    }

    #[test]
    fn srgb_round_trip() {
        for i in 0..=255 {
            let v = i as f32 / 255.0;
            assert!((srgb_oetf(srgb_eotf(v)) - v).abs() < 1e-5);
        }
        assert_eq!(srgb_oetf(0.0), 0.0);
        assert!((srgb_oetf(1.0) - 1.0).abs() < 1e-6);
    }

    #[test]
    fn to_rgb8_matches_apply() {
        let mut img = Image::new(3, 2);
        img.pixels[1] = [0.18, 1.0, f32::NAN, 1.0];
        img.pixels[5] = [100.0, -3.0, 0.5, 0.0];
        let rgb = ToneMap::default().to_rgb8(&img);
        assert_eq!(rgb.len(), 18);
        for (i, p) in img.pixels.iter().enumerate() {
            assert_eq!(&rgb[i * 3..i * 3 + 3], &ToneMap::default().apply([p[0], p[1], p[2]]));
        }
    }

    #[test]
    fn composite_is_t_times_surface_plus_inscatter() {
        let mut surface = Image::new(2, 1);
        let mut inscatter = Image::new(2, 1);
        surface.pixels = vec![[1.0, 2.0, 4.0, 0.3], [8.0, 8.0, 8.0, 1.0]];
        inscatter.pixels = vec![[0.1, 0.2, 0.3, 0.5], [0.0, 0.0, 1.0, 1.0]];
        let t = [[0.5, 0.25, 0.0], [1.0, 0.0, 0.5]];
        let out = composite(&surface, &inscatter, &t);
        assert_eq!(out.width, 2);
        assert_eq!(out.height, 1);
        assert_eq!(out.pixels, vec![[0.6, 0.7, 0.3, 1.0], [8.0, 0.0, 5.0, 1.0]]);
    }

    #[test]
    #[should_panic]
    fn composite_rejects_wrong_transmittance_length() {
        let img = Image::new(2, 2);
        composite(&img, &img, &[[1.0; 3]; 3]);
    }
}
