//! What a technique reports about one frame.

use serde::Serialize;
use std::collections::BTreeMap;

/// Time of one pass.
#[derive(Clone, Debug, Serialize)]
pub struct PassTime {
    /// Pass label (the same label the GPU debugger shows).
    pub name: String,
    /// Milliseconds: GPU timestamps on hardware adapters, synchronised wall clock on software
    /// adapters and on the CPU.
    pub ms: f64,
}

/// Per-frame statistics of a technique.
#[derive(Clone, Debug, Default, Serialize)]
pub struct TechniqueStats {
    /// Technique name.
    pub technique: String,
    /// "gpu" or "cpu".
    pub backend: String,
    /// How the times were taken: "timestamp-queries", "wall-clock", or "off" (not taken:
    /// [`crate::StatsMode::Off`], every pass 0 ms).
    pub timing: String,
    /// Per-pass times, in order.
    pub passes: Vec<PassTime>,
    /// Number of ray-marched samples (shadow-map lookups along view rays) in the frame. Under
    /// [`crate::StatsMode::Off`] the samples only the GPU counts (epipolar's classified and
    /// re-marched pixels, subsampled's re-marched silhouette pixels) are not included.
    pub raymarched_samples: u64,
    /// Bytes of GPU memory the technique itself holds (buffers, textures, excluding the
    /// caller's inputs and output); 0 on the CPU.
    pub gpu_memory_bytes: u64,
    /// Technique-specific figures (e.g. the reference's convergence estimate).
    pub extra: BTreeMap<String, f64>,
}

impl TechniqueStats {
    /// Sum of the pass times, ms.
    pub fn total_ms(&self) -> f64 {
        self.passes.iter().map(|p| p.ms).sum()
    }
}
