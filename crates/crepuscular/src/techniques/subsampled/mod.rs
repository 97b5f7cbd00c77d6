//! Technique `subsampled`: ray marching on a reduced grid, upsampled to the screen with a
//! depth-aware (joint bilateral) filter — the "naïve subsampling" baseline of Wyman & Ramsey
//! 2008 and of Engelhardt & Dachsbacher 2010 (§1, §6 and Fig. 9: 256×256 ray-marched samples),
//! made robust at silhouettes. Two compute passes, and their CPU mirror in `cpu.rs`:
//!
//! 1. `march` (march.wgsl): a w×h grid (w = ⌈W/factor⌉, or a fixed `grid`). Grid sample (i, j)
//!    takes the ray and the depth of one real pixel, the centre of its footprint,
//!    p = ⌊(i + ½)·W/w⌋, and marches it exactly as `brute-force` marches that pixel (N steps of
//!    Tóth & Umenhoffer 2009, eq. 1, over the spot-step interval), so every grid sample is an
//!    exact brute-force sample. It stores the in-scattering (rgb) and the view distance s (a).
//! 2. `upsample` (upsample.wgsl): each pixel blends the 2×2 grid samples around it with
//!    bilinear weights (from the positions of their source pixels) times a depth weight on
//!    |sᵢ − s|/s (Engelhardt & Dachsbacher 2010, §4.3: a product of a spatial and a depth
//!    kernel, normalised). When no neighbour is depth-compatible — a silhouette, or geometry
//!    thinner than the grid spacing — the pixel is ray-marched right there at full resolution
//!    (`edge_remarch`), or takes the neighbour nearest in depth. Re-marched pixels are counted
//!    on the GPU, so `raymarched_samples` = (w·h + re-marched)·N is measured.
//!
//! What it cannot do: shafts (shadow boundaries inside the medium) narrower than the grid
//! spacing are blurred or lost, since the depth buffer does not see them (Engelhardt &
//! Dachsbacher 2010, Fig. 9, left).

pub mod cpu;

use crate::error::Error;
use crate::frame::GpuFrame;
use crate::gpu::{GpuContext, Recorder, compute_pass};
use crate::march::{MarchSettings, StepPolicy};
use crate::stats::TechniqueStats;
use crate::techniques::pass::{self, Pass};
use serde::{Deserialize, Serialize};

/// The `march` pass shader (composed with common.wgsl).
pub const MARCH_WGSL: &str = include_str!("march.wgsl");
/// The `upsample` pass shader (composed with common.wgsl).
pub const UPSAMPLE_WGSL: &str = include_str!("upsample.wgsl");

/// Below this total bilateral weight (the bilinear weights sum to 1) a pixel has no
/// depth-compatible grid neighbour. `MIN_WEIGHT` in upsample.wgsl.
pub const MIN_WEIGHT: f32 = 1e-3;

/// Largest grid side accepted by [`SubsampledSettings::validate`].
pub const MAX_GRID: u32 = 16384;

/// Settings of `subsampled` (`[render.subsampled]` in a scene file).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SubsampledSettings {
    /// Subsampling factor f: the grid is ⌈W/f⌉ × ⌈H/f⌉ ray-marched samples for a W×H image.
    ///
    /// Ray-marching cost falls as 1/f² (plus the re-marched silhouette pixels); shafts narrower
    /// than about f pixels blur. 1 is brute-force. Must be in 1..=32. Default 4.
    pub factor: u32,
    /// A fixed grid size [width, height] in samples that overrides `factor`, e.g. `[256, 256]`
    /// as in Engelhardt & Dachsbacher 2010, Fig. 9; clamped to the image size. Cost is
    /// width·height marches per frame at any resolution. Each side in 1..=16384. Default none.
    pub grid: Option<[u32; 2]>,
    /// How the grid samples and re-marched pixels march their rays ([`MarchSettings`], flattened: the keys `steps`, `jitter`, `frame_index`). `steps` is N in eq. 1 per grid sample and per re-marched pixel; a grid
    /// sample's jitter is its source pixel's, as `brute-force` would use there.
    #[serde(flatten)]
    pub ray_march: MarchSettings,
    /// Where the steps go for spot and point lights ([`StepPolicy`], flattened: the keys
    /// `spot_steps`, `spot_denominator`, `local_steps`).
    #[serde(flatten)]
    pub policy: StepPolicy,
    /// Depth tolerance of the bilateral upsampling: the relative view-distance difference
    /// |sᵢ − s|/s (dimensionless) at which a grid sample stops counting for a pixel. Samples
    /// within half of it get their full bilinear weight, then the weight falls smoothly to 0.
    ///
    /// Smaller re-marches (or, without `edge_remarch`, snaps) more pixels: sharper silhouettes,
    /// more cost on steep surfaces (a ground plane towards the horizon). Larger lets the fog of
    /// a far background bleed onto near silhouettes. On the built-in scenes at factor 4
    /// (160×90), halving it from 0.1 doubles to triples the re-marched pixels for ±0.3 dB, and
    /// doubling it halves them for up to −0.6 dB; with no depth test at all (a huge value) four
    /// of the five lose 5–16 dB at their silhouettes. Must be finite and > 0. Default 0.1.
    pub depth_tolerance: f32,
    /// Ray-march a pixel at full resolution (N steps, as `brute-force`) when none of its 2×2
    /// grid neighbours is depth-compatible, instead of copying the neighbour nearest in depth.
    /// Costs N steps per such pixel (counted in `remarched_pixels`); exact at silhouettes and
    /// on geometry thinner than the grid spacing. Default true.
    pub edge_remarch: bool,
    /// Treat a grid sample whose ray meets a different set of spot-light cones than the
    /// pixel's ray as incompatible, as a depth step is: the pixel blends only the samples that
    /// see the same cones, or is re-marched (`edge_remarch`) when none does. A beam narrower
    /// than the grid spacing then keeps its edges instead of being spread over the samples
    /// around it, and a pixel whose ray misses a cone gets that spot's exact zero. Costs one
    /// ray–cone test per spot light for the pixel and each of its four samples, plus the
    /// re-marched pixels along the cones' edges; nothing in a frame without spot lights. With
    /// several spots a tap must meet the same set of all the frame's cones, so the frame is no
    /// longer the sum of each light's own upsampling (off, it is; tests/lights.rs). Measured:
    /// docs/ROBUSTNESS.md (the sweep's spot views). Default true.
    pub cone_aware: bool,
}

impl Default for SubsampledSettings {
    fn default() -> Self {
        Self {
            factor: 4,
            grid: None,
            ray_march: MarchSettings::default(),
            policy: StepPolicy::default(),
            depth_tolerance: 0.1,
            edge_remarch: true,
            cone_aware: true,
        }
    }
}

impl SubsampledSettings {
    /// Checks the ranges.
    pub fn validate(&self) -> Result<(), Error> {
        if !(1..=32).contains(&self.factor) {
            return Err(Error::invalid("subsampled.factor", self.factor, "must be in 1..=32"));
        }
        if let Some([w, h]) = self.grid
            && (!(1..=MAX_GRID).contains(&w) || !(1..=MAX_GRID).contains(&h))
        {
            return Err(Error::invalid(
                "subsampled.grid",
                format!("[{w}, {h}]"),
                format!("each side must be in 1..={MAX_GRID}"),
            ));
        }
        if !(self.depth_tolerance.is_finite() && self.depth_tolerance > 0.0) {
            return Err(Error::invalid("subsampled.depth_tolerance", self.depth_tolerance, "must be finite and > 0"));
        }
        self.ray_march.validate("subsampled")?;
        self.policy.validate("subsampled")
    }

    /// The grid size (w, h) for a `width`×`height` image: `grid` clamped to the image, else
    /// ⌈width/factor⌉ × ⌈height/factor⌉ (at least 1×1).
    pub fn grid_size(&self, width: u32, height: u32) -> (u32, u32) {
        match self.grid {
            Some([w, h]) => (w.clamp(1, width.max(1)), h.clamp(1, height.max(1))),
            None => {
                let f = self.factor.max(1);
                (width.div_ceil(f).max(1), height.div_ceil(f).max(1))
            }
        }
    }
}

/// The uniform block of both passes (`struct Params` in march.wgsl and upsample.wgsl).
#[repr(C)]
#[derive(Clone, Copy, Debug, bytemuck::Pod, bytemuck::Zeroable)]
pub struct SubsampledParams {
    /// Steps per ray.
    pub steps: u32,
    /// 1 to jitter.
    pub jitter: u32,
    /// Jitter seed.
    pub frame_index: u32,
    /// [`crate::march::StepPolicy::code`]: the spot policy and the equiangular bit.
    pub spot_steps: u32,
    /// App. B denominator.
    pub spot_denominator: f32,
    /// Grid width w, samples.
    pub grid_width: u32,
    /// Grid height h, samples.
    pub grid_height: u32,
    /// Relative depth tolerance.
    pub depth_tolerance: f32,
    /// 1 to re-march pixels without a depth-compatible neighbour.
    pub edge_remarch: u32,
    /// 1 to treat samples that meet other spot cones than the pixel as incompatible.
    pub cone_aware: u32,
    /// Padding.
    pub _pad: [u32; 2],
}

const _: () = assert!(std::mem::size_of::<SubsampledParams>() == 48);

impl SubsampledParams {
    /// The block for `settings` on a `grid` = (w, h) grid.
    pub fn new(s: &SubsampledSettings, grid: (u32, u32)) -> Self {
        Self {
            steps: s.ray_march.steps,
            jitter: s.ray_march.jitter as u32,
            frame_index: s.ray_march.frame_index,
            spot_steps: s.policy.code(),
            spot_denominator: s.policy.denominator,
            grid_width: grid.0,
            grid_height: grid.1,
            depth_tolerance: s.depth_tolerance,
            edge_remarch: s.edge_remarch as u32,
            cone_aware: s.cone_aware as u32,
            _pad: [0; 2],
        }
    }
}

/// The low-resolution grid texture (in-scattering, view distance; in the output's format).
struct Grid {
    texture: wgpu::Texture,
    view: wgpu::TextureView,
}

/// The GPU side of `subsampled`: its two passes, uniform buffers, the re-march counter and
/// the grid texture, built once and reused (the grid is reallocated only when its size changes).
pub struct Subsampled {
    /// Current settings; changes apply on the next `Subsampled::encode`.
    pub settings: SubsampledSettings,
    march: Pass,
    upsample: Pass,
    buffers: pass::FrameBuffers,
    params_buffer: wgpu::Buffer,
    counter: wgpu::Buffer,
    white: wgpu::TextureView,
    grid: Option<Grid>,
    /// The grid's format ([`pass::intermediate_format`]).
    inter: wgpu::TextureFormat,
    binds: pass::BindCache<[wgpu::BindGroup; 2]>,
}

impl Subsampled {
    /// Builds the passes and buffers.
    pub(crate) fn new(
        gpu: &GpuContext,
        settings: SubsampledSettings,
        output: wgpu::TextureFormat,
    ) -> Result<Self, Error> {
        settings.validate()?;
        gpu.try_scoped("creating the subsampled pipelines", || {
            let device = &gpu.device;
            let inter = pass::intermediate_format(output);
            let march_src = pass::with_storage_format(MARCH_WGSL, "grid_tex", inter);
            let march = Pass::new(device, "subsampled/march", &march_src, "march")?;
            let upsample =
                Pass::new(device, "subsampled/upsample", &pass::with_output(UPSAMPLE_WGSL, output), "upsample")?;
            let buffers = pass::FrameBuffers::new(device);
            let params_buffer =
                pass::uniform_buffer(device, "subsampled params", std::mem::size_of::<SubsampledParams>() as u64);
            let counter = device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("re-marched pixels"),
                size: 4,
                usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::COPY_SRC,
                mapped_at_creation: false,
            });
            let white = pass::white_array(gpu);
            Ok(Self {
                settings,
                march,
                upsample,
                buffers,
                params_buffer,
                counter,
                white,
                grid: None,
                inter,
                binds: Default::default(),
            })
        })
    }

    /// Bytes of GPU memory this technique holds (buffers, the 1×1 white texture and the grid).
    pub fn gpu_memory_bytes(&self) -> u64 {
        let texel = pass::texel_bytes(self.inter);
        let grid = self.grid.as_ref().map_or(0, |g| g.texture.width() as u64 * g.texture.height() as u64 * texel);
        self.buffers.size() + self.params_buffer.size() + self.counter.size() + 16 + grid
    }

    /// The low-resolution grid of the last frame (w×h, in the output's format: in-scattering in rgb,
    /// view distance in alpha), for tests and debugging; None before the first render.
    pub fn grid_texture(&self) -> Option<&wgpu::Texture> {
        self.grid.as_ref().map(|g| &g.texture)
    }

    /// Records the in-scattering of `frame` into `output` (an `Rgba32Float` storage view of
    /// the frame's size) through `rec`. Pass list: `march` (the grid), `upsample` (every
    /// pixel). The re-marched pixels are counted on the GPU and join the stats once the
    /// counter has been read back.
    pub(crate) fn encode(
        &mut self,
        gpu: &GpuContext,
        rec: &mut Recorder,
        frame: &GpuFrame,
        output: &wgpu::TextureView,
    ) -> Result<TechniqueStats, Error> {
        self.settings.validate()?;
        let desc = frame.desc;
        let (gw, gh) = self.settings.grid_size(desc.width, desc.height);
        gpu.check_texture_size("subsampled grid", gw, gh)?;
        if self.grid.as_ref().is_none_or(|g| g.texture.width() != gw || g.texture.height() != gh) {
            self.grid = Some(gpu.scoped("allocating the subsampled grid", || {
                let texture = crate::gpu::storage_texture(&gpu.device, "subsampled grid", self.inter, gw, gh);
                let view = texture.create_view(&Default::default());
                Grid { texture, view }
            })?);
        }
        let grid_view = &self.grid.as_ref().expect("allocated above").view;
        let params = SubsampledParams::new(&self.settings, (gw, gh));
        self.buffers.write(rec, desc);
        rec.write_buffer(&self.params_buffer, bytemuck::bytes_of(&params));
        let mut key = pass::frame_key(frame, output);
        key.push(pass::Bound::View(grid_view.clone()));
        if !self.binds.is_current(&key) {
            let binds = gpu.try_scoped("binding the subsampled inputs", || {
                let view = wgpu::BindingResource::TextureView;
                let common = || pass::frame_resources(&self.buffers, &self.params_buffer, frame, &self.white);
                Ok([
                    self.march.bind(&gpu.device, &pass::with(common(), [("grid_tex", view(grid_view))]))?,
                    self.upsample.bind(
                        &gpu.device,
                        &pass::with(
                            common(),
                            [
                                ("grid_tex", view(grid_view)),
                                ("remarched", self.counter.as_entire_binding()),
                                ("out_tex", view(output)),
                            ],
                        ),
                    )?,
                ])
            })?;
            self.binds.store(key, binds);
        }
        let [march_bind, upsample_bind] = self.binds.value();
        let variant = frame.shader_variant();
        self.march.dispatch(rec, variant, "march", march_bind, self.march.groups_2d(gw, gh))?;
        rec.pass("upsample", |enc, ts| {
            enc.clear_buffer(&self.counter, 0, None);
            {
                let mut pass = compute_pass(enc, self.upsample.label(), ts);
                pass.set_pipeline(self.upsample.pipeline(variant));
                pass.set_bind_group(0, upsample_bind, &[]);
                let [x, y, z] = self.upsample.groups_2d(desc.width, desc.height);
                pass.dispatch_workgroups(x, y, z);
            }
        })?;
        // The re-marched pixels are counted on the GPU; until the counter arrives (and with
        // StatsMode::Off) the samples are the grid's only.
        let steps = self.settings.ray_march.steps as u64;
        rec.read_counters(&self.counter, move |counter, stats| {
            let remarched = u32::from_le_bytes([counter[0], counter[1], counter[2], counter[3]]) as u64;
            stats.raymarched_samples += remarched * steps;
            stats.extra.insert("remarched_pixels".into(), remarched as f64);
        });
        let mut extra = stats_extra(gw, gh, 0);
        extra.remove("remarched_pixels");
        Ok(TechniqueStats {
            technique: "subsampled".into(),
            backend: "gpu".into(),
            timing: String::new(),
            passes: Vec::new(),
            raymarched_samples: gw as u64 * gh as u64 * steps,
            gpu_memory_bytes: self.gpu_memory_bytes(),
            extra,
        })
    }
}

/// `TechniqueStats::extra` of a frame: `grid_width`, `grid_height`, `remarched_pixels`.
pub(crate) fn stats_extra(gw: u32, gh: u32, remarched: u64) -> std::collections::BTreeMap<String, f64> {
    [("grid_width", gw as f64), ("grid_height", gh as f64), ("remarched_pixels", remarched as f64)]
        .into_iter()
        .map(|(k, v)| (k.to_string(), v))
        .collect()
}

impl crate::techniques::Technique for SubsampledSettings {
    const INFO: crate::techniques::TechniqueInfo = crate::techniques::TechniqueInfo {
        name: "subsampled",
        summary: "ray marching on a reduced grid, joint-bilateral upsampling by depth, silhouette pixels re-marched at full resolution (GPU + CPU mirror)",
        paper: "the baseline of Engelhardt & Dachsbacher 2010 §6 / Fig. 9",
        gpu: true,
        cpu: true,
        per_light: false,
    };
    fn validate(&self) -> Result<(), Error> {
        SubsampledSettings::validate(self)
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

gpu_technique!(Subsampled, SubsampledSettings);
