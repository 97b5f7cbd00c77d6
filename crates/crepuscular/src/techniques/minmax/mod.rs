//! Technique `minmax`: single scattering through 1D min-max mipmaps on a rectified shadow map
//! (Chen, Baran, Durand & Jarosz 2011), the competitor Klehm, Seidel & Eisemann 2014 measure
//! their filtered technique against (§5, Fig. 5). On the rectified map `prefiltered` builds
//! (prefiltered/rectify.rs: every view ray runs along one row at one constant depth), each row
//! gets a binary tree of (min, max) depths; a view ray walks its row from the camera to its
//! surface, skipping every node that is entirely lit or entirely shadowed for its depth, and
//! integrates its lit spans in closed form. The result is exact at the map's resolution
//! (docs/MODEL.md §8): no step count, and a cost that grows with how often the visibility along
//! the ray changes, not with the ray's length.
//!
//! Passes (GPU, and their CPU mirror in `cpu.rs`):
//!
//! 1. `rectify` (`prefiltered`'s rectify.wgsl): the rectified shadow map, resampled from the
//!    standard shadow map — skipped when the host rasterized the projective map itself
//!    ([`crate::techniques::Technique::raster_request`]).
//! 2. `build` (build.wgsl): the min-max tree of every row, one workgroup per row.
//! 3. `traverse` (traverse.wgsl): per pixel, the walk (Chen et al. 2011 §3.2) and the exact
//!    integral of its lit spans; the walks' counts go to a counter buffer read after the frame.
//! 4. `epipole` (prefiltered/epipole.wgsl): the disc around a visible light, ray-marched, as
//!    `prefiltered` does.

pub mod cpu;
pub mod settings;

pub use settings::MinmaxSettings;

use crate::error::Error;
use crate::frame::GpuFrame;
use crate::gpu::{GpuContext, Recorder};
use crate::march::mean_extinction;
use crate::stats::TechniqueStats;
use crate::techniques::pass;
use crate::techniques::prefiltered::{
    self, EPIPOLE_WGSL, Mode, PrefilteredParams, RECTIFY_WGSL, Rectification, RectifiedRaster, epipole_box,
    epipole_pixel, epipole_samples, pass_source,
};
use std::collections::BTreeMap;

/// Pass `build`.
pub const BUILD_WGSL: &str = include_str!("build.wgsl");
/// The walk and its integration (`shade`), shared by `traverse` and epipolar's min-max march.
pub const WALK_WGSL: &str = include_str!("walk.wgsl");
/// Pass `traverse` (the walk and the `epipole` entry of prefiltered/epipole.wgsl appended).
pub const TRAVERSE_WGSL: &str = include_str!("traverse.wgsl");

fn traverse_wgsl() -> String {
    format!("{WALK_WGSL}\n{TRAVERSE_WGSL}\n{EPIPOLE_WGSL}")
}

/// The pass shaders: (name, source with the rectification's geometry prepended, entry).
pub fn shaders() -> [(&'static str, String, &'static str); 3] {
    let p = prefiltered::BasisPrecision::Unorm8;
    [
        ("minmax/build", pass_source(BUILD_WGSL, p), "build"),
        ("minmax/traverse", pass_source(&traverse_wgsl(), p), "traverse"),
        ("minmax/epipole", pass_source(&traverse_wgsl(), p), "epipole"),
    ]
}

/// The uniform block of every pass: `prefiltered`'s (one band, one region), with the tree's
/// levels and the node budget in `ints4.z` and `ints4.w`.
pub fn params(
    s: &MinmaxSettings,
    rect: &Rectification,
    desc: &crate::FrameDesc,
    epipole: Option<[f32; 2]>,
    host: bool,
) -> PrefilteredParams {
    let mut p = PrefilteredParams::new(
        &s.rectified(),
        rect,
        mean_extinction(desc),
        desc.lights[0].shadow_bias,
        epipole,
        host,
        1,
    );
    p.ints4[2] = s.tree_levels();
    p.ints4[3] = s.max_nodes;
    p
}

/// `TechniqueStats::extra` of a frame: the rectification, the tree's size and memory, and —
/// once the walks are counted (`totals`) — nodes visited per ray (mean, max), lit and shadowed
/// nodes per ray, and the rays that reached the node budget.
pub(crate) fn stats_extra(
    s: &MinmaxSettings,
    rect: &Rectification,
    host: bool,
    totals: Option<&cpu::WalkTotals>,
) -> BTreeMap<String, f64> {
    let mut m: BTreeMap<String, f64> = [
        ("projective", (rect.mode == Mode::Projective) as u32 as f64),
        ("host_rasterized", host as u32 as f64),
        ("map_columns", rect.width as f64),
        ("map_rows", rect.height as f64),
        ("tree_levels", s.tree_levels() as f64),
        ("tree_bytes", s.tree_bytes() as f64),
    ]
    .into_iter()
    .map(|(k, v)| (k.to_string(), v))
    .collect();
    if let Some(t) = totals {
        let per_ray = |v: u64| if t.rays > 0 { v as f64 / t.rays as f64 } else { 0.0 };
        m.insert("rays".into(), t.rays as f64);
        m.insert("nodes_per_ray".into(), per_ray(t.nodes));
        m.insert("max_nodes_per_ray".into(), t.max_nodes as f64);
        m.insert("lit_nodes_per_ray".into(), per_ray(t.lit));
        m.insert("shadowed_nodes_per_ray".into(), per_ray(t.shadowed));
        m.insert("rays_over_budget".into(), t.over_budget as f64);
    }
    m
}

/// The rectified map and its tree, reallocated when the map size changes.
struct Maps {
    depth: wgpu::Texture,
    depth_view: wgpu::TextureView,
    tree: wgpu::Buffer,
    key: [u32; 2],
}

/// What [`TreeBuilder::encode`] recorded for a frame.
pub struct TreeFrame {
    /// The frame's rectification.
    pub rect: Rectification,
    /// The host's rectified raster was used (projective frames).
    pub host: bool,
}

/// The min-max structure of a one-light frame on the GPU: passes `rectify` (skipped where the
/// host rasterized the projective map) and `build`, into a tree buffer and the uniform block the
/// walk reads. `minmax` walks it per pixel; `epipolar` with `march = "minmax"` per ray-march
/// sample (Yusov 2013). Its frame uniforms and lights are the owner's ([`pass::FrameBuffers`],
/// written by the owner before [`TreeBuilder::encode`]).
pub struct TreeBuilder {
    rectify_pipeline: wgpu::ComputePipeline,
    build_pipeline: wgpu::ComputePipeline,
    rectify_layout: wgpu::BindGroupLayout,
    build_layout: wgpu::BindGroupLayout,
    params_buffer: wgpu::Buffer,
    /// The rectify pass's per-row reference rays (unused by the walk, bound for the layout).
    rows_buffer: wgpu::Buffer,
    maps: Option<Maps>,
    binds: pass::BindCache<[wgpu::BindGroup; 2]>,
}

impl TreeBuilder {
    /// Builds the two pipelines.
    pub fn new(device: &wgpu::Device) -> Self {
        use wgpu::TextureViewDimension as D;
        let rectify_layout = prefiltered::rectify_layout(device);
        let build_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("minmax build"),
            entries: &[
                pass::uniform_entry(0),
                pass::uniform_entry(1),
                pass::texture_entry(2, D::D2),
                pass::storage_buffer_entry(3, false, None),
            ],
        });
        let p = prefiltered::BasisPrecision::Unorm8;
        let pipe = |label: &str, src: &str, entry: &str, layout: &wgpu::BindGroupLayout| {
            pass::compute_pipeline(device, label, &pass_source(src, p), entry, layout)
        };
        Self {
            rectify_pipeline: pipe("prefiltered/rectify.wgsl", RECTIFY_WGSL, "rectify", &rectify_layout),
            build_pipeline: pipe("minmax/build.wgsl", BUILD_WGSL, "build", &build_layout),
            rectify_layout,
            build_layout,
            params_buffer: pass::uniform_buffer(
                device,
                "minmax params",
                std::mem::size_of::<PrefilteredParams>() as u64,
            ),
            rows_buffer: device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("minmax rows"),
                size: 16,
                usage: wgpu::BufferUsages::STORAGE,
                mapped_at_creation: false,
            }),
            maps: None,
            binds: Default::default(),
        }
    }

    /// The uniform block of the last frame (`Params` of the walk).
    pub fn params_buffer(&self) -> &wgpu::Buffer {
        &self.params_buffer
    }

    /// The tree of the last frame (`2·columns` (min, max) pairs per row); None before the first.
    pub fn tree(&self) -> Option<&wgpu::Buffer> {
        self.maps.as_ref().map(|m| &m.tree)
    }

    /// Bytes held: the rectified depth, the tree and the two small buffers.
    pub fn gpu_memory_bytes(&self) -> u64 {
        let maps = self.maps.as_ref().map_or(0, |m| m.key[0] as u64 * m.key[1] as u64 * 4 + m.tree.size());
        maps + self.params_buffer.size() + self.rows_buffer.size()
    }

    /// Records `rectify` (unless `host_raster` and the frame's rectified raster serves) and
    /// `build` for `frame` under `s`; `buffers` hold the frame's uniforms and lights.
    pub fn encode(
        &mut self,
        gpu: &GpuContext,
        rec: &mut Recorder,
        frame: &GpuFrame,
        s: &MinmaxSettings,
        buffers: &pass::FrameBuffers,
        host_raster: bool,
    ) -> Result<TreeFrame, Error> {
        let desc = frame.desc;
        let [w, h] = s.map_size;
        gpu.check_texture_size("minmax rectified map (map_size)", w, h)?;
        let rect = Rectification::new(desc, &s.rectify_options());
        let host = frame.rectified_shadow_map().filter(|_| host_raster && rect.mode == Mode::Projective);
        if self.maps.as_ref().is_none_or(|m| m.key != [w, h]) {
            let limit = gpu.device.limits().max_storage_buffer_binding_size;
            if s.tree_bytes() > limit {
                return Err(Error::Limit {
                    what: "minmax tree (16 bytes × map_size[0] × map_size[1])".into(),
                    value: s.tree_bytes(),
                    limit,
                });
            }
            self.maps = None;
            self.maps = Some(gpu.scoped("allocating the minmax maps", || {
                let depth = crate::gpu::storage_texture(
                    &gpu.device,
                    "minmax rectified depth",
                    wgpu::TextureFormat::R32Float,
                    w,
                    h,
                );
                let tree = gpu.device.create_buffer(&wgpu::BufferDescriptor {
                    label: Some("minmax tree"),
                    size: s.tree_bytes(),
                    usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
                    mapped_at_creation: false,
                });
                Maps { depth_view: depth.create_view(&Default::default()), depth, tree, key: [w, h] }
            })?);
        }
        let epipole = epipole_pixel(desc, s.epipole_radius);
        let p = params(s, &rect, desc, epipole, host.is_some());
        rec.write_buffer(&self.params_buffer, bytemuck::bytes_of(&p));
        let maps = self.maps.as_ref().expect("allocated above");
        let view = wgpu::BindingResource::TextureView;
        let mut key = pass::frame_key(frame, &maps.depth_view);
        key.extend([pass::Bound::Buffer(maps.tree.clone()), pass::Bound::Choice(host.is_some() as u32)]);
        if !self.binds.is_current(&key) {
            let binds = gpu.scoped("binding the minmax inputs", || {
                let bind = |label, layout, entries: &[wgpu::BindGroupEntry]| {
                    gpu.device.create_bind_group(&wgpu::BindGroupDescriptor { label: Some(label), layout, entries })
                };
                let e = |binding, resource| wgpu::BindGroupEntry { binding, resource };
                let rectify = bind(
                    "minmax rectify",
                    &self.rectify_layout,
                    &[
                        e(0, buffers.frame.as_entire_binding()),
                        e(1, self.params_buffer.as_entire_binding()),
                        e(2, view(frame.shadow_maps)),
                        e(3, self.rows_buffer.as_entire_binding()),
                        e(4, view(&maps.depth_view)),
                        pass::lights_binding(&buffers.lights),
                    ],
                );
                let build = bind(
                    "minmax build",
                    &self.build_layout,
                    &[
                        e(0, buffers.frame.as_entire_binding()),
                        e(1, self.params_buffer.as_entire_binding()),
                        e(2, view(host.unwrap_or(&maps.depth_view))),
                        e(3, maps.tree.as_entire_binding()),
                    ],
                );
                [rectify, build]
            })?;
            self.binds.store(key, binds);
        }
        let [rectify_bind, build_bind] = self.binds.value();
        if host.is_none() {
            let groups = [w.div_ceil(8), h.div_ceil(8), 1];
            rec.dispatch("rectify", "minmax rectify", &self.rectify_pipeline, rectify_bind, groups)?;
        }
        rec.dispatch("build", "minmax build", &self.build_pipeline, build_bind, [h, 1, 1])?;
        Ok(TreeFrame { rect, host: host.is_some() })
    }

    /// Reads back the last frame's rectified depth (`width × height`) and tree (`2·width`
    /// (min, max) pairs per row), laid out as [`cpu::Passes`], for tests and debug views.
    pub fn read_maps(&self, gpu: &GpuContext) -> Result<(Vec<f32>, Vec<[f32; 2]>), Error> {
        let m = self.maps.as_ref().ok_or_else(|| Error::invalid("minmax maps", "none", "render a frame first"))?;
        let depth = gpu.read_texture_f32(&m.depth, 0)?;
        let tree = bytemuck::cast_slice(&crate::scattering::read_buffer(gpu, &m.tree)?).to_vec();
        Ok((depth, tree))
    }

    /// The bind groups built so far.
    fn builds(&self) -> u64 {
        self.binds.builds()
    }
}

/// The GPU side of `minmax`: the tree ([`TreeBuilder`]), the walk's pipelines and the counters.
pub struct MinMax {
    /// Current settings; changes apply on the next render.
    pub settings: MinmaxSettings,
    tree: TreeBuilder,
    traverse_pipeline: wgpu::ComputePipeline,
    epipole_pipeline: wgpu::ComputePipeline,
    traverse_layout: wgpu::BindGroupLayout,
    buffers: pass::FrameBuffers,
    counters: wgpu::Buffer,
    white: wgpu::TextureView,
    last: Option<Rectification>,
    binds: Binds,
}

/// The traverse pass's bind groups, with the tree builder's count for the trait.
#[derive(Default)]
struct Binds {
    traverse: pass::BindCache<wgpu::BindGroup>,
    tree_builds: u64,
}

impl Binds {
    /// The times the frame's bind groups were (re)built: the traverse pass's are rebuilt with
    /// every new input the tree's are (the tree buffer is in their key), and also for a new
    /// output, so the larger count is the number of rebuilds.
    fn builds(&self) -> u64 {
        self.traverse.builds().max(self.tree_builds)
    }
}

impl MinMax {
    /// Builds the pipelines and buffers.
    pub fn new(gpu: &GpuContext, settings: MinmaxSettings, output: wgpu::TextureFormat) -> Result<Self, Error> {
        settings.validate()?;
        gpu.scoped("creating the minmax pipelines", || {
            let device = &gpu.device;
            let traverse_layout = pass::frame_pass_layout_to(
                device,
                "minmax traverse",
                &[pass::storage_buffer_entry(6, true, None), pass::storage_buffer_entry(7, false, None)],
                output,
            );
            let p = prefiltered::BasisPrecision::Unorm8;
            let traverse_src = pass_source(&pass::with_output(&traverse_wgsl(), output), p);
            let pipe = |entry: &str| {
                pass::compute_pipeline(device, "minmax/traverse.wgsl", &traverse_src, entry, &traverse_layout)
            };
            Self {
                tree: TreeBuilder::new(device),
                traverse_pipeline: pipe("traverse"),
                epipole_pipeline: pipe("epipole"),
                traverse_layout,
                buffers: pass::FrameBuffers::new(device),
                counters: device.create_buffer(&wgpu::BufferDescriptor {
                    label: Some("minmax counters"),
                    size: 32,
                    usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::COPY_SRC,
                    mapped_at_creation: false,
                }),
                white: pass::white_array(gpu),
                last: None,
                binds: Binds::default(),
                settings,
            }
        })
    }

    /// The rectification of the last frame rendered.
    pub fn last_rectification(&self) -> Option<&Rectification> {
        self.last.as_ref()
    }

    /// Bytes of GPU memory this technique holds: the rectified depth, the tree, the counters and
    /// the uniforms.
    pub fn gpu_memory_bytes(&self) -> u64 {
        self.tree.gpu_memory_bytes() + self.buffers.size() + self.counters.size() + 16
    }

    /// Reads back the last frame's rectified depth and tree ([`TreeBuilder::read_maps`]).
    pub fn read_maps(&self, gpu: &GpuContext) -> Result<(Vec<f32>, Vec<[f32; 2]>), Error> {
        self.tree.read_maps(gpu)
    }

    /// Records the in-scattering of `frame` into `output` through `rec`. Passes: `rectify`
    /// (skipped when the frame carries the host's rectified raster and this frame's
    /// rectification is projective), `build`, `traverse`, `epipole` (when the light's disc is on
    /// screen).
    pub fn encode(
        &mut self,
        gpu: &GpuContext,
        rec: &mut Recorder,
        frame: &GpuFrame,
        output: &wgpu::TextureView,
    ) -> Result<TechniqueStats, Error> {
        self.settings.validate()?;
        frame.desc.single_light()?;
        let s = self.settings.clone();
        let desc = frame.desc;
        self.buffers.write(rec, desc);
        let TreeFrame { rect, host } = self.tree.encode(gpu, rec, frame, &s, &self.buffers, true)?;
        self.binds.tree_builds = self.tree.builds();
        let tree = self.tree.tree().expect("built by encode").clone();
        let mut key = pass::frame_key(frame, output);
        key.push(pass::Bound::Buffer(tree.clone()));
        if !self.binds.traverse.is_current(&key) {
            let bind = gpu.scoped("binding the minmax walk", || {
                let mut entries =
                    pass::frame_pass_bindings(&self.buffers, self.tree.params_buffer(), frame, &self.white, output)
                        .to_vec();
                entries.extend([
                    wgpu::BindGroupEntry { binding: 6, resource: tree.as_entire_binding() },
                    wgpu::BindGroupEntry { binding: 7, resource: self.counters.as_entire_binding() },
                ]);
                gpu.device.create_bind_group(&wgpu::BindGroupDescriptor {
                    label: Some("minmax traverse"),
                    layout: &self.traverse_layout,
                    entries: &entries,
                })
            })?;
            self.binds.traverse.store(key, bind);
        }
        let traverse_bind = self.binds.traverse.value();
        rec.pass("traverse", |enc, ts| {
            enc.clear_buffer(&self.counters, 0, None);
            let mut pass = crate::gpu::compute_pass(enc, "minmax traverse", ts);
            pass.set_pipeline(&self.traverse_pipeline);
            pass.set_bind_group(0, traverse_bind, &[]);
            pass.dispatch_workgroups(desc.width.div_ceil(8), desc.height.div_ceil(8), 1);
        })?;
        let epipole = epipole_pixel(desc, s.epipole_radius);
        if let Some([x0, y0, x1, y1]) = epipole_box(desc, s.epipole_radius, epipole) {
            let groups = [(x1 - x0).div_ceil(8), (y1 - y0).div_ceil(8), 1];
            rec.dispatch("epipole", "minmax epipole", &self.epipole_pipeline, traverse_bind, groups)?;
        }
        // The walks are counted on the GPU; their figures join the stats once the counters are
        // read back (never with StatsMode::Off).
        let (settings, rect_c) = (s.clone(), rect.clone());
        rec.read_counters(&self.counters, move |data, stats| {
            let v: &[u32] = bytemuck::cast_slice(&data[..24]);
            let totals = cpu::WalkTotals {
                rays: v[0] as u64,
                nodes: v[1] as u64,
                max_nodes: v[2],
                lit: v[3] as u64,
                shadowed: v[4] as u64,
                over_budget: v[5] as u64,
            };
            stats.extra = stats_extra(&settings, &rect_c, host, Some(&totals));
        });
        let extra = stats_extra(&s, &rect, host, None);
        self.last = Some(rect);
        Ok(TechniqueStats {
            technique: "minmax".into(),
            backend: "gpu".into(),
            timing: String::new(),
            passes: Vec::new(),
            raymarched_samples: epipole_samples(desc, &s.rectified(), epipole),
            gpu_memory_bytes: self.gpu_memory_bytes(),
            extra,
        })
    }
}

impl crate::techniques::Technique for MinmaxSettings {
    const INFO: crate::techniques::TechniqueInfo = crate::techniques::TechniqueInfo {
        name: "minmax",
        summary: "1D min-max mipmaps per row of a rectified shadow map: each view ray skips all-lit and all-shadowed spans and integrates its lit spans exactly (GPU: rectify, build, traverse; CPU mirror)",
        paper: "Chen, Baran, Durand & Jarosz 2011, on the rectification of Klehm, Seidel & Eisemann 2014 §4",
        gpu: true,
        cpu: true,
        per_light: true,
    };
    fn validate(&self) -> Result<(), Error> {
        MinmaxSettings::validate(self)
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

gpu_technique!(MinMax, MinmaxSettings);
