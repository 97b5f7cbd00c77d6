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

/// Mirrors `pixel_jitter` in common.wgsl: uniform in [0, 1).
pub fn pixel_jitter(x: u32, y: u32, frame: u32) -> f32 {
    let h = pcg_hash(x ^ pcg_hash(y ^ pcg_hash(frame)));
    (h >> 8) as f32 * (1.0 / 16777216.0)
}
