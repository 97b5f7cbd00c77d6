//! The sum over lights for the techniques that render one light per run (`epipolar`,
//! `prefiltered`: their lines or rectified maps depend on where the light is): each light is
//! rendered into a scratch texture and added to a running sum, ping-ponged between two more,
//! the last sum written into the caller's output (docs/MODEL.md §6). A frame with one light
//! writes the output directly and uses none of this.

use crate::error::Error;
use crate::gpu::{GpuContext, Recorder, storage_texture};
use crate::techniques::pass::{self, Pass, ShaderVariant};

/// The add and clear passes and the scratch textures, kept between frames.
pub(crate) struct LightSum {
    add: Pass,
    clear: Pass,
    format: wgpu::TextureFormat,
    /// The light being rendered, and the two running sums.
    scratch: Option<Scratch>,
    /// Bind groups of the add pass by (sum in, light, sum out); of the clear pass by output.
    binds: Vec<(Vec<pass::Bound>, wgpu::BindGroup)>,
}

struct Scratch {
    size: (u32, u32),
    textures: Vec<wgpu::Texture>,
    views: [wgpu::TextureView; 3],
}

/// Bind groups kept per distinct set of views (the caller's output views may change).
const MAX_BINDS: usize = 8;

impl LightSum {
    pub(crate) fn new(gpu: &GpuContext, format: wgpu::TextureFormat) -> Result<Self, Error> {
        gpu.try_scoped("creating the light sum", || {
            let device = &gpu.device;
            let src = pass::with_output(include_str!("shaders/light_sum.wgsl"), format);
            let add = Pass::new(device, "light sum/add", &src, "add")?;
            let src = pass::with_output(include_str!("shaders/light_clear.wgsl"), format);
            let clear = Pass::new(device, "light sum/clear", &src, "clear")?;
            Ok(Self { add, clear, format, scratch: None, binds: Vec::new() })
        })
    }

    /// The scratch views for a `w × h` frame: [light, sum A, sum B].
    pub(crate) fn views(&mut self, gpu: &GpuContext, w: u32, h: u32) -> Result<[wgpu::TextureView; 3], Error> {
        if self.scratch.as_ref().is_none_or(|s| s.size != (w, h)) {
            let textures: Vec<wgpu::Texture> = gpu.scoped("allocating the light sum", || {
                ["light", "light sum A", "light sum B"]
                    .map(|label| storage_texture(&gpu.device, label, self.format, w, h))
                    .to_vec()
            })?;
            let views = [0, 1, 2].map(|i| textures[i].create_view(&Default::default()));
            self.scratch = Some(Scratch { size: (w, h), textures, views });
            self.binds.clear();
        }
        Ok(self.scratch.as_ref().expect("allocated above").views.clone())
    }

    /// The bind group of `views` named as the add pass's shader names them (`a_tex`, `b_tex`,
    /// `out_tex`) or, with `out_tex` alone, the clear pass's.
    fn bind(&mut self, gpu: &GpuContext, views: &[(&str, &wgpu::TextureView)]) -> Result<wgpu::BindGroup, Error> {
        let key: Vec<pass::Bound> = views.iter().map(|(_, v)| pass::Bound::View((*v).clone())).collect();
        if let Some((_, b)) = self.binds.iter().find(|(k, _)| *k == key) {
            return Ok(b.clone());
        }
        let kernel = if views.len() == 3 { &self.add } else { &self.clear };
        let resources: Vec<pass::Resource> =
            views.iter().map(|(n, v)| (*n, wgpu::BindingResource::TextureView(v))).collect();
        let bind = gpu.try_scoped("binding the light sum", || kernel.bind(&gpu.device, &resources))?;
        if self.binds.len() >= MAX_BINDS {
            self.binds.remove(0);
        }
        self.binds.push((key, bind.clone()));
        Ok(bind)
    }

    /// Records `out = sum + light` (a pass named `sum lights`).
    pub(crate) fn add(
        &mut self,
        gpu: &GpuContext,
        rec: &mut Recorder,
        sum: &wgpu::TextureView,
        light: &wgpu::TextureView,
        out: &wgpu::TextureView,
    ) -> Result<(), Error> {
        let bind = self.bind(gpu, &[("a_tex", sum), ("b_tex", light), ("out_tex", out)])?;
        let size = out.texture().size();
        self.add.dispatch(rec, ShaderVariant::ALL, "sum lights", &bind, self.add.groups_2d(size.width, size.height))
    }

    /// Records zero in-scattering into `out` (no light reaches the view).
    pub(crate) fn clear(&mut self, gpu: &GpuContext, rec: &mut Recorder, out: &wgpu::TextureView) -> Result<(), Error> {
        let bind = self.bind(gpu, &[("out_tex", out)])?;
        let size = out.texture().size();
        self.clear.dispatch(rec, ShaderVariant::ALL, "no lights", &bind, self.clear.groups_2d(size.width, size.height))
    }

    /// Bytes of GPU memory held.
    pub(crate) fn gpu_memory_bytes(&self) -> u64 {
        let texel = if self.format == wgpu::TextureFormat::Rgba16Float { 8 } else { 16 };
        self.scratch.as_ref().map_or(0, |s| s.textures.len() as u64 * s.size.0 as u64 * s.size.1 as u64 * texel)
    }
}
