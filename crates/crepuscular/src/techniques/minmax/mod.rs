//! Technique `minmax`: single scattering through 1D min-max mipmaps on a rectified shadow map
//! (Chen, Baran, Durand & Jarosz 2011), the competitor Klehm, Seidel & Eisemann 2014 measure
//! their filtered technique against (§5, Fig. 5). On the rectified map `prefiltered` builds
//! (prefiltered/rectify.rs: every view ray runs along one row at one constant depth), each row
//! gets a binary tree of (min, max) depths; a view ray walks its row from the camera to its
//! surface, skipping every node that is entirely lit or entirely shadowed for its depth, and
//! integrates its lit spans in closed form. Where the rectified map resamples the standard
//! shadow map, a texel of the tree's level 0 holds the min and max of the standard texels it
//! covers (conservative), and a ray that a texel leaves undecided (a shadow edge crosses it)
//! looks the standard map up along its span there; so the result is exact at the standard
//! map's resolution, and where the host rasterized the map, at the rectified map's
//! (docs/MODEL.md §8): no step count, and a cost that grows with how often the visibility along
//! the ray changes, not with the ray's length.
//!
//! Passes (GPU, and their CPU mirror in `cpu.rs`):
//!
//! 1. `build` (build.wgsl, bounds.wgsl): the min-max tree of every row, one workgroup per row:
//!    level 0 the host's rasterized rectified map
//!    ([`crate::techniques::Technique::raster_request`]) or the bounds of the standard
//!    shadow-map texels each rectified texel covers.
//! 2. `traverse` (traverse.wgsl): per pixel, the walk (Chen et al. 2011 §3.2), the exact
//!    integral of its lit spans and the lookups of its mixed texels; the walks' counts go to a
//!    counter buffer read after the frame.
//! 3. `epipole` (prefiltered/epipole.wgsl): the disc around a visible light, ray-marched, as
//!    `prefiltered` does.

pub mod cpu;
pub mod settings;

pub use settings::MinmaxSettings;

use crate::error::Error;
use crate::frame::GpuFrame;
use crate::gpu::{GpuContext, Recorder};
use crate::march::mean_extinction;
use crate::stats::TechniqueStats;
use crate::techniques::pass::{self, Pass};
use crate::techniques::prefiltered::{
    self, EPIPOLE_WGSL, Mode, PrefilteredParams, RESAMPLE_WGSL, Rectification, RectifiedRaster, epipole_box,
    epipole_pixel, epipole_samples, pass_source,
};
use std::collections::BTreeMap;

/// Pass `build`.
pub const BUILD_WGSL: &str = include_str!("build.wgsl");
/// Level 0 of the tree from the standard shadow map (`texel_bounds`), used by `build`.
pub const BOUNDS_WGSL: &str = include_str!("bounds.wgsl");

fn build_wgsl() -> String {
    format!("{RESAMPLE_WGSL}\n{BOUNDS_WGSL}\n{BUILD_WGSL}")
}
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
        ("minmax/build", pass_source(&build_wgsl(), p), "build"),
        ("minmax/traverse", pass_source(&traverse_wgsl(), p), "traverse"),
        ("minmax/epipole", pass_source(&traverse_wgsl(), p), "epipole"),
    ]
}

/// The uniform block of every pass: `prefiltered`'s (one band, one region), with the tree's
/// levels and the node budget in `tree_levels` and `max_nodes`.
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
    p.tree_levels = s.tree_levels();
    p.max_nodes = s.max_nodes;
    p
}

/// `TechniqueStats::extra` of a frame: the rectification, the tree's size and memory, and —
/// once the walks are counted (`totals`) — nodes visited per ray (mean, max), lit and shadowed
/// nodes per ray, mixed texels looked up in the standard map per ray, and the rays that
/// reached the node budget.
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
        m.insert("mixed_texels_per_ray".into(), per_ray(t.mixed));
    }
    m
}

/// The tree buffer, reallocated when the map size changes.
struct TreeBuffer {
    tree: wgpu::Buffer,
    key: [u32; 2],
}

/// What `TreeBuilder::encode` recorded for a frame.
pub struct TreeFrame {
    /// The frame's rectification.
    pub rect: Rectification,
    /// The host's rectified raster was used (projective frames).
    pub host: bool,
}

/// The min-max structure of a one-light frame on the GPU: pass `build`, into a tree buffer and
/// the uniform block the walk reads. `minmax` walks it per pixel; `epipolar` with
/// `march = "minmax"` per ray-march sample (Yusov 2013). Its frame uniforms and lights are the
/// owner's ([`pass::FrameBuffers`], written by the owner before `TreeBuilder::encode`).
pub struct TreeBuilder {
    build: Pass,
    params_buffer: wgpu::Buffer,
    /// Bound in the host raster's place where the map is resampled (never read there).
    no_raster: wgpu::TextureView,
    tree: Option<TreeBuffer>,
    binds: pass::BindCache<wgpu::BindGroup>,
}

impl TreeBuilder {
    /// Builds the pass.
    pub(crate) fn new(device: &wgpu::Device) -> Result<Self, Error> {
        let src = pass_source(&build_wgsl(), prefiltered::BasisPrecision::Unorm8);
        let no_raster = crate::gpu::storage_texture(device, "minmax no raster", wgpu::TextureFormat::R32Float, 1, 1)
            .create_view(&Default::default());
        Ok(Self {
            build: Pass::new(device, "minmax/build", &src, "build")?,
            params_buffer: pass::uniform_buffer(
                device,
                "minmax params",
                std::mem::size_of::<PrefilteredParams>() as u64,
            ),
            no_raster,
            tree: None,
            binds: Default::default(),
        })
    }

    /// The uniform block of the last frame (`Params` of the walk).
    pub fn params_buffer(&self) -> &wgpu::Buffer {
        &self.params_buffer
    }

    /// The tree of the last frame (`2·columns` (min, max) pairs per row); None before the first.
    pub fn tree(&self) -> Option<&wgpu::Buffer> {
        self.tree.as_ref().map(|m| &m.tree)
    }

    /// Bytes held: the tree and the uniforms.
    pub fn gpu_memory_bytes(&self) -> u64 {
        self.tree.as_ref().map_or(0, |m| m.tree.size()) + self.params_buffer.size()
    }

    /// Records `build` for `frame` under `s` (from the frame's rectified raster where
    /// `host_raster` and the rectification is projective, else from its standard shadow map);
    /// `buffers` hold the frame's uniforms and lights.
    pub(crate) fn encode(
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
        let rect = Rectification::new(desc, &s.rectify_options());
        let host = frame.rectified_shadow_map().filter(|_| host_raster && reads_host_raster(desc, &rect));
        if let Some(view) = host {
            let size = view.texture().size();
            if [size.width, size.height] != [w, h] {
                return Err(Error::invalid(
                    "minmax host raster",
                    format!("{}x{}", size.width, size.height),
                    format!("must be map_size {w}x{h}"),
                ));
            }
        }
        if self.tree.as_ref().is_none_or(|m| m.key != [w, h]) {
            let limit = gpu.device.limits().max_storage_buffer_binding_size;
            if s.tree_bytes() > limit {
                return Err(Error::Limit {
                    what: "minmax tree (16 bytes × map_size[0] × map_size[1])".into(),
                    value: s.tree_bytes(),
                    limit,
                });
            }
            self.tree = None;
            self.tree = Some(gpu.scoped("allocating the minmax tree", || TreeBuffer {
                tree: gpu.device.create_buffer(&wgpu::BufferDescriptor {
                    label: Some("minmax tree"),
                    size: s.tree_bytes(),
                    usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
                    mapped_at_creation: false,
                }),
                key: [w, h],
            })?);
        }
        let epipole = epipole_pixel(desc, s.epipole_radius);
        let p = params(s, &rect, desc, epipole, host.is_some());
        rec.write_buffer(&self.params_buffer, bytemuck::bytes_of(&p));
        let tree = &self.tree.as_ref().expect("allocated above").tree;
        let raster = host.unwrap_or(&self.no_raster);
        let mut key = pass::frame_key(frame, raster);
        key.push(pass::Bound::Buffer(tree.clone()));
        if !self.binds.is_current(&key) {
            let bind = gpu.try_scoped("binding the minmax inputs", || {
                let view = wgpu::BindingResource::TextureView;
                let resources = pass::with(
                    pass::uniform_resources(buffers, &self.params_buffer),
                    [
                        ("depth_map", view(raster)),
                        ("shadow_map", view(frame.shadow_maps)),
                        ("tree", tree.as_entire_binding()),
                    ],
                );
                self.build.bind(&gpu.device, &resources)
            })?;
            self.binds.store(key, bind);
        }
        // One workgroup per row of the map.
        self.build.dispatch(rec, frame.shader_variant(), "build", self.binds.value(), [h, 1, 1])?;
        Ok(TreeFrame { rect, host: host.is_some() })
    }

    /// Reads back the last frame's tree (`2·width` (min, max) pairs per row), laid out as
    /// [`cpu::Passes::tree`], for tests and debug views.
    pub fn read_tree(&self, gpu: &GpuContext) -> Result<Vec<[f32; 2]>, Error> {
        let m = self.tree.as_ref().ok_or_else(|| Error::invalid("minmax tree", "none", "render a frame first"))?;
        Ok(bytemuck::cast_slice(&crate::scattering::read_buffer(gpu, &m.tree)?).to_vec())
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
    traverse: Pass,
    epipole: Pass,
    buffers: pass::FrameBuffers,
    counters: wgpu::Buffer,
    white: wgpu::TextureView,
    last: Option<Rectification>,
    binds: Binds,
}

/// The traverse and epipole passes' bind groups, with the tree builder's count for the trait.
#[derive(Default)]
struct Binds {
    traverse: pass::BindCache<[wgpu::BindGroup; 2]>,
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
    pub(crate) fn new(gpu: &GpuContext, settings: MinmaxSettings, output: wgpu::TextureFormat) -> Result<Self, Error> {
        settings.validate()?;
        gpu.try_scoped("creating the minmax pipelines", || {
            let device = &gpu.device;
            let p = prefiltered::BasisPrecision::Unorm8;
            let traverse_src = pass_source(&pass::with_output(&traverse_wgsl(), output), p);
            Ok(Self {
                tree: TreeBuilder::new(device)?,
                traverse: Pass::new(device, "minmax/traverse", &traverse_src, "traverse")?,
                epipole: Pass::new(device, "minmax/epipole", &traverse_src, "epipole")?,
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
            })
        })
    }

    /// The rectification of the last frame rendered.
    pub fn last_rectification(&self) -> Option<&Rectification> {
        self.last.as_ref()
    }

    /// Bytes of GPU memory this technique holds: the tree, the counters and the uniforms.
    pub fn gpu_memory_bytes(&self) -> u64 {
        self.tree.gpu_memory_bytes() + self.buffers.size() + self.counters.size() + 16
    }

    /// Reads back the last frame's tree ([`TreeBuilder::read_tree`]).
    pub fn read_tree(&self, gpu: &GpuContext) -> Result<Vec<[f32; 2]>, Error> {
        self.tree.read_tree(gpu)
    }

    /// Records the in-scattering of `frame` into `output` through `rec`. Passes: `build` (from
    /// the host's rectified raster when the frame carries one and this frame's rectification is
    /// projective, else from the standard shadow map), `traverse`, `epipole` (when the light's
    /// disc is on screen).
    pub(crate) fn encode(
        &mut self,
        gpu: &GpuContext,
        rec: &mut Recorder,
        frame: &GpuFrame,
        output: &wgpu::TextureView,
    ) -> Result<TechniqueStats, Error> {
        self.settings.validate()?;
        frame.desc.single_light()?;
        let desc = frame.desc;
        let s = self.settings.for_frame(desc);
        self.buffers.write(rec, desc);
        let TreeFrame { rect, host } = self.tree.encode(gpu, rec, frame, &s, &self.buffers, true)?;
        self.binds.tree_builds = self.tree.builds();
        let tree = self.tree.tree().expect("built by encode").clone();
        let mut key = pass::frame_key(frame, output);
        key.push(pass::Bound::Buffer(tree.clone()));
        if !self.binds.traverse.is_current(&key) {
            let binds = gpu.try_scoped("binding the minmax walk", || {
                let res = pass::with(
                    pass::frame_resources(&self.buffers, self.tree.params_buffer(), frame, &self.white),
                    [
                        ("tree", tree.as_entire_binding()),
                        ("counters", self.counters.as_entire_binding()),
                        ("out_tex", wgpu::BindingResource::TextureView(output)),
                    ],
                );
                Ok([self.traverse.bind(&gpu.device, &res)?, self.epipole.bind(&gpu.device, &res)?])
            })?;
            self.binds.traverse.store(key, binds);
        }
        let [traverse_bind, epipole_bind] = self.binds.traverse.value();
        let variant = frame.shader_variant();
        rec.pass("traverse", |enc, ts| {
            enc.clear_buffer(&self.counters, 0, None);
            let mut pass = crate::gpu::compute_pass(enc, self.traverse.label(), ts);
            pass.set_pipeline(self.traverse.pipeline(variant));
            pass.set_bind_group(0, traverse_bind, &[]);
            let [x, y, z] = self.traverse.groups_2d(desc.width, desc.height);
            pass.dispatch_workgroups(x, y, z);
        })?;
        let epipole = epipole_pixel(desc, s.epipole_radius);
        if let Some([x0, y0, x1, y1]) = epipole_box(desc, s.epipole_radius, epipole) {
            self.epipole.dispatch(rec, variant, "epipole", epipole_bind, self.epipole.groups_2d(x1 - x0, y1 - y0))?;
        }
        // The walks are counted on the GPU; their figures join the stats once the counters are
        // read back (never with StatsMode::Off).
        let (settings, rect_c) = (s.clone(), rect.clone());
        rec.read_counters(&self.counters, move |data, stats| {
            let v: &[u32] = bytemuck::cast_slice(&data[..28]);
            let totals = cpu::WalkTotals {
                rays: v[0] as u64,
                nodes: v[1] as u64,
                max_nodes: v[2],
                lit: v[3] as u64,
                shadowed: v[4] as u64,
                over_budget: v[5] as u64,
                mixed: v[6] as u64,
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
        summary: "1D min-max mipmaps per row of a rectified shadow map: each view ray skips all-lit and all-shadowed spans, integrates its lit spans exactly and looks its mixed texels up in the standard shadow map (GPU: build, traverse; CPU mirror)",
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
        let rect = Rectification::new(desc, &self.rectify_options());
        if !reads_host_raster(desc, &rect) {
            return None;
        }
        rect.raster()
    }
}

/// Whether level 0 of the tree comes from a rectified map the host rasterized, where one is
/// given: a projective rectification under the nearest shadow filter. That raster is one
/// depth per rectified texel, the shadow test itself at the rectified map's resolution; the
/// bilinear filter's answer blends the standard map's texels, so under it level 0 always
/// bounds the standard map and mixed texels are resolved there (docs/MODEL.md §8).
pub(crate) fn reads_host_raster(desc: &crate::frame::FrameDesc, rect: &Rectification) -> bool {
    rect.mode == Mode::Projective && desc.lights[0].shadow_filter == crate::shadow::ShadowFilter::Nearest
}

gpu_technique!(MinMax, MinmaxSettings);
