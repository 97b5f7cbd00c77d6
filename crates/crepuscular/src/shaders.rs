//! WGSL sources. Shared code lives in `shaders/common.wgsl` and is composed with each pass
//! shader at build time by concatenation (`compose`): the shared module defines only
//! functions, structs and constants, and every pass declares its own bindings, so textual
//! composition is exact and needs no preprocessor. A test validates every composed shader
//! with naga without a GPU.

/// The shared module: frame uniforms, phase functions, lights, shadow lookups, integrand.
pub const COMMON: &str = include_str!("shaders/common.wgsl");

/// Prepends the shared module to a pass shader.
pub fn compose(pass: &str) -> String {
    format!("{COMMON}\n// ---- pass ----\n{pass}")
}

/// Every pass shader of the library, composed, with its name: for validation.
pub fn all_library_shaders() -> Vec<(&'static str, String)> {
    use crate::techniques::{brute_force, epipolar, interleaved, subsampled};
    let mut v = vec![("brute_force/march", compose(brute_force::MARCH_WGSL))];
    v.extend(interleaved::SHADERS.iter().map(|(n, s)| (*n, compose(s))));
    v.extend([
        ("subsampled/march", compose(subsampled::MARCH_WGSL)),
        ("subsampled/upsample", compose(subsampled::UPSAMPLE_WGSL)),
    ]);
    v.extend(epipolar::SHADERS.iter().map(|(n, s, _)| (*n, compose(&epipolar::pass_source(s)))));
    v.extend(crate::techniques::prefiltered::shaders().into_iter().map(|(n, s, _)| (n, compose(&s))));
    v.push(("epipolar/march_minmax", compose(&epipolar::march_minmax_source())));
    v.extend(crate::techniques::minmax::shaders().into_iter().map(|(n, s, _)| (n, compose(&s))));
    v.push(("composite", compose(crate::composite::COMPOSITE_WGSL)));
    v.push(("light_sum", compose(include_str!("shaders/light_sum.wgsl"))));
    v.push(("light_clear", compose(include_str!("shaders/light_clear.wgsl"))));
    v.push(("temporal", compose(crate::temporal::TEMPORAL_WGSL)));
    v
}

/// Mirrors `pcg_hash` in common.wgsl.
pub fn pcg_hash(v: u32) -> u32 {
    let state = v.wrapping_mul(747796405).wrapping_add(2891336453);
    let word = ((state >> ((state >> 28) + 4)) ^ state).wrapping_mul(277803737);
    (word >> 22) ^ word
}

/// 2³²/φ (φ the golden ratio), rounded to odd: the step of the additive recurrence
/// [`pixel_jitter`] walks from frame to frame.
pub const GOLDEN_STEP: u32 = 2654435769;

/// 2³²/g and 2³²/g² (g ≈ 1.3247, the plastic number: the 2D analogue of φ), rounded to odd:
/// the steps of the R2 sequence (Roberts 2018) [`pixel_jitter`] lays over the image, per pixel
/// to the right and per pixel down.
pub const R2_STEPS: [u32; 2] = [3242174889, 2447445413];

/// A pixel's jitter in frame `frame`, in [0, 1): {x/g + y/g² + frame/φ} (docs/MODEL.md §7), in
/// integers modulo 2³², so the GPU and the CPU agree exactly at any frame. Within a frame the
/// offsets are the R2 sequence over the pixels: spatially stratified, every 3×3 block of pixels
/// leaves no gap in [0, 1) wider than 0.185 (nine independent offsets: 0.32 on average, up to
/// 0.8), so a 3×3 mean of a jittered frame — the temporal stage's clip box and young-history
/// estimate — averages nine well-spread offsets instead of nine random ones. From frame to frame
/// a pixel's offsets are the golden-ratio sequence: any 8 consecutive frames leave no gap wider
/// than about 1.2/8 (independent offsets: 2.7/8 on average), so a running mean of the frames
/// converges like a stratified sample. Mirrors `pixel_jitter` in common.wgsl.
pub fn pixel_jitter(x: u32, y: u32, frame: u32) -> f32 {
    let h = x
        .wrapping_mul(R2_STEPS[0])
        .wrapping_add(y.wrapping_mul(R2_STEPS[1]))
        .wrapping_add(frame.wrapping_mul(GOLDEN_STEP));
    (h >> 8) as f32 * (1.0 / 16777216.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The widest gap, as a fraction of [0, 1) on the circle, between `n` sorted offsets.
    fn widest_gap(mut v: Vec<f32>) -> f32 {
        v.sort_by(f32::total_cmp);
        let wrap = 1.0 - v[v.len() - 1] + v[0];
        v.windows(2).map(|w| w[1] - w[0]).fold(wrap, f32::max)
    }

    #[test]
    fn consecutive_frames_of_a_pixel_are_low_discrepancy() {
        // The golden-ratio sequence's gaps take at most three lengths (the three-distance
        // theorem); for 8 consecutive terms the widest is under 1.2/8 wherever it starts.
        // Independent uniform offsets leave a widest gap of 2.7/8 on average.
        let mut worst: f32 = 0.0;
        for p in 0..2000u32 {
            let (x, y, start) = (p % 61, p / 61, pcg_hash(p) >> 4);
            let v: Vec<f32> = (0..8).map(|i| pixel_jitter(x, y, start.wrapping_add(i))).collect();
            assert!(v.iter().all(|j| (0.0..1.0).contains(j)), "{v:?}");
            worst = worst.max(widest_gap(v));
        }
        assert!(worst * 8.0 < 1.2, "widest gap of 8 frames {worst}");
    }

    #[test]
    fn every_3x3_block_of_a_frame_is_spread_over_the_unit_interval() {
        // The R2 sequence over the pixels: every 3×3 block's nine offsets leave no gap wider than
        // 0.185 (an even spread would leave 1/9 = 0.111), in any frame (the frame adds the same
        // to every pixel); nine independent uniform offsets leave 0.32 on average. And one frame
        // over a 64×64 block fills [0, 1) evenly: each of 16 bins holds 256 ± 10.
        let mut worst: f32 = 0.0;
        for frame in [0u32, 1, 7, 1000] {
            for y in 0..90 {
                for x in 0..160 {
                    let v: Vec<f32> = (0..9).map(|k| pixel_jitter(x + k % 3, y + k / 3, frame)).collect();
                    worst = worst.max(widest_gap(v));
                }
            }
        }
        assert!(worst < 0.186, "widest gap of a 3×3 block {worst}");
        let mut bins = [0u32; 16];
        for y in 0..64 {
            for x in 0..64 {
                bins[(pixel_jitter(x, y, 5) * 16.0) as usize] += 1;
            }
        }
        assert!(bins.iter().all(|&b| b.abs_diff(256) <= 10), "{bins:?}");
    }
}
