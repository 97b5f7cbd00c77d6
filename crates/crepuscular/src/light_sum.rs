//! The sum over lights for the techniques that render one light per run (`epipolar`,
//! `prefiltered`: their lines or rectified maps depend on where the light is): each light is
//! rendered into a scratch texture and added to a running sum, ping-ponged between two more,
//! the last sum written into the caller's output (docs/MODEL.md §6). A frame with one light
//! writes the output directly and uses none of this.

use crate::error::Error;
use crate::gpu::{GpuContext, Recorder, storage_texture};
use crate::techniques::pass;

/// The add and clear passes and the scratch textures, kept between frames.
pub(crate) struct LightSum {
    add: wgpu::ComputePipeline,
    clear: wgpu::ComputePipeline,
    add_layout: wgpu::BindGroupLayout,
    clear_layout: wgpu::BindGroupLayout,
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
        gpu.scoped("creating the light sum", || {
            let device = &gpu.device;
            use wgpu::TextureViewDimension as D;
            let out = pass::storage_texture_entry_of(2, format);
            let add_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
                label: Some("light sum"),
                entries: &[pass::texture_entry(0, D::D2), pass::texture_entry(1, D::D2), out],
            });
            let clear_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
                label: Some("light clear"),
                entries: &[out],
            });
            let src = pass::with_output(include_str!("shaders/light_sum.wgsl"), format);
            let add = pass::compute_pipeline(device, "light_sum.wgsl", &src, "add", &add_layout);
            let src = pass::with_output(include_str!("shaders/light_clear.wgsl"), format);
            let clear = pass::compute_pipeline(device, "light_clear.wgsl", &src, "clear", &clear_layout);
            Self { add, clear, add_layout, clear_layout, format, scratch: None, binds: Vec::new() }
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

    fn bind(&mut self, gpu: &GpuContext, views: &[&wgpu::TextureView]) -> Result<wgpu::BindGroup, Error> {
        let key: Vec<pass::Bound> = views.iter().map(|v| pass::Bound::View((*v).clone())).collect();
        if let Some((_, b)) = self.binds.iter().find(|(k, _)| *k == key) {
            return Ok(b.clone());
        }
        let layout = if views.len() == 3 { &self.add_layout } else { &self.clear_layout };
        let first = 3 - views.len() as u32;
        let entries: Vec<wgpu::BindGroupEntry> = views
            .iter()
            .enumerate()
            .map(|(i, v)| wgpu::BindGroupEntry {
                binding: first + i as u32,
                resource: wgpu::BindingResource::TextureView(v),
            })
            .collect();
        let bind = gpu.scoped("binding the light sum", || {
            gpu.device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some("light sum"),
                layout,
                entries: &entries,
            })
        })?;
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
        let bind = self.bind(gpu, &[sum, light, out])?;
        let size = out.texture().size();
        let groups = [size.width.div_ceil(8), size.height.div_ceil(8), 1];
        rec.dispatch("sum lights", "light sum", &self.add, &bind, groups)
    }

    /// Records zero in-scattering into `out` (no light reaches the view).
    pub(crate) fn clear(&mut self, gpu: &GpuContext, rec: &mut Recorder, out: &wgpu::TextureView) -> Result<(), Error> {
        let bind = self.bind(gpu, &[out])?;
        let size = out.texture().size();
        let groups = [size.width.div_ceil(8), size.height.div_ceil(8), 1];
        rec.dispatch("no lights", "light clear", &self.clear, &bind, groups)
    }

    /// Bytes of GPU memory held.
    pub(crate) fn gpu_memory_bytes(&self) -> u64 {
        let texel = if self.format == wgpu::TextureFormat::Rgba16Float { 8 } else { 16 };
        self.scratch.as_ref().map_or(0, |s| s.textures.len() as u64 * s.size.0 as u64 * s.size.1 as u64 * texel)
    }
}
