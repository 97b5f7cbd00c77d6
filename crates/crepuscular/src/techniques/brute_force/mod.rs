//! Technique `brute-force`: per-pixel ray marching with shadow-map visibility
//! (Tóth & Umenhoffer 2009, §3–4, eq. 1), one compute pass, and its CPU mirror in `cpu.rs`.
//!
//! Each pixel marches N equal steps of Δ = s/N from the eye to the visible surface (or the far
//! plane) and sums σs·p·L_in·V at one sample per step, weighted by the transmittance to the eye.
//! Eq. 1 weights a step by exp(−τ(s − l))·Δl; we integrate the transmittance over each step
//! exactly (`segment_transmittance`), which converges to the same sum and is exact wherever
//! the light is constant along a step (an unshadowed sun).

pub mod cpu;

use crate::error::Error;
use crate::frame::GpuFrame;
use crate::gpu::{GpuContext, Recorder};
use crate::march::{MarchSettings, StepPolicy};
use crate::stats::TechniqueStats;
use crate::techniques::pass;
use serde::{Deserialize, Serialize};

/// The pass shader (composed with common.wgsl).
pub const MARCH_WGSL: &str = include_str!("march.wgsl");

/// Settings of `brute-force` (`[render.brute-force]` in a scene file).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct BruteForceSettings {
    /// How each pixel marches its own ray ([`MarchSettings`], flattened: the keys `steps`, `jitter`, `frame_index`). `steps` is N
    /// in eq. 1 of Tóth & Umenhoffer 2009, per pixel: one shadow-map lookup per step per pixel.
    #[serde(flatten)]
    pub ray_march: MarchSettings,
    /// Where the steps go for spot and point lights ([`StepPolicy`], flattened: the keys
    /// `spot_steps`, `spot_denominator`, `local_steps`).
    #[serde(flatten)]
    pub policy: StepPolicy,
}

impl BruteForceSettings {
    /// Checks the ranges.
    pub fn validate(&self) -> Result<(), Error> {
        self.ray_march.validate("brute-force")?;
        self.policy.validate("brute-force")
    }
}

/// The uniform block of the march pass (`struct Params` in march.wgsl).
#[repr(C)]
#[derive(Clone, Copy, Debug, bytemuck::Pod, bytemuck::Zeroable)]
pub struct MarchParams {
    /// Steps per pixel.
    pub steps: u32,
    /// 1 to jitter.
    pub jitter: u32,
    /// Jitter seed.
    pub frame_index: u32,
    /// [`crate::march::StepPolicy::code`]: the spot policy and the equiangular bit.
    pub spot_steps: u32,
    /// App. B denominator.
    pub spot_denominator: f32,
    /// Padding.
    pub _pad: [u32; 3],
}

impl From<&BruteForceSettings> for MarchParams {
    fn from(s: &BruteForceSettings) -> Self {
        let m = &s.ray_march;
        Self {
            steps: m.steps,
            jitter: m.jitter as u32,
            frame_index: m.frame_index,
            spot_steps: s.policy.code(),
            spot_denominator: s.policy.denominator,
            _pad: [0; 3],
        }
    }
}

/// The GPU side of `brute-force`: its pass and uniform buffers, built once and reused.
pub struct BruteForce {
    /// Current settings; changes apply on the next `BruteForce::encode`.
    pub settings: BruteForceSettings,
    march: pass::Pass,
    buffers: pass::FrameBuffers,
    params_buffer: wgpu::Buffer,
    white: wgpu::TextureView,
    binds: pass::BindCache<wgpu::BindGroup>,
}

impl BruteForce {
    /// Builds the pipeline.
    pub(crate) fn new(
        gpu: &GpuContext,
        settings: BruteForceSettings,
        output: wgpu::TextureFormat,
    ) -> Result<Self, Error> {
        settings.validate()?;
        gpu.try_scoped("creating the brute-force pipeline", || {
            let device = &gpu.device;
            let march = pass::Pass::new(device, "brute-force/march", &pass::with_output(MARCH_WGSL, output), "march")?;
            let buffers = pass::FrameBuffers::new(device);
            let params_buffer = pass::uniform_buffer(device, "march params", std::mem::size_of::<MarchParams>() as u64);
            let white = pass::white_array(gpu);
            Ok(Self { settings, march, buffers, params_buffer, white, binds: Default::default() })
        })
    }

    /// Bytes of GPU memory this technique holds.
    pub fn gpu_memory_bytes(&self) -> u64 {
        self.buffers.size() + self.params_buffer.size() + 16
    }

    /// Records the in-scattering of `frame` into `output` (an `Rgba32Float` storage view of
    /// the frame's size) through `rec`. Pass list: `march`.
    pub(crate) fn encode(
        &mut self,
        gpu: &GpuContext,
        rec: &mut Recorder,
        frame: &GpuFrame,
        output: &wgpu::TextureView,
    ) -> Result<TechniqueStats, Error> {
        self.settings.validate()?;
        let desc = frame.desc;
        self.buffers.write(rec, desc);
        rec.write_buffer(&self.params_buffer, bytemuck::bytes_of(&MarchParams::from(&self.settings)));
        let key = pass::frame_key(frame, output);
        if !self.binds.is_current(&key) {
            let bind = gpu.try_scoped("binding the brute-force inputs", || {
                let frame = pass::frame_resources(&self.buffers, &self.params_buffer, frame, &self.white);
                self.march
                    .bind(&gpu.device, &pass::with(frame, [("out_tex", wgpu::BindingResource::TextureView(output))]))
            })?;
            self.binds.store(key, bind);
        }
        let bind = self.binds.value();
        self.march.dispatch(
            rec,
            frame.shader_variant(),
            "march",
            bind,
            self.march.groups_2d(desc.width, desc.height),
        )?;
        Ok(TechniqueStats {
            technique: "brute-force".into(),
            backend: "gpu".into(),
            timing: String::new(),
            passes: Vec::new(),
            raymarched_samples: desc.width as u64 * desc.height as u64 * self.settings.ray_march.steps as u64,
            gpu_memory_bytes: self.gpu_memory_bytes(),
            extra: Default::default(),
        })
    }
}

impl crate::techniques::Technique for BruteForceSettings {
    const INFO: crate::techniques::TechniqueInfo = crate::techniques::TechniqueInfo {
        name: "brute-force",
        summary: "per-pixel ray marching through the shadow map, N steps per pixel (GPU + CPU mirror)",
        paper: "Tóth & Umenhoffer 2009, §3–4, eq. 1",
        gpu: true,
        cpu: true,
        per_light: false,
    };
    fn validate(&self) -> Result<(), Error> {
        BruteForceSettings::validate(self)
    }
    fn render_cpu(
        &self,
        frame: &crate::CpuFrame,
        _rectified: Option<&[f32]>,
        _progress: &(dyn Fn(u64, u64) + Sync),
    ) -> Result<(crate::Image, TechniqueStats), Error> {
        cpu::march(frame, self)
    }
}

gpu_technique!(BruteForce, BruteForceSettings);
