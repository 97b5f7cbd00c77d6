//! The techniques, one folder each: settings, GPU passes with their WGSL beside them, and
//! `cpu.rs`, the CPU mirror with the same sample placement and function names.

pub mod brute_force;
pub mod epipolar;
pub mod interleaved;
pub mod pass;
pub mod prefiltered;
pub mod presets;
pub mod reference;
pub mod subsampled;

/// What the tool and the docs list about a technique.
#[derive(Clone, Copy, Debug)]
pub struct TechniqueInfo {
    /// Name used on the command line and in scene files (`[render.<name>]`).
    pub name: &'static str,
    /// One line.
    pub summary: &'static str,
    /// The paper it implements.
    pub paper: &'static str,
    /// Runs on the GPU.
    pub gpu: bool,
    /// Runs on the CPU.
    pub cpu: bool,
}

/// Every technique, in the order the tool lists them.
pub const TECHNIQUES: &[TechniqueInfo] = &[
    TechniqueInfo {
        name: "brute-force",
        summary: "per-pixel ray marching through the shadow map, N steps per pixel (GPU + CPU mirror)",
        paper: "Tóth & Umenhoffer 2009, §3–4, eq. 1",
        gpu: true,
        cpu: true,
    },
    TechniqueInfo {
        name: "interleaved",
        summary: "M×M interleaved sampling: each pixel marches N/M² of the N steps, a separable (optionally depth-aware) block sum adds them (GPU + CPU mirror)",
        paper: "Tóth & Umenhoffer 2009, §4.1",
        gpu: true,
        cpu: true,
    },
    TechniqueInfo {
        name: "subsampled",
        summary: "ray marching on a reduced grid, joint-bilateral upsampling by depth, silhouette pixels re-marched at full resolution (GPU + CPU mirror)",
        paper: "the baseline of Engelhardt & Dachsbacher 2010 §6 / Fig. 9",
        gpu: true,
        cpu: true,
    },
    TechniqueInfo {
        name: "epipolar",
        summary: "epipolar sampling: ray-march samples on epipolar lines refined at depth discontinuities, interpolated along and bilaterally between the lines (GPU: lines, refine, indirect march over a compacted list, interpolate, upsample; CPU mirror)",
        paper: "Engelhardt & Dachsbacher 2010, §4–5",
        gpu: true,
        cpu: true,
    },
    TechniqueInfo {
        name: "prefiltered",
        summary: "filter-based single scattering: Fourier-expanded visibility on a rectified shadow map, prefix-summed per row with transmittance weights, one filtered lookup and dot product per pixel (GPU: rectify, prefilter, evaluate; CPU mirror)",
        paper: "Klehm, Seidel & Eisemann 2014, §3–5",
        gpu: true,
        cpu: true,
    },
    TechniqueInfo {
        name: "reference",
        summary: "ground truth: f64, many stratified steps per pixel over the same shadow map, with a convergence estimate (CPU only)",
        paper: "DESIGN.md §1 (the integral itself)",
        gpu: false,
        cpu: true,
    },
];

/// Looks a technique up by name.
pub fn find(name: &str) -> Option<&'static TechniqueInfo> {
    TECHNIQUES.iter().find(|t| t.name == name)
}
