//! Technique `prefiltered`: filter-based single scattering on rectified shadow maps (Klehm,
//! Seidel & Eisemann 2014). Instead of marching each view ray through the shadow map, the
//! visibility step of every texel of a *rectified* shadow map — where each view ray runs along
//! one row at one depth — is expanded in a Fourier basis (§3.1, eq. 8–10), the bases are
//! prefix-summed along the rows once per frame with transmittance weights (§3.2–3.3,
//! Listings 1–3), and each pixel then needs one filtered lookup and one dot product
//! (Listing 4): a constant cost per pixel, whatever the scene.
//!
//! Passes (GPU, and their CPU mirror in `cpu.rs`):
//!
//! 1. `rectify` (rectify.wgsl): the rectified shadow map (rectify.rs: the projective map of
//!    §4.2 or the epipolar one of §4.1), resampled from the standard shadow map — skipped when
//!    the host rasterized the projective map itself ([`Prefiltered::raster_request`]).
//! 2. `prefilter` (prefilter.wgsl): basis transform fused with the weighted prefix sum, one
//!    thread per row × region × group of bases.
//! 3. `evaluate` (evaluate.wgsl): per pixel, the unoccluded in-scattering times the prefiltered
//!    visibility.
//! 4. `epipole` (evaluate.wgsl): a small disc around a visible light is ray-marched instead
//!    (§5, Fig. 8), dispatched over the disc's bounding box only.

pub mod cpu;
pub mod debug;
pub mod raster;
pub mod rectify;
pub mod settings;

pub use rectify::{Mode, Rectification, RectificationChoice, ReferenceRay};
pub use settings::{
    BasisPrecision, FLAG_FULL_CIRCLE, FLAG_HOST_RASTER, FLAG_TRANSMITTANCE_WEIGHTS, PrefilteredParams,
    PrefilteredSettings,
};

use crate::error::Error;
use crate::frame::{FrameDesc, GpuFrame};
use crate::gpu::{GpuContext, Recorder};
use crate::march::mean_extinction;
use crate::stats::TechniqueStats;
use crate::techniques::pass::{self, Pass};
pub use raster::RectifiedRaster;
use std::collections::BTreeMap;

/// The rectification and Fourier basis shared by the passes (prepended to each).
pub const GEOMETRY_WGSL: &str = include_str!("geometry.wgsl");
/// Pass `rectify`.
pub const RECTIFY_WGSL: &str = include_str!("rectify.wgsl");
/// The light line of a rectified texel and the rectified depth of a point on it, shared by pass
/// `rectify` and `minmax`'s pass `build`.
pub const RESAMPLE_WGSL: &str = include_str!("resample.wgsl");

/// Pass `rectify`'s source: [`RESAMPLE_WGSL`] and [`RECTIFY_WGSL`].
fn rectify_wgsl() -> String {
    format!("{RESAMPLE_WGSL}\n{RECTIFY_WGSL}")
}
/// Pass `prefilter` (its storage format is the `BASIS_FORMAT` placeholder).
pub const PREFILTER_WGSL: &str = include_str!("prefilter.wgsl");
/// Pass `evaluate` (without its `epipole` entry, [`EPIPOLE_WGSL`]).
pub const EVALUATE_WGSL: &str = include_str!("evaluate.wgsl");
/// Pass `epipole`, appended to the per-pixel pass of `prefiltered` and of `minmax`.
pub const EPIPOLE_WGSL: &str = include_str!("epipole.wgsl");

/// The per-pixel pass `evaluate` with the `epipole` entry appended.
fn evaluate_wgsl() -> String {
    format!("{EVALUATE_WGSL}\n{EPIPOLE_WGSL}")
}

/// The pass shaders: (name, source with the geometry prepended and the 8-bit format, entry).
pub fn shaders() -> [(&'static str, String, &'static str); 4] {
    [
        ("prefiltered/rectify", pass_source(&rectify_wgsl(), BasisPrecision::Unorm8), "rectify"),
        ("prefiltered/prefilter", pass_source(PREFILTER_WGSL, BasisPrecision::Unorm8), "prefilter"),
        ("prefiltered/evaluate", pass_source(&evaluate_wgsl(), BasisPrecision::Unorm8), "evaluate"),
        ("prefiltered/epipole", pass_source(&evaluate_wgsl(), BasisPrecision::Unorm8), "epipole"),
    ]
}

/// A pass shader with the shared geometry prepended and the basis storage format filled in
/// (common.wgsl is added by [`crate::shaders::compose`]).
pub fn pass_source(pass: &str, precision: BasisPrecision) -> String {
    format!("{GEOMETRY_WGSL}\n// ---- prefiltered pass ----\n{}", pass.replace("BASIS_FORMAT", precision.wgsl()))
}

/// Pixel position of the light's epipole when the light is directly visible on screen (its
/// direction is in front of the camera and within `radius` pixels of the image), else None.
/// Directional: the sun's direction; spot and point: the light's position.
pub fn epipole_pixel(desc: &FrameDesc, radius: u32) -> Option<[f32; 2]> {
    if radius == 0 {
        return None;
    }
    let vp = desc.camera.view_proj();
    let p = match &desc.lights[0].light {
        crate::Light::Directional { direction, .. } => desc.camera.position - direction.normalize(),
        crate::Light::Spot { position, .. } | crate::Light::Point { position, .. } => *position,
    };
    let c = vp * p.extend(1.0);
    if c.w <= 1e-6 {
        return None;
    }
    let x = (c.x / c.w * 0.5 + 0.5) * desc.width as f32;
    let y = (0.5 - c.y / c.w * 0.5) * desc.height as f32;
    let r = radius as f32;
    let inside = x >= -r && y >= -r && x <= desc.width as f32 + r && y <= desc.height as f32 + r;
    (inside && x.is_finite() && y.is_finite()).then_some([x, y])
}

/// Ray-marched samples of a frame: the pixels of the epipole disc times their steps.
pub fn epipole_samples(desc: &FrameDesc, settings: &PrefilteredSettings, epipole: Option<[f32; 2]>) -> u64 {
    let Some([x0, y0, x1, y1]) = epipole_box(desc, settings.epipole_radius, epipole) else { return 0 };
    let mut n = 0u64;
    for y in y0..y1 {
        for x in x0..x1 {
            n += cpu::in_epipole_disc(epipole, settings.epipole_radius, x, y) as u64;
        }
    }
    n * settings.epipole_steps as u64
}

/// The pixels [x0, x1) × [y0, y1) of the image that hold the epipole disc of `radius` around
/// `epipole`; None when there is no disc or it misses the image. Its corner is the first pixel
/// of the `epipole` pass (`origin` in evaluate.wgsl).
pub fn epipole_box(desc: &FrameDesc, radius: u32, epipole: Option<[f32; 2]>) -> Option<[u32; 4]> {
    let [ex, ey] = epipole?;
    let r = radius as f32;
    let x0 = (ex - r).floor().max(0.0) as u32;
    let y0 = (ey - r).floor().max(0.0) as u32;
    let x1 = ((ex + r).ceil().max(0.0) as u32 + 1).min(desc.width);
    let y1 = ((ey + r).ceil().max(0.0) as u32 + 1).min(desc.height);
    (radius > 0 && x1 > x0 && y1 > y0).then_some([x0, y0, x1, y1])
}

/// `TechniqueStats::extra` of a frame: the rectification chosen (`projective` 1/0), the
/// projected frustum angle, whether the host rasterized the map, and the filtered-basis memory.
pub(crate) fn stats_extra(settings: &PrefilteredSettings, rect: &Rectification, host: bool) -> BTreeMap<String, f64> {
    [
        ("projective", (rect.mode == Mode::Projective) as u32 as f64),
        ("frustum_angle_degrees", rect.frustum_angle as f64),
        ("host_rasterized", host as u32 as f64),
        ("basis_bytes", settings.basis_bytes() as f64),
        ("map_columns", rect.width as f64),
        ("map_rows", rect.height as f64),
    ]
    .into_iter()
    .map(|(k, v)| (k.to_string(), v))
    .collect()
}

/// The technique's own textures, reallocated when the map size, M or the precision changes.
struct Maps {
    depth: wgpu::Texture,
    basis: wgpu::Texture,
    cumw: wgpu::Texture,
    depth_view: wgpu::TextureView,
    basis_store: wgpu::TextureView,
    basis_sample: wgpu::TextureView,
    cumw_view: wgpu::TextureView,
    key: (u32, u32, u32, BasisPrecision),
    sets: u32,
}

/// The GPU side of `prefiltered`: four passes, buffers, samplers and the map textures.
pub struct Prefiltered {
    /// Current settings; changes apply on the next render.
    pub settings: PrefilteredSettings,
    rectify: Pass,
    prefilter: Pass,
    evaluate: Pass,
    epipole: Pass,
    pipeline_precision: BasisPrecision,
    buffers: pass::FrameBuffers,
    params_buffer: wgpu::Buffer,
    rows_buffer: Option<wgpu::Buffer>,
    clamp_sampler: wgpu::Sampler,
    wrap_sampler: wgpu::Sampler,
    white: wgpu::TextureView,
    maps: Option<Maps>,
    last: Option<Rectification>,
    binds: pass::BindCache<[wgpu::BindGroup; 4]>,
    /// The in-scattering's storage format (kept to rebuild the pipelines on `precision`).
    output: wgpu::TextureFormat,
}

impl Prefiltered {
    /// Builds the passes and buffers.
    pub(crate) fn new(
        gpu: &GpuContext,
        settings: PrefilteredSettings,
        output: wgpu::TextureFormat,
    ) -> Result<Self, Error> {
        settings.validate()?;
        gpu.try_scoped("creating the prefiltered pipelines", || {
            let device = &gpu.device;
            let pass = |label: &str, src: &str, entry: &str| {
                Pass::new(device, &format!("prefiltered/{label}"), &pass_source(src, settings.precision), entry)
            };
            let evaluate_src = pass::with_output(&evaluate_wgsl(), output);
            let sampler = |mode| {
                device.create_sampler(&wgpu::SamplerDescriptor {
                    label: Some("prefiltered basis"),
                    address_mode_u: wgpu::AddressMode::ClampToEdge,
                    address_mode_v: mode,
                    mag_filter: wgpu::FilterMode::Linear,
                    min_filter: wgpu::FilterMode::Linear,
                    ..Default::default()
                })
            };
            Ok(Self {
                pipeline_precision: settings.precision,
                rectify: pass("rectify", &rectify_wgsl(), "rectify")?,
                prefilter: pass("prefilter", PREFILTER_WGSL, "prefilter")?,
                evaluate: pass("evaluate", &evaluate_src, "evaluate")?,
                epipole: pass("epipole", &evaluate_src, "epipole")?,
                settings,
                buffers: pass::FrameBuffers::new(device),
                params_buffer: pass::uniform_buffer(
                    device,
                    "prefiltered params",
                    std::mem::size_of::<PrefilteredParams>() as u64,
                ),
                rows_buffer: None,
                clamp_sampler: sampler(wgpu::AddressMode::ClampToEdge),
                wrap_sampler: sampler(wgpu::AddressMode::Repeat),
                white: pass::white_array(gpu),
                maps: None,
                last: None,
                binds: Default::default(),
                output,
            })
        })
    }

    /// The rectification this frame would use, and the host raster request when it is the
    /// projective one (§4.2): a host that rasterizes it (depth-clamped, see [`RectifiedRaster`])
    /// passes the result as [`crate::GpuFrame::rectified_shadow_maps`] and the `rectify` pass is
    /// skipped.
    pub fn raster_request(&self, desc: &FrameDesc) -> Option<RectifiedRaster> {
        Rectification::new(desc, &self.settings.rectify_options()).raster()
    }

    /// The rectification of the last frame rendered.
    pub fn last_rectification(&self) -> Option<&Rectification> {
        self.last.as_ref()
    }

    /// Bytes of GPU memory this technique holds: the filtered bases (Table 2's column), the
    /// rectified depth and the weight sums, the per-row buffer and the uniforms.
    pub fn gpu_memory_bytes(&self) -> u64 {
        let maps = self.maps.as_ref().map_or(0, |m| {
            let (w, h, layers, p) = m.key;
            w as u64 * h as u64 * (layers as u64 * 4 * p.bytes() + 4 + 4 * m.sets as u64)
        });
        maps + self.rows_buffer.as_ref().map_or(0, |b| b.size()) + self.buffers.size() + self.params_buffer.size() + 16
    }

    /// Reads back the last frame's maps for tests and debug views, laid out as
    /// [`cpu::Passes`]: the rectified depth (`width × height`), the stored bases
    /// (`sets × layers × height × width` RGBA) and the weight sums (`sets × height × width`).
    pub fn read_maps(&self, gpu: &GpuContext) -> Result<(Vec<f32>, Vec<[f32; 4]>, Vec<f32>), Error> {
        let m = self.maps.as_ref().ok_or_else(|| Error::invalid("prefiltered maps", "none", "render a frame first"))?;
        let depth = gpu.read_texture_f32(&m.depth, 0)?;
        let mut cumw = Vec::new();
        for set in 0..m.sets {
            cumw.extend(gpu.read_texture_f32(&m.cumw, set)?);
        }
        let (w, h, layers, p) = m.key;
        let mut basis = Vec::with_capacity((w * h * layers) as usize);
        for l in 0..layers {
            basis.extend(read_rgba_layer(gpu, &m.basis, l, p)?);
        }
        Ok((depth, basis, cumw))
    }

    /// Records the in-scattering of `frame` into `output` (an `Rgba32Float` storage view of the
    /// frame's size) through `rec`. Passes: `rectify` (skipped when the frame carries the
    /// host's rectified raster, [`crate::GpuFrame::rectified_shadow_maps`], and this frame's
    /// rectification is projective), `prefilter`, `evaluate`, `epipole` (when the sun's disc
    /// is on screen).
    pub(crate) fn encode(
        &mut self,
        gpu: &GpuContext,
        rec: &mut Recorder,
        frame: &GpuFrame,
        output: &wgpu::TextureView,
    ) -> Result<TechniqueStats, Error> {
        let host_depth = frame.rectified_shadow_map();
        self.settings.validate()?;
        frame.desc.single_light()?;
        let s = self.settings.clone();
        let desc = frame.desc;
        let [w, h] = s.map_size;
        gpu.check_texture_size("prefiltered rectified map", w, h)?;
        if self.pipeline_precision != s.precision {
            let fresh = Prefiltered::new(gpu, s.clone(), self.output)?;
            *self = Prefiltered { maps: None, ..fresh };
        }
        let rect = Rectification::new(desc, &s.rectify_options());
        let host = host_depth.filter(|_| rect.mode == Mode::Projective);
        let sets = s.sets(&desc.lights[0].light);
        let key = (w, h, s.layers() * sets, s.precision);
        if self.maps.as_ref().is_none_or(|m| m.key != key || m.sets != sets) {
            self.maps = Some(gpu.scoped("allocating the prefiltered maps", || allocate_maps(&gpu.device, key, sets))?);
        }
        let rows_size = (rect.rows.len() as u64 * 4).max(16);
        if self.rows_buffer.as_ref().is_none_or(|b| b.size() != rows_size) {
            self.rows_buffer = Some(gpu.device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("prefiltered rows"),
                size: rows_size,
                usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            }));
        }
        let rows = self.rows_buffer.as_ref().expect("allocated above");
        rec.write_buffer(rows, bytemuck::cast_slice(&rect.rows));
        let epipole = epipole_pixel(desc, s.epipole_radius);
        let channels = s.channels(&desc.lights[0].light);
        let params = PrefilteredParams::new(
            &s,
            &rect,
            mean_extinction(desc),
            desc.lights[0].shadow_bias,
            epipole,
            host.is_some(),
            channels,
        );
        self.buffers.write(rec, desc);
        rec.write_buffer(&self.params_buffer, bytemuck::bytes_of(&params));
        let maps = self.maps.as_ref().expect("allocated above");
        let view = wgpu::BindingResource::TextureView;
        let mut key = pass::frame_key(frame, output);
        key.extend([
            pass::Bound::View(maps.depth_view.clone()),
            pass::Bound::Buffer(rows.clone()),
            pass::Bound::Choice(rect.full_circle as u32 + 2 * host.is_some() as u32),
        ]);
        if !self.binds.is_current(&key) {
            let binds = gpu.try_scoped("binding the prefiltered inputs", || {
                let device = &gpu.device;
                let uniforms = || {
                    pass::with(
                        pass::uniform_resources(&self.buffers, &self.params_buffer),
                        [("rows", rows.as_entire_binding())],
                    )
                };
                let rectify = pass::with(
                    uniforms(),
                    [("shadow_map", view(frame.shadow_maps)), ("out_depth", view(&maps.depth_view))],
                );
                let prefilter = pass::with(
                    uniforms(),
                    [
                        ("spot_tex", view(frame.spot_textures.unwrap_or(&self.white))),
                        ("depth_map", view(host.unwrap_or(&maps.depth_view))),
                        ("out_basis", view(&maps.basis_store)),
                        ("out_cumw", view(&maps.cumw_view)),
                    ],
                );
                let sampler = if rect.full_circle { &self.wrap_sampler } else { &self.clamp_sampler };
                let evaluate = pass::with(
                    pass::frame_resources(&self.buffers, &self.params_buffer, frame, &self.white),
                    [
                        ("rows", rows.as_entire_binding()),
                        ("basis_tex", view(&maps.basis_sample)),
                        ("basis_sampler", wgpu::BindingResource::Sampler(sampler)),
                        ("cumw_tex", view(&maps.cumw_view)),
                        ("out_tex", view(output)),
                    ],
                );
                Ok([
                    self.rectify.bind(device, &rectify)?,
                    self.prefilter.bind(device, &prefilter)?,
                    self.evaluate.bind(device, &evaluate)?,
                    self.epipole.bind(device, &evaluate)?,
                ])
            })?;
            self.binds.store(key, binds);
        }
        let [rectify_bind, prefilter_bind, evaluate_bind, epipole_bind] = self.binds.value();
        let variant = frame.shader_variant();
        if host.is_none() {
            self.rectify.dispatch(rec, variant, "rectify", rectify_bind, self.rectify.groups_2d(w, h))?;
        }
        // One thread per (row, region, group of bases, set), in as many rows of 65535
        // workgroups as it takes.
        let threads = h * s.regions * (s.bases / s.bases_per_thread) * sets;
        let groups = threads.div_ceil(self.prefilter.workgroup_size()[0]);
        self.prefilter.dispatch(
            rec,
            variant,
            "prefilter",
            prefilter_bind,
            [groups.min(65535), groups.div_ceil(65535), 1],
        )?;
        self.evaluate.dispatch(
            rec,
            variant,
            "evaluate",
            evaluate_bind,
            self.evaluate.groups_2d(desc.width, desc.height),
        )?;
        if let Some([x0, y0, x1, y1]) = epipole_box(desc, s.epipole_radius, epipole) {
            self.epipole.dispatch(rec, variant, "epipole", epipole_bind, self.epipole.groups_2d(x1 - x0, y1 - y0))?;
        }
        let extra = stats_extra(&s, &rect, host.is_some());
        self.last = Some(rect);
        Ok(TechniqueStats {
            technique: "prefiltered".into(),
            backend: "gpu".into(),
            timing: String::new(),
            passes: Vec::new(),
            raymarched_samples: epipole_samples(desc, &s, epipole),
            gpu_memory_bytes: self.gpu_memory_bytes(),
            extra,
        })
    }
}

fn allocate_maps(device: &wgpu::Device, key: (u32, u32, u32, BasisPrecision), sets: u32) -> Maps {
    let (w, h, layers, precision) = key;
    let depth = crate::gpu::storage_texture(device, "prefiltered rectified depth", wgpu::TextureFormat::R32Float, w, h);
    let array_texture = |label, format, layers| {
        device.create_texture(&wgpu::TextureDescriptor {
            label: Some(label),
            size: wgpu::Extent3d { width: w, height: h, depth_or_array_layers: layers },
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format,
            usage: wgpu::TextureUsages::STORAGE_BINDING
                | wgpu::TextureUsages::TEXTURE_BINDING
                | wgpu::TextureUsages::COPY_SRC,
            view_formats: &[],
        })
    };
    let cumw = array_texture("prefiltered weight sums", wgpu::TextureFormat::R32Float, sets);
    let basis = array_texture("prefiltered filtered bases", precision.format(), layers);
    let array =
        wgpu::TextureViewDescriptor { dimension: Some(wgpu::TextureViewDimension::D2Array), ..Default::default() };
    Maps {
        depth_view: depth.create_view(&Default::default()),
        cumw_view: cumw.create_view(&array),
        basis_store: basis.create_view(&array),
        basis_sample: basis.create_view(&array),
        depth,
        basis,
        cumw,
        key,
        sets,
    }
}

/// Reads one layer of an `Rgba8Unorm` / `Rgba16Float` array texture as f32 RGBA.
fn read_rgba_layer(
    gpu: &GpuContext,
    tex: &wgpu::Texture,
    layer: u32,
    p: BasisPrecision,
) -> Result<Vec<[f32; 4]>, Error> {
    let data = gpu.read_texture_bytes(tex, layer)?;
    Ok(match p {
        BasisPrecision::Unorm8 => data.chunks_exact(4).map(|c| [0, 1, 2, 3].map(|i| c[i] as f32 / 255.0)).collect(),
        BasisPrecision::Float16 => data
            .chunks_exact(8)
            .map(|c| [0, 1, 2, 3].map(|i| f16_to_f32(u16::from_le_bytes([c[2 * i], c[2 * i + 1]]))))
            .collect(),
    })
}

/// IEEE half → f32.
fn f16_to_f32(h: u16) -> f32 {
    let sign = if h & 0x8000 != 0 { -1.0 } else { 1.0 };
    let exp = ((h >> 10) & 0x1f) as i32;
    let man = (h & 0x3ff) as f32;
    sign * match exp {
        0 => man * 2f32.powi(-24),
        31 => f32::INFINITY,
        e => (1.0 + man / 1024.0) * 2f32.powi(e - 15),
    }
}

impl crate::techniques::Technique for PrefilteredSettings {
    const INFO: crate::techniques::TechniqueInfo = crate::techniques::TechniqueInfo {
        name: "prefiltered",
        summary: "filter-based single scattering: Fourier-expanded visibility on a rectified shadow map, prefix-summed per row with transmittance weights, one filtered lookup and dot product per pixel (GPU: rectify, prefilter, evaluate; CPU mirror)",
        paper: "Klehm, Seidel & Eisemann 2014, §3–5",
        gpu: true,
        cpu: true,
        per_light: true,
    };
    fn validate(&self) -> Result<(), Error> {
        PrefilteredSettings::validate(self)
    }
    fn render_cpu(
        &self,
        frame: &crate::CpuFrame,
        rectified: Option<&[f32]>,
        _progress: &(dyn Fn(u64, u64) + Sync),
    ) -> Result<(crate::Image, TechniqueStats), Error> {
        cpu::render_with(frame, self, rectified)
    }
    fn raster_request(&self, desc: &crate::frame::FrameDesc) -> Option<RectifiedRaster> {
        Rectification::new(desc, &self.rectify_options()).raster()
    }
}

gpu_technique!(Prefiltered, PrefilteredSettings);
