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
    /// Number of ray-marched samples (shadow-map tests along view rays; four texture reads each
    /// under [`crate::ShadowFilter::Bilinear`]) in the frame. Under
    /// [`crate::StatsMode::Off`] the samples only the GPU counts (epipolar's classified and
    /// re-marched pixels, subsampled's re-marched silhouette pixels) are not included.
    pub raymarched_samples: u64,
    /// Bytes of GPU memory the technique itself holds (buffers, textures, excluding the
    /// caller's inputs and output); 0 on the CPU.
    pub gpu_memory_bytes: u64,
    /// Technique-specific figures (e.g. the reference's convergence estimate).
    pub extra: BTreeMap<String, f64>,
}

impl PassTime {
    /// The passes with the same name added into one (at the first one's place): a frame's
    /// passes over all its lights, as a per-light technique records them once per light.
    pub fn merge(passes: Vec<PassTime>) -> Vec<PassTime> {
        let mut out: Vec<PassTime> = Vec::with_capacity(passes.len());
        for p in passes {
            match out.iter_mut().find(|q| q.name == p.name) {
                Some(q) => q.ms += p.ms,
                None => out.push(p),
            }
        }
        out
    }
}

impl TechniqueStats {
    /// No work: what a frame whose lights all miss the view reports.
    pub fn empty(technique: &str, backend: &str) -> Self {
        Self { technique: technique.into(), backend: backend.into(), ..Default::default() }
    }

    /// The stats of one frame rendered in parts (a per-light technique's runs, one per light):
    /// passes merged by name ([`PassTime::merge`]), samples, memory and every technique-specific
    /// figure added (counts over the lights). One part is returned as it is.
    pub fn sum(parts: Vec<TechniqueStats>) -> TechniqueStats {
        let mut it = parts.into_iter();
        let Some(mut total) = it.next() else { return TechniqueStats::default() };
        let mut passes = std::mem::take(&mut total.passes);
        for p in it {
            passes.extend(p.passes);
            total.raymarched_samples += p.raymarched_samples;
            total.gpu_memory_bytes += p.gpu_memory_bytes;
            for (k, v) in p.extra {
                *total.extra.entry(k).or_insert(0.0) += v;
            }
        }
        total.passes = PassTime::merge(passes);
        total
    }

    /// Sum of the pass times, ms.
    pub fn total_ms(&self) -> f64 {
        self.passes.iter().map(|p| p.ms).sum()
    }
}
