//! Image comparison: RMSE and PSNR of linear radiance, FLIP of the tone-mapped images, and the
//! heat maps `crepuscular diff --heatmap` writes.

use anyhow::{Result, bail};
use crepuscular::Image;
use crepuscular::tonemap::{ToneMap, composite};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// How two images differ.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Metrics {
    /// Root-mean-square error over the R, G and B channels of every pixel, in linear radiance.
    /// Non-finite values in either image make it non-finite (serialised as `null`).
    pub rmse: f64,
    /// `20 · log10(peak / rmse)` in dB, where `peak` is the largest finite R, G or B value of the
    /// reference (1 when the reference has none above 0). Identical images give
    /// `f64::INFINITY`, which is serialised as JSON `null` (and `null` reads back as infinity).
    #[serde(with = "psnr_serde")]
    pub psnr_db: f64,
    /// Mean of NVIDIA's FLIP error map (0 = identical, 1 = maximal) between the tone-mapped 8-bit
    /// images, at FLIP's default 67 pixels per degree.
    pub flip_mean: f64,
    /// Largest absolute per-channel difference in linear radiance (NaN if any difference is NaN).
    pub max_abs: f64,
}

/// `psnr_db`: +∞ (identical images) ↔ JSON `null`; finite values as numbers.
pub(crate) mod psnr_serde {
    use serde::{Deserialize, Deserializer, Serializer};

    pub fn serialize<S: Serializer>(v: &f64, s: S) -> Result<S::Ok, S::Error> {
        if v.is_finite() { s.serialize_f64(*v) } else { s.serialize_none() }
    }

    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<f64, D::Error> {
        Ok(Option::<f64>::deserialize(d)?.unwrap_or(f64::INFINITY))
    }
}

/// A list of `psnr_db`s: each +∞ ↔ JSON `null`, as [`psnr_serde`].
pub(crate) mod psnr_vec_serde {
    use serde::Serializer;
    use serde::ser::SerializeSeq;

    pub fn serialize<S: Serializer>(v: &[f64], s: S) -> Result<S::Ok, S::Error> {
        let mut seq = s.serialize_seq(Some(v.len()))?;
        for x in v {
            seq.serialize_element(&x.is_finite().then_some(*x))?;
        }
        seq.end()
    }
}

/// Errors unless both images have the same, consistent, non-empty size.
fn check_sizes(reference: &Image, test: &Image) -> Result<()> {
    if reference.width != test.width || reference.height != test.height {
        bail!(
            "image sizes differ: reference is {}x{}, test is {}x{}",
            reference.width,
            reference.height,
            test.width,
            test.height
        );
    }
    for (what, img) in [("reference", reference), ("test", test)] {
        let n = img.width as usize * img.height as usize;
        if img.pixels.len() != n {
            bail!("{what} image claims {}x{} but holds {} pixels", img.width, img.height, img.pixels.len());
        }
    }
    if reference.pixels.is_empty() {
        bail!("cannot compare empty ({}x{}) images", reference.width, reference.height);
    }
    Ok(())
}

/// Peak signal value of the reference: its largest finite R, G or B value, or 1 when none is
/// above 0 (an all-black reference).
fn reference_peak(reference: &Image) -> f64 {
    let peak =
        reference.pixels.iter().flat_map(|p| &p[..3]).filter(|c| c.is_finite()).fold(0.0f32, |m, &c| m.max(c)) as f64;
    if peak > 0.0 { peak } else { 1.0 }
}

/// The FLIP error map (values in `[0, 1]`) between the tone-mapped images.
fn flip_error_map(reference: &Image, test: &Image, tone: &ToneMap) -> nv_flip::FlipImageFloat {
    let (w, h) = (reference.width, reference.height);
    let (ref_rgb, test_rgb) = rayon::join(|| tone.to_rgb8(reference), || tone.to_rgb8(test));
    nv_flip::flip(
        nv_flip::FlipImageRgb8::with_data(w, h, &ref_rgb),
        nv_flip::FlipImageRgb8::with_data(w, h, &test_rgb),
        nv_flip::DEFAULT_PIXELS_PER_DEGREE,
    )
}

/// Compares `test` against `reference`: RMSE, PSNR and largest difference of the linear
/// radiance (RGB only, alpha ignored), and the FLIP mean of the images tone-mapped with `tone`.
///
/// Errors when the sizes differ (naming both) or the images are empty. The result is
/// deterministic (fixed-order reduction).
pub fn compare(reference: &Image, test: &Image, tone: &ToneMap) -> Result<Metrics> {
    check_sizes(reference, test)?;
    const CHUNK: usize = 4096;
    // Per fixed-size chunk: (sum of squared differences, max |difference|); NaN propagates.
    let partials: Vec<(f64, f64)> = reference
        .pixels
        .par_chunks(CHUNK)
        .zip(test.pixels.par_chunks(CHUNK))
        .map(|(r, t)| {
            let mut sum = 0.0f64;
            let mut max = 0.0f64;
            for (pr, pt) in r.iter().zip(t) {
                for c in 0..3 {
                    let d = pr[c] as f64 - pt[c] as f64;
                    sum += d * d;
                    max = nan_max(max, d.abs());
                }
            }
            (sum, max)
        })
        .collect();
    let (sum, max_abs) = partials.iter().fold((0.0f64, 0.0f64), |(s, m), &(ps, pm)| (s + ps, nan_max(m, pm)));
    let rmse = (sum / (reference.pixels.len() * 3) as f64).sqrt();
    let psnr_db = if rmse == 0.0 { f64::INFINITY } else { 20.0 * (reference_peak(reference) / rmse).log10() };
    let error_map = flip_error_map(reference, test, tone);
    let flip_mean = nv_flip::FlipPool::from_image(&error_map).mean() as f64;
    Ok(Metrics { rmse, psnr_db, flip_mean, max_abs })
}

/// PSNR of `test` against `reference` over the pixels where `mask` is true (R, G and B), with
/// the whole reference's peak (as [`compare`]), so a region's PSNR reads on the frame's scale.
/// Errors when the sizes differ, the mask is not one entry per pixel, or it selects no pixel.
pub fn region_psnr(reference: &Image, test: &Image, mask: &[bool]) -> Result<f64> {
    check_sizes(reference, test)?;
    if mask.len() != reference.pixels.len() {
        bail!("region mask holds {} entries for {} pixels", mask.len(), reference.pixels.len());
    }
    let mut sum = 0.0f64;
    let mut n = 0usize;
    for ((r, t), _) in reference.pixels.iter().zip(&test.pixels).zip(mask).filter(|(_, m)| **m) {
        for c in 0..3 {
            let d = r[c] as f64 - t[c] as f64;
            sum += d * d;
        }
        n += 3;
    }
    if n == 0 {
        bail!("region mask selects no pixel");
    }
    let rmse = (sum / n as f64).sqrt();
    Ok(if rmse == 0.0 { f64::INFINITY } else { 20.0 * (reference_peak(reference) / rmse).log10() })
}

/// A frame's reference, for the quality figures `bench` and `animate` report: PSNR of the
/// linear in-scattering, FLIP of the tone-mapped final image.
pub struct Quality {
    /// The reference in-scattering.
    pub inscatter: Image,
    /// The reference final image (`composite` of the frame's surface and `inscatter`).
    pub final_radiance: Image,
    /// The frame's transmittance to the visible surface, per pixel.
    pub transmittance: Vec<[f32; 3]>,
    /// The display transform FLIP compares under.
    pub tone: ToneMap,
}

impl Quality {
    /// (PSNR of `inscatter` against the reference's in dB, FLIP mean of the final image it
    /// composites over `surface`).
    pub fn measure(&self, inscatter: &Image, surface: &Image) -> Result<(f64, f64)> {
        let lin = compare(&self.inscatter, inscatter, &self.tone)?;
        let fin = compare(&self.final_radiance, &composite(surface, inscatter, &self.transmittance), &self.tone)?;
        Ok((lin.psnr_db, fin.flip_mean))
    }
}

/// `max` that returns NaN when either operand is NaN.
fn nan_max(a: f64, b: f64) -> f64 {
    if a.is_nan() || b.is_nan() { f64::NAN } else { a.max(b) }
}

/// The FLIP error map between the tone-mapped images, coloured with FLIP's magma LUT: returns
/// `(width, height, rgb)` with `rgb` tightly packed 8-bit RGB, row-major from the top left.
///
/// Errors when the sizes differ (naming both) or the images are empty.
pub fn flip_heatmap(reference: &Image, test: &Image, tone: &ToneMap) -> Result<(u32, u32, Vec<u8>)> {
    check_sizes(reference, test)?;
    let error_map = flip_error_map(reference, test, tone);
    let coloured = error_map.apply_color_lut(&nv_flip::magma_lut());
    Ok((coloured.width(), coloured.height(), coloured.to_vec()))
}

/// Per-pixel absolute error heat map: the Rec. 709 luminance of the per-channel `|reference −
/// test|` (so opposite-signed channel errors do not cancel), divided by `full_scale` times the
/// reference peak (the peak as for PSNR; `full_scale` 1: an error as large as the peak is the
/// ramp's top, 0.05: 5 % of it is), clamped to `[0, 1]` and coloured with a magma-like ramp
/// (black → purple → orange → pale yellow). NaN or infinite differences show as the top of the
/// ramp.
///
/// Returns tightly packed 8-bit RGB of the images' size. Errors when the sizes differ or
/// `full_scale` is not finite and positive.
pub fn abs_error_heatmap(reference: &Image, test: &Image, full_scale: f64) -> Result<Vec<u8>> {
    check_sizes(reference, test)?;
    if !(full_scale.is_finite() && full_scale > 0.0) {
        bail!("error heat map: full scale {full_scale} must be finite and > 0");
    }
    let peak = reference_peak(reference) * full_scale;
    let mut out = vec![0u8; reference.pixels.len() * 3];
    out.par_chunks_mut(3).zip(reference.pixels.par_iter().zip(test.pixels.par_iter())).for_each(|(dst, (r, t))| {
        let d = |c: usize| (r[c] as f64 - t[c] as f64).abs();
        let y = 0.2126 * d(0) + 0.7152 * d(1) + 0.0722 * d(2);
        let v = if y.is_finite() { (y / peak).clamp(0.0, 1.0) } else { 1.0 };
        dst.copy_from_slice(&magma_ramp(v as f32));
    });
    Ok(out)
}

/// The magma ramp of the FLIP error maps and the nodes view (one copy, in the library).
pub use crepuscular::debug::magma_ramp;

#[cfg(test)]
mod tests {
    use super::*;

    /// A smooth colourful test image.
    fn gradient(w: u32, h: u32) -> Image {
        let mut img = Image::new(w, h);
        for y in 0..h {
            for x in 0..w {
                let (fx, fy) = (x as f32 / w as f32, y as f32 / h as f32);
                img.pixels[(y * w + x) as usize] = [fx * 2.0, fy, 0.5 * (fx + fy), 1.0];
            }
        }
        img
    }

    fn filled(w: u32, h: u32, v: f32) -> Image {
        Image { width: w, height: h, pixels: vec![[v, v, v, 1.0]; (w * h) as usize] }
    }

    #[test]
    fn identical_images_have_zero_error() {
        let img = gradient(32, 24);
        let m = compare(&img, &img, &ToneMap::default()).unwrap();
        assert_eq!(m.rmse, 0.0);
        assert_eq!(m.max_abs, 0.0);
        assert_eq!(m.flip_mean, 0.0);
        assert_eq!(m.psnr_db, f64::INFINITY);
    }

    #[test]
    fn known_offset_gives_known_rmse_and_psnr() {
        let reference = filled(16, 8, 0.5);
        let test = filled(16, 8, 0.6);
        let m = compare(&reference, &test, &ToneMap::default()).unwrap();
        assert!((m.rmse - 0.1).abs() < 1e-6, "{}", m.rmse);
        assert!((m.max_abs - 0.1).abs() < 1e-6, "{}", m.max_abs);
        // peak 0.5, RMSE 0.1 → 20·log10(5)
        assert!((m.psnr_db - 20.0 * 5f64.log10()).abs() < 1e-4, "{}", m.psnr_db);
        assert!(m.flip_mean > 0.0 && m.flip_mean < 1.0, "{}", m.flip_mean);
    }

    #[test]
    fn offset_in_one_channel_only() {
        let reference = filled(4, 4, 0.25);
        let mut test = reference.clone();
        for p in &mut test.pixels {
            p[1] += 0.3;
            p[3] = 0.0; // alpha is ignored
        }
        let m = compare(&reference, &test, &ToneMap::default()).unwrap();
        assert!((m.rmse - (0.09f64 / 3.0).sqrt()).abs() < 1e-6, "{}", m.rmse);
    }

    #[test]
    fn region_psnr_counts_only_the_masked_pixels_with_the_frames_peak() {
        let mut r = Image::new(2, 1);
        r.pixels = vec![[0.5, 0.5, 0.5, 1.0], [0.1, 0.1, 0.1, 1.0]];
        let mut t = r.clone();
        t.pixels[1] = [0.2, 0.2, 0.2, 1.0];
        // Only pixel 1 differs, by 0.1 on each channel; the peak is the frame's, 0.5.
        let p = region_psnr(&r, &t, &[false, true]).unwrap();
        assert!((p - 20.0 * 5f64.log10()).abs() < 1e-5, "{p}");
        assert_eq!(region_psnr(&r, &t, &[true, false]).unwrap(), f64::INFINITY);
        assert!(region_psnr(&r, &t, &[false, false]).is_err());
        assert!(region_psnr(&r, &t, &[true]).is_err());
    }

    #[test]
    fn all_black_reference_uses_peak_one() {
        let reference = filled(8, 8, 0.0);
        let test = filled(8, 8, 0.01);
        let m = compare(&reference, &test, &ToneMap::default()).unwrap();
        assert!((m.psnr_db - 40.0).abs() < 1e-3, "{}", m.psnr_db);
    }

    #[test]
    fn size_mismatch_is_an_error_naming_both_sizes() {
        let a = filled(8, 4, 0.5);
        let b = filled(4, 8, 0.5);
        let msg = compare(&a, &b, &ToneMap::default()).unwrap_err().to_string();
        assert!(msg.contains("8x4") && msg.contains("4x8"), "{msg}");
        assert!(flip_heatmap(&a, &b, &ToneMap::default()).is_err());
        assert!(abs_error_heatmap(&a, &b, 1.0).is_err());
    }

    #[test]
    fn nan_in_test_is_reported_not_hidden() {
        let reference = filled(4, 4, 0.5);
        let mut test = reference.clone();
        test.pixels[5][0] = f32::NAN;
        let m = compare(&reference, &test, &ToneMap::default()).unwrap();
        assert!(m.rmse.is_nan() && m.max_abs.is_nan());
        assert!(m.flip_mean.is_finite());
    }

    #[test]
    fn psnr_infinity_serialises_as_null_and_back() {
        let m = Metrics { rmse: 0.0, psnr_db: f64::INFINITY, flip_mean: 0.0, max_abs: 0.0 };
        let json = serde_json::to_string(&m).unwrap();
        assert!(json.contains("\"psnr_db\":null"), "{json}");
        let back: Metrics = serde_json::from_str(&json).unwrap();
        assert_eq!(back, m);
        let finite = Metrics { psnr_db: 42.5, ..m };
        let back: Metrics = serde_json::from_str(&serde_json::to_string(&finite).unwrap()).unwrap();
        assert_eq!(back, finite);
    }

    #[test]
    fn heatmaps_have_the_right_size_and_are_dark_for_identical_images() {
        let img = gradient(20, 10);
        let (w, h, rgb) = flip_heatmap(&img, &img, &ToneMap::default()).unwrap();
        assert_eq!((w, h, rgb.len()), (20, 10, 600));
        let lut0 = nv_flip::magma_lut().to_vec();
        assert!(rgb.chunks(3).all(|p| p == &lut0[..3]));
        let abs = abs_error_heatmap(&img, &img, 1.0).unwrap();
        assert_eq!(abs.len(), 600);
        assert!(abs.chunks(3).all(|p| p == [0, 0, 4]));
        let mut test = img.clone();
        test.pixels[0] = [1.0e9, 1.0e9, 1.0e9, 1.0];
        let abs = abs_error_heatmap(&img, &test, 1.0).unwrap();
        assert_eq!(&abs[..3], &[252, 253, 191]);
    }

    #[test]
    fn magma_ramp_is_monotonic_in_brightness() {
        let mut prev = -1.0f32;
        for i in 0..=256 {
            let [r, g, b] = magma_ramp(i as f32 / 256.0);
            let y = 0.2126 * r as f32 + 0.7152 * g as f32 + 0.0722 * b as f32;
            assert!(y >= prev - 0.5, "ramp not monotonic at {i}");
            prev = y;
        }
        assert_eq!(magma_ramp(0.0), [0, 0, 4]);
        assert_eq!(magma_ramp(1.0), [252, 253, 191]);
        assert_eq!(magma_ramp(f32::NAN), [252, 253, 191]);
    }
}
