//! Technique `interleaved`: ray marching with interleaved sampling (Tóth & Umenhoffer 2009,
//! §4.1), three compute passes, and its CPU mirror in `cpu.rs`.
//!
//! The N terms of eq. 1 along a view ray are independent (§3: "the consecutive samples of the
//! summation are independent"), so §4.1 spreads them over M×M pixel blocks: pixel (x, y)
//! evaluates only the terms i ≡ k (mod M²), k = (y mod M)·M + (x mod M), on its own view ray
//! (pass `march`, about N/M² terms per pixel), and a separable box sum adds the contributions
//! of M×M neighbours back together — M horizontally (pass `sum_rows`), then M vertically
//! (pass `sum_columns`) — so each pixel ends up with all N terms, borrowed from rays that are
//! "lying approximately on the same view ray".
//!
//! Choices beyond the paper, all documented at the settings:
//! - **Sliding window.** The paper sums within fixed M×M blocks, which makes the image blocky
//!   (every pixel of a block gets the same value). Here every pixel sums the M×M window around
//!   it; since the pattern is periodic, every M×M window holds each offset k exactly once. At
//!   the image borders the window is shifted inward (start = clamp(x − ⌊M/2⌋, 0, W − M)), so
//!   it is still complete. An image narrower or lower than M covers only some offsets; the sum
//!   is then renormalised (below).
//! - **Renormalisation by terms.** Each pass carries (sum, terms), where terms counts the eq.-1
//!   terms the added pixels evaluated (offset k evaluates ⌈(N − k)/M²⌉ of them, so offsets differ
//!   by one when M² ∤ N); the result is sum·N/terms. A complete window has terms = N exactly and
//!   the factor is 1. With M² | N this is the M²/(pixels added) of the usual formulation.
//! - **Depth awareness** (`depth_aware`, default on). Near silhouettes the neighbours' rays end
//!   on other surfaces and are not "approximately the same view ray"; their terms would leak
//!   shafts across edges. A neighbour is added only when its view distance is within
//!   `depth_tolerance` (relative) of the centre's, and the sum is renormalised as above. In
//!   the separable form each row-pass neighbour is compared against the row pass's own centre
//!   (x, y′), and the column pass compares (x, y′) against (x, y) — the usual separable
//!   bilateral approximation: a neighbour (x′, y′) is added when it matches (x, y′) and (x, y′)
//!   matches (x, y).
//! - **Phase lookup table** (`phase_lut`, default off): §4 notes that "complicated phase
//!   functions like the Henyey-Greenstein phase function can be stored in a lookup table, and
//!   fetched by a single texture read". [`PhaseLut`] tabulates the medium's phase function (any
//!   kind; RGB for Hoffman–Preetham) over u = sin(θ/2) = √((1 − cos θ)/2), which puts table
//!   resolution near the forward peak (near the backward one, u = cos(θ/2), when g < 0), and
//!   the march pass interpolates it linearly; the table's measured error is reported as
//!   `phase_lut_max_rel_error`.
//!
//! Each step's weight is the transmittance integrated exactly over the step, as in
//! `brute-force` (`march_steps`), so with M = 1 this technique is `brute-force` exactly.

pub mod cpu;

use crate::error::Error;
use crate::frame::GpuFrame;
use crate::gpu::{GpuContext, Recorder};
use crate::march::{MarchSettings, StepPolicy};
use crate::model::Phase;
use crate::stats::TechniqueStats;
use crate::techniques::pass::{self, Bound, Pass};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

/// The march pass shader (composed with common.wgsl).
pub const MARCH_WGSL: &str = include_str!("march.wgsl");
/// The horizontal sum pass shader (composed with common.wgsl).
pub const SUM_ROWS_WGSL: &str = include_str!("sum_rows.wgsl");
/// The vertical sum pass shader (composed with common.wgsl).
pub const SUM_COLUMNS_WGSL: &str = include_str!("sum_columns.wgsl");

/// The pass shaders with their names, for validation: (`interleaved/<pass>`, source).
pub const SHADERS: [(&str, &str); 3] = [
    ("interleaved/march", MARCH_WGSL),
    ("interleaved/sum_rows", SUM_ROWS_WGSL),
    ("interleaved/sum_columns", SUM_COLUMNS_WGSL),
];

/// Settings of `interleaved` (`[render.interleaved]` in a scene file).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct InterleavedSettings {
    /// Block size M, pixels: the N terms are spread over M×M pixels (Tóth & Umenhoffer 2009,
    /// §4.1). Each pixel marches ⌈N/M²⌉ (or ⌊N/M²⌋) terms, so the march costs ~1/M² of
    /// `brute-force`'s; the two sum passes cost M texture loads per pixel each. Larger M blurs
    /// thin shafts and shadow edges over M pixels. The sum window runs from x − ⌊M/2⌋ to
    /// x − ⌊M/2⌋ + M − 1: centred for odd M, half a pixel up and left for even M (a first-order
    /// error where the in-scattering changes fast, e.g. near the sun with a strongly forward
    /// phase function). 1 is `brute-force`. Must be in 1..=16. Default 4.
    pub block: u32,
    /// How the view rays are marched ([`MarchSettings`], flattened: the keys `steps`, `jitter`, `frame_index`). `steps` is the total N
    /// per view ray (eq. 1), shared among the M² pixels of a window, so the march costs N/M²
    /// per pixel (4 terms at the default 64 and M = 4); `jitter` offsets each aligned M×M
    /// block's samples by one value.
    #[serde(flatten)]
    pub ray_march: MarchSettings,
    /// Where the steps go for spot and point lights ([`StepPolicy`], flattened: the keys
    /// `spot_steps`, `spot_denominator`, `local_steps`).
    #[serde(flatten)]
    pub policy: StepPolicy,
    /// Only add neighbours whose view distance is within `depth_tolerance` of the centre
    /// pixel's, and renormalise (see the module docs). Keeps shafts from leaking across
    /// silhouettes at the cost of fewer terms (more banding) there; costs one comparison per
    /// load. Default true.
    pub depth_aware: bool,
    /// Relative view-distance tolerance of `depth_aware`: a neighbour at distance s′ is added
    /// when |s′ − s| ≤ tolerance·s. Dimensionless, ≥ 0. Default 0.1.
    pub depth_tolerance: f32,
    /// Read the phase function from a lookup table (§4's suggestion for Henyey–Greenstein)
    /// instead of evaluating it: one storage-buffer read and a lerp per term instead of a
    /// `pow`-like evaluation. The table is rebuilt when the medium's phase function changes
    /// (`phase_lut_size` evaluations on the CPU, an upload of 16 bytes per entry). Its error is
    /// reported as `phase_lut_max_rel_error`. Default false.
    pub phase_lut: bool,
    /// Entries of the phase table, uniform in u = sin(θ/2) (cos(θ/2) for a backward-peaked
    /// phase function, g < 0; see [`PhaseLut`]). Interpolation error falls as
    /// 1/size² (about 0.2 % for HG g = 0.9 at 256). Memory 16 bytes per entry. Must be in
    /// 2..=65536. Default 256.
    pub phase_lut_size: u32,
}

impl Default for InterleavedSettings {
    fn default() -> Self {
        Self {
            block: 4,
            ray_march: MarchSettings::default(),
            policy: StepPolicy::default(),
            depth_aware: true,
            depth_tolerance: 0.1,
            phase_lut: false,
            phase_lut_size: 256,
        }
    }
}

impl InterleavedSettings {
    /// Checks the ranges.
    pub fn validate(&self) -> Result<(), Error> {
        if !(1..=16).contains(&self.block) {
            return Err(Error::invalid("interleaved.block", self.block, "must be in 1..=16"));
        }
        if !(self.depth_tolerance.is_finite() && self.depth_tolerance >= 0.0) {
            return Err(Error::invalid("interleaved.depth_tolerance", self.depth_tolerance, "must be finite and >= 0"));
        }
        if !(2..=65536).contains(&self.phase_lut_size) {
            return Err(Error::invalid("interleaved.phase_lut_size", self.phase_lut_size, "must be in 2..=65536"));
        }
        self.ray_march.validate("interleaved")?;
        self.policy.validate("interleaved")
    }

    /// The block offset k = (y mod M)·M + (x mod M) of pixel (x, y) (§4.1). Mirrors
    /// `block_offset` in the WGSL.
    pub fn block_offset(&self, x: u32, y: u32) -> u32 {
        let m = self.block;
        (y % m) * m + (x % m)
    }

    /// Number of eq.-1 terms a pixel of block offset `k` evaluates: i = k, k + M², … < N.
    pub fn terms_of_offset(&self, k: u32) -> u32 {
        let m2 = self.block * self.block;
        if k < self.ray_march.steps { (self.ray_march.steps - k).div_ceil(m2) } else { 0 }
    }

    /// Σ over the pixels of a `width`×`height` image of the terms each evaluates: the frame's
    /// ray-marched samples, exactly.
    pub fn raymarched_samples(&self, width: u32, height: u32) -> u64 {
        let m = self.block;
        // Pixels with x mod M = r: ⌈(W − r)/M⌉ for r < W.
        let count = |size: u32, r: u32| if r < size { (size - r).div_ceil(m) as u64 } else { 0 };
        let mut total = 0u64;
        for ky in 0..m {
            for kx in 0..m {
                total += count(width, kx) * count(height, ky) * self.terms_of_offset(ky * m + kx) as u64;
            }
        }
        total
    }

    /// The technique-specific figures of [`TechniqueStats::extra`].
    pub fn extra_stats(&self, lut_error: Option<f64>) -> BTreeMap<String, f64> {
        let mut extra = BTreeMap::new();
        extra.insert("block".into(), self.block as f64);
        extra.insert("steps".into(), self.ray_march.steps as f64);
        if let Some(e) = lut_error {
            extra.insert("phase_lut_max_rel_error".into(), e);
        }
        extra
    }
}

/// The uniform block of all three passes (`struct Params` in march.wgsl, sum_rows.wgsl and
/// sum_columns.wgsl, identical in each).
#[repr(C)]
#[derive(Clone, Copy, Debug, bytemuck::Pod, bytemuck::Zeroable)]
pub struct InterleavedParams {
    /// Block size M.
    pub block: u32,
    /// Total steps N.
    pub steps: u32,
    /// [`crate::march::StepPolicy::code`]: the spot policy and the equiangular bit.
    pub spot_steps: u32,
    /// App. B denominator.
    pub spot_denominator: f32,
    /// 1 to jitter per block.
    pub jitter: u32,
    /// Jitter seed.
    pub frame_index: u32,
    /// 1 for the depth-aware sums.
    pub depth_aware: u32,
    /// Relative view-distance tolerance.
    pub depth_tolerance: f32,
    /// 1 to read the phase function from the table.
    pub phase_lut: u32,
    /// Entries of the table.
    pub phase_lut_size: u32,
    /// Padding to a multiple of 16 bytes.
    pub _pad: [u32; 2],
}

const _: () = assert!(std::mem::size_of::<InterleavedParams>().is_multiple_of(16));

impl From<&InterleavedSettings> for InterleavedParams {
    fn from(s: &InterleavedSettings) -> Self {
        Self {
            block: s.block,
            steps: s.ray_march.steps,
            spot_steps: s.policy.code(),
            spot_denominator: s.policy.denominator,
            jitter: s.ray_march.jitter as u32,
            frame_index: s.ray_march.frame_index,
            depth_aware: s.depth_aware as u32,
            depth_tolerance: s.depth_tolerance,
            phase_lut: s.phase_lut as u32,
            phase_lut_size: s.phase_lut_size,
            _pad: [0; 2],
        }
    }
}

/// A phase-function lookup table (Tóth & Umenhoffer 2009, §4: "complicated phase functions …
/// can be stored in a lookup table"): `size` RGB entries at u_i = i/(size − 1), where
/// u = sin(θ/2) = √((1 − cos θ)/2), i.e. cos θ = 1 − 2u². Uniform steps in u are steps of
/// ~θ/2 near the forward peak (θ = 0) where Henyey–Greenstein varies fastest, and coarser
/// steps of cos θ in the flat backward half. A phase function peaked backwards (asymmetry
/// g < 0) is tabulated from the other end, u = cos(θ/2) = √((1 + cos θ)/2): the sign
/// σ = −1 below, which the shader derives from the same g in the frame uniforms. Looked up
/// with linear interpolation ([`cpu::phase_lut`], `phase_lut` in march.wgsl).
#[derive(Clone, Debug, PartialEq)]
pub struct PhaseLut {
    /// The phase function tabulated.
    pub phase: Phase,
    /// σ: +1 when the table starts at θ = 0 (u = √((1 − cos θ)/2)), −1 when it starts at
    /// θ = π (u = √((1 + cos θ)/2)), for g < 0.
    pub sign: f32,
    /// p(cos θ_i) per RGB channel (alpha 0), evaluated in f64 and rounded to f32.
    pub entries: Vec<[f32; 4]>,
    /// Largest relative error of the interpolated table against the analytic phase function
    /// (f64), over a dense grid: 8193 points uniform in cos θ and 64·size + 1 uniform in u,
    /// every channel.
    pub max_rel_error: f64,
}

impl PhaseLut {
    /// Tabulates `phase` with `size` (≥ 2) entries and measures the table's error.
    pub fn new(phase: &Phase, size: u32) -> Self {
        let size = size.max(2);
        let sign = Self::sign_of(phase);
        let entries = (0..size)
            .map(|i| {
                let u = i as f64 / (size - 1) as f64;
                let p = phase.eval_f64(sign as f64 * (1.0 - 2.0 * u * u));
                [p[0] as f32, p[1] as f32, p[2] as f32, 0.0]
            })
            .collect();
        let mut lut = Self { phase: *phase, sign, entries, max_rel_error: 0.0 };
        let dense_c = 8192u32;
        let dense_u = 64 * size;
        let cos_grid = (0..=dense_c).map(|i| (-1.0 + 2.0 * i as f64 / dense_c as f64) as f32);
        let u_grid = (0..=dense_u).map(|i| {
            let u = i as f64 / dense_u as f64;
            (sign as f64 * (1.0 - 2.0 * u * u)) as f32
        });
        let mut worst = 0.0f64;
        for c in cos_grid.chain(u_grid) {
            let got = cpu::phase_lut(&lut, c);
            let exact = phase.eval_f64(c as f64);
            for ch in 0..3 {
                let e = (got[ch] as f64 - exact[ch]).abs() / exact[ch].abs().max(1e-30);
                worst = worst.max(e);
            }
        }
        lut.max_rel_error = worst;
        lut
    }

    /// σ of a phase function: −1 when its asymmetry g (as the shader sees it, `sigma_s.w` of
    /// the frame uniforms) is negative, else +1.
    pub fn sign_of(phase: &Phase) -> f32 {
        if phase.gpu_params().1 < 0.0 { -1.0 } else { 1.0 }
    }

    /// Number of entries.
    pub fn size(&self) -> u32 {
        self.entries.len() as u32
    }
}

/// The textures between the passes, sized to the frame.
struct Targets {
    width: u32,
    height: u32,
    march: wgpu::Texture,
    rows: wgpu::Texture,
    march_view: wgpu::TextureView,
    rows_view: wgpu::TextureView,
}

/// The phase table on the GPU, with the key it was built for.
struct GpuLut {
    phase: Phase,
    size: u32,
    buffer: wgpu::Buffer,
    max_rel_error: f64,
}

/// The GPU side of `interleaved`: three passes, their uniform buffers, the intermediate
/// textures (reallocated only when the frame size changes) and the phase table (rebuilt only
/// when the phase function or table size changes).
pub struct Interleaved {
    /// Current settings; changes apply on the next `Interleaved::encode`.
    pub settings: InterleavedSettings,
    march: Pass,
    rows: Pass,
    columns: Pass,
    buffers: pass::FrameBuffers,
    params_buffer: wgpu::Buffer,
    white: wgpu::TextureView,
    no_lut: wgpu::Buffer,
    lut: Option<GpuLut>,
    targets: Option<Targets>,
    /// The partial sums' format ([`pass::intermediate_format`]).
    inter: wgpu::TextureFormat,
    binds: pass::BindCache<[wgpu::BindGroup; 3]>,
}

impl Interleaved {
    /// Builds the three passes.
    pub(crate) fn new(
        gpu: &GpuContext,
        settings: InterleavedSettings,
        output: wgpu::TextureFormat,
    ) -> Result<Self, Error> {
        settings.validate()?;
        gpu.try_scoped("creating the interleaved pipelines", || {
            let device = &gpu.device;
            let inter = pass::intermediate_format(output);
            let march = Pass::new(device, "interleaved/march", &pass::with_output(MARCH_WGSL, inter), "march")?;
            let rows = Pass::new(device, "interleaved/sum_rows", &pass::with_output(SUM_ROWS_WGSL, inter), "sum_rows")?;
            let columns = Pass::new(
                device,
                "interleaved/sum_columns",
                &pass::with_output(SUM_COLUMNS_WGSL, output),
                "sum_columns",
            )?;
            let buffers = pass::FrameBuffers::new(device);
            let params_buffer =
                pass::uniform_buffer(device, "interleaved params", std::mem::size_of::<InterleavedParams>() as u64);
            let no_lut = device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("interleaved phase table (unused)"),
                size: 16,
                usage: wgpu::BufferUsages::STORAGE,
                mapped_at_creation: false,
            });
            let white = pass::white_array(gpu);
            Ok(Self {
                settings,
                march,
                rows,
                columns,
                buffers,
                params_buffer,
                white,
                no_lut,
                lut: None,
                targets: None,
                inter,
                binds: Default::default(),
            })
        })
    }

    /// Bytes of GPU memory this technique holds: uniforms, the 1×1 white spot texture, the
    /// phase table, and the two intermediate textures (16 bytes per pixel each, 8 when the
    /// output is `Rgba16Float`).
    pub fn gpu_memory_bytes(&self) -> u64 {
        let texel = pass::texel_bytes(self.inter);
        let targets = self.targets.as_ref().map_or(0, |t| 2 * texel * t.width as u64 * t.height as u64);
        let lut = self.lut.as_ref().map_or(0, |l| l.buffer.size());
        self.buffers.size() + self.params_buffer.size() + 16 + self.no_lut.size() + lut + targets
    }

    /// The march pass's output of the last render (rgb: the pixel's own terms; alpha: its view
    /// distance s), for tests and debugging. None before the first render.
    pub fn march_texture(&self) -> Option<&wgpu::Texture> {
        self.targets.as_ref().map(|t| &t.march)
    }

    /// The row pass's output of the last render (rgb: the sum over the row window; alpha: the
    /// number of eq.-1 terms in it). None before the first render.
    pub fn rows_texture(&self) -> Option<&wgpu::Texture> {
        self.targets.as_ref().map(|t| &t.rows)
    }

    fn ensure_targets(&mut self, gpu: &GpuContext, width: u32, height: u32) -> Result<(), Error> {
        if self.targets.as_ref().is_some_and(|t| t.width == width && t.height == height) {
            return Ok(());
        }
        gpu.check_texture_size("image size", width, height)?;
        self.targets = None;
        let targets = gpu.scoped("allocating the interleaved textures", || {
            let tex = |label| crate::gpu::storage_texture(&gpu.device, label, self.inter, width, height);
            let march = tex("interleaved march");
            let rows = tex("interleaved rows");
            let march_view = march.create_view(&Default::default());
            let rows_view = rows.create_view(&Default::default());
            Targets { width, height, march, rows, march_view, rows_view }
        })?;
        self.targets = Some(targets);
        Ok(())
    }

    /// Builds (or reuses) the phase table for `phase`; returns its measured error.
    fn ensure_lut(&mut self, gpu: &GpuContext, phase: &Phase) -> Result<f64, Error> {
        let size = self.settings.phase_lut_size;
        if let Some(l) = &self.lut
            && l.phase == *phase
            && l.size == size
        {
            return Ok(l.max_rel_error);
        }
        let table = PhaseLut::new(phase, size);
        let buffer = gpu.scoped("uploading the interleaved phase table", || {
            let b = gpu.device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("interleaved phase table"),
                size: size as u64 * 16,
                usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            });
            gpu.queue.write_buffer(&b, 0, bytemuck::cast_slice(&table.entries));
            b
        })?;
        self.lut = Some(GpuLut { phase: *phase, size, buffer, max_rel_error: table.max_rel_error });
        Ok(table.max_rel_error)
    }

    /// Records the in-scattering of `frame` into `output` (an `Rgba32Float` storage view of
    /// the frame's size) through `rec`. Pass list: `march`, `sum_rows`, `sum_columns`.
    pub(crate) fn encode(
        &mut self,
        gpu: &GpuContext,
        rec: &mut Recorder,
        frame: &GpuFrame,
        output: &wgpu::TextureView,
    ) -> Result<TechniqueStats, Error> {
        self.settings.validate()?;
        let desc = frame.desc;
        self.ensure_targets(gpu, desc.width, desc.height)?;
        let lut_error = if self.settings.phase_lut { Some(self.ensure_lut(gpu, &desc.medium.phase)?) } else { None };
        self.buffers.write(rec, desc);
        rec.write_buffer(&self.params_buffer, bytemuck::bytes_of(&InterleavedParams::from(&self.settings)));
        let targets = self.targets.as_ref().expect("allocated above");
        let lut = match (&self.lut, self.settings.phase_lut) {
            (Some(l), true) => &l.buffer,
            _ => &self.no_lut,
        };
        let mut key = pass::frame_key(frame, output);
        key.extend([Bound::View(targets.march_view.clone()), Bound::Buffer(lut.clone())]);
        if !self.binds.is_current(&key) {
            let binds = gpu.try_scoped("binding the interleaved inputs", || {
                let device = &gpu.device;
                let view = wgpu::BindingResource::TextureView;
                let march = pass::with(
                    pass::frame_resources(&self.buffers, &self.params_buffer, frame, &self.white),
                    [("lut", lut.as_entire_binding()), ("out_tex", view(&targets.march_view))],
                );
                let uniforms = pass::uniform_resources(&self.buffers, &self.params_buffer);
                let rows = [("march_tex", view(&targets.march_view)), ("out_tex", view(&targets.rows_view))];
                let columns = [
                    ("rows_tex", view(&targets.rows_view)),
                    ("march_tex", view(&targets.march_view)),
                    ("out_tex", view(output)),
                ];
                Ok([
                    self.march.bind(device, &march)?,
                    self.rows.bind(device, &[&uniforms[..], &rows].concat())?,
                    self.columns.bind(device, &[&uniforms[..], &columns].concat())?,
                ])
            })?;
            self.binds.store(key, binds);
        }
        let [march_bind, rows_bind, columns_bind] = self.binds.value();
        let groups = self.march.groups_2d(desc.width, desc.height);
        let variant = frame.shader_variant();
        self.march.dispatch(rec, variant, "march", march_bind, groups)?;
        self.rows.dispatch(rec, variant, "sum_rows", rows_bind, groups)?;
        self.columns.dispatch(rec, variant, "sum_columns", columns_bind, groups)?;
        Ok(TechniqueStats {
            technique: "interleaved".into(),
            backend: "gpu".into(),
            timing: String::new(),
            passes: Vec::new(),
            raymarched_samples: self.settings.raymarched_samples(desc.width, desc.height),
            gpu_memory_bytes: self.gpu_memory_bytes(),
            extra: self.settings.extra_stats(lut_error),
        })
    }
}

impl crate::techniques::Technique for InterleavedSettings {
    const INFO: crate::techniques::TechniqueInfo = crate::techniques::TechniqueInfo {
        name: "interleaved",
        summary: "M×M interleaved sampling: each pixel marches N/M² of the N steps, a separable (optionally depth-aware) block sum adds them (GPU + CPU mirror)",
        paper: "Tóth & Umenhoffer 2009, §4.1",
        gpu: true,
        cpu: true,
        per_light: false,
    };
    fn validate(&self) -> Result<(), Error> {
        InterleavedSettings::validate(self)
    }
    fn render_cpu(
        &self,
        frame: &crate::CpuFrame,
        _rectified: Option<&[f32]>,
        _progress: &(dyn Fn(u64, u64) + Sync),
    ) -> Result<(crate::Image, TechniqueStats), Error> {
        cpu::render(frame, self)
    }
}

gpu_technique!(Interleaved, InterleavedSettings);
