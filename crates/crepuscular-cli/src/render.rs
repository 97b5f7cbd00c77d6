//! One frame, end to end: scene → shadow map, depth and surface (host renderer) → technique →
//! composite. The GPU and CPU backends run the same steps.

use anyhow::{Context, Result, bail};
use crepuscular::frame::{FrameDesc, surface_transmittance};
use crepuscular::gpu::GpuContext;
use crepuscular::stats::{PassTime, TechniqueStats};
use crepuscular::techniques::brute_force::{self, BruteForce, BruteForceSettings};
use crepuscular::techniques::epipolar::{self, Epipolar, EpipolarSettings};
use crepuscular::techniques::interleaved::{self, Interleaved, InterleavedSettings};
use crepuscular::techniques::prefiltered::{self, Prefiltered, PrefilteredSettings};
use crepuscular::techniques::reference::{self, ReferenceSettings};
use crepuscular::techniques::subsampled::{self, Subsampled, SubsampledSettings};
use crepuscular::tonemap::composite;
use crepuscular::{CpuFrame, GpuFrame, Image, ShadowProjection};
use crepuscular_scene::{Geometry, GpuHost, Scene, builtin, file, host, host_cpu};
use serde::Serialize;
use std::path::Path;

/// Where the frame is computed.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Backend {
    /// A GPU adapter if there is one, else the CPU (with a one-line notice).
    Auto,
    /// The GPU; fails if there is no adapter.
    Gpu,
    /// The CPU implementation of every step.
    Cpu,
}

/// Loads a built-in scene by name or a scene file by path.
pub fn load_scene(name_or_path: &str) -> Result<Scene> {
    if let Some(s) = builtin::builtin(name_or_path) {
        return Ok(s);
    }
    let p = Path::new(name_or_path);
    if p.extension().is_some_and(|e| e == "toml") || p.exists() {
        return Ok(file::load_scene_file(p)?);
    }
    let names: Vec<_> = builtin::builtin_names().iter().map(|(n, _)| *n).collect();
    bail!("{name_or_path}: no such built-in scene or scene file (built-in: {})", names.join(", "))
}

/// A technique with its parsed settings.
#[derive(Clone, Debug, Serialize)]
#[serde(tag = "technique", rename_all = "kebab-case")]
pub enum TechniqueChoice {
    /// `brute-force`.
    BruteForce(BruteForceSettings),
    /// `interleaved`.
    Interleaved(InterleavedSettings),
    /// `subsampled`.
    Subsampled(SubsampledSettings),
    /// `epipolar`.
    Epipolar(EpipolarSettings),
    /// `prefiltered`.
    Prefiltered(PrefilteredSettings),
    /// `reference`.
    Reference(ReferenceSettings),
}

/// A technique's GPU side, built once and rendered many times (bench, viewer).
pub enum GpuRunner {
    /// `brute-force`.
    BruteForce(BruteForce),
    /// `interleaved`.
    Interleaved(Interleaved),
    /// `subsampled`.
    Subsampled(Subsampled),
    /// `epipolar`.
    Epipolar(Epipolar),
    /// `prefiltered`.
    Prefiltered(Prefiltered),
}

impl GpuRunner {
    /// Applies the settings of `choice` to this runner in place when it is the same technique,
    /// and returns whether it did. Each technique keeps its pipelines and rebuilds on its next
    /// render only what the changed settings need: `interleaved` its phase table (on
    /// `phase_lut_size`), `subsampled` and `epipolar` their textures (on the grid, slice or
    /// sample counts), `prefiltered` its maps (on `map_size`, `bases`, `bands`) and, on
    /// `precision`, its pipelines (the storage format is in their layout). Everything else is
    /// a uniform, written every frame. Returns false, changing nothing, for another technique
    /// (build a new runner with [`TechniqueChoice::gpu_runner`]).
    pub fn update(&mut self, choice: &TechniqueChoice) -> bool {
        match (self, choice) {
            (GpuRunner::BruteForce(t), TechniqueChoice::BruteForce(s)) => t.settings = s.clone(),
            (GpuRunner::Interleaved(t), TechniqueChoice::Interleaved(s)) => t.settings = s.clone(),
            (GpuRunner::Subsampled(t), TechniqueChoice::Subsampled(s)) => t.settings = s.clone(),
            (GpuRunner::Epipolar(t), TechniqueChoice::Epipolar(s)) => t.settings = s.clone(),
            (GpuRunner::Prefiltered(t), TechniqueChoice::Prefiltered(s)) => t.settings = s.clone(),
            _ => return false,
        }
        true
    }

    /// Renders the in-scattering of `frame` into `output` (Rgba32Float storage, frame size).
    /// `host` is the renderer that drew the frame's textures: `prefiltered` asks it to
    /// rasterize its projective rectified shadow map (Klehm et al. 2014, §4.2); without one it
    /// resamples the map from the shadow map.
    pub fn render(
        &mut self,
        gpu: &GpuContext,
        host: Option<&GpuHost>,
        frame: &GpuFrame,
        output: &wgpu::TextureView,
    ) -> Result<TechniqueStats> {
        if let GpuRunner::Prefiltered(t) = self {
            let (Some(host), Some(request)) = (host, t.raster_request(frame.desc)) else {
                return Ok(t.render(gpu, frame, output)?);
            };
            // The host's rectified raster is part of this technique's frame: timed as a pass by
            // synchronised wall clock.
            let start = std::time::Instant::now();
            let map = host.render_rectified(gpu, &request)?;
            gpu.wait()?;
            let ms = start.elapsed().as_secs_f64() * 1e3;
            let view = map.create_view(&wgpu::TextureViewDescriptor {
                aspect: wgpu::TextureAspect::DepthOnly,
                ..Default::default()
            });
            let mut stats = t.render_with(gpu, frame, Some(&view), output)?;
            stats.passes.insert(0, PassTime { name: "rasterize (host)".into(), ms });
            return Ok(stats);
        }
        Ok(match self {
            GpuRunner::BruteForce(t) => t.render(gpu, frame, output)?,
            GpuRunner::Interleaved(t) => t.render(gpu, frame, output)?,
            GpuRunner::Subsampled(t) => t.render(gpu, frame, output)?,
            GpuRunner::Epipolar(t) => t.render(gpu, frame, output)?,
            GpuRunner::Prefiltered(t) => t.render(gpu, frame, output)?,
        })
    }
}

impl TechniqueChoice {
    /// Name.
    pub fn name(&self) -> &'static str {
        match self {
            TechniqueChoice::BruteForce(_) => "brute-force",
            TechniqueChoice::Interleaved(_) => "interleaved",
            TechniqueChoice::Subsampled(_) => "subsampled",
            TechniqueChoice::Epipolar(_) => "epipolar",
            TechniqueChoice::Prefiltered(_) => "prefiltered",
            TechniqueChoice::Reference(_) => "reference",
        }
    }

    /// The GPU side of the technique (pipelines built here); None for the CPU-only reference.
    pub fn gpu_runner(&self, gpu: &GpuContext) -> Result<Option<GpuRunner>> {
        Ok(match self {
            TechniqueChoice::BruteForce(s) => Some(GpuRunner::BruteForce(BruteForce::new(gpu, s.clone())?)),
            TechniqueChoice::Interleaved(s) => Some(GpuRunner::Interleaved(Interleaved::new(gpu, s.clone())?)),
            TechniqueChoice::Subsampled(s) => Some(GpuRunner::Subsampled(Subsampled::new(gpu, s.clone())?)),
            TechniqueChoice::Epipolar(s) => Some(GpuRunner::Epipolar(Epipolar::new(gpu, s.clone())?)),
            TechniqueChoice::Prefiltered(s) => Some(GpuRunner::Prefiltered(Prefiltered::new(gpu, s.clone())?)),
            TechniqueChoice::Reference(_) => None,
        })
    }

    /// Runs the technique's CPU implementation on a frame; `geometry` (the scene's) lets
    /// `prefiltered` rasterize its projective rectified shadow map as the GPU host does.
    pub fn run_cpu(
        &self,
        frame: &CpuFrame,
        geometry: Option<&Geometry>,
        progress: &(dyn Fn(u64, u64) + Sync),
    ) -> Result<(Image, TechniqueStats)> {
        if let (TechniqueChoice::Prefiltered(s), Some(g)) = (self, geometry) {
            let rect = prefiltered::Rectification::new(frame.desc, &s.rectify_options());
            if let Some(request) = rect.raster() {
                let start = std::time::Instant::now();
                let map = crepuscular_scene::raster::rasterize_rectified(g, &request);
                let ms = start.elapsed().as_secs_f64() * 1e3;
                let (img, mut stats) = prefiltered::cpu::render_with(frame, s, Some(&map))?;
                stats.passes.insert(0, PassTime { name: "rasterize (host)".into(), ms });
                return Ok((img, stats));
            }
        }
        Ok(match self {
            TechniqueChoice::BruteForce(s) => brute_force::cpu::march(frame, s)?,
            TechniqueChoice::Interleaved(s) => interleaved::cpu::render(frame, s)?,
            TechniqueChoice::Subsampled(s) => subsampled::cpu::render(frame, s)?,
            TechniqueChoice::Epipolar(s) => epipolar::cpu::render(frame, s)?,
            TechniqueChoice::Prefiltered(s) => prefiltered::cpu::render(frame, s)?,
            TechniqueChoice::Reference(s) => reference::render(frame, s, progress)?,
        })
    }

    /// Parses a technique's settings from the scene's `[render.<name>]` table and `key=value`
    /// overrides (values in TOML syntax). Errors name the source, key and value.
    pub fn parse(name: &str, scene: &Scene, overrides: &[String]) -> Result<Self> {
        let mut table = scene.render.techniques.get(name).cloned().unwrap_or_default();
        for o in overrides {
            let (k, v) = o.split_once('=').with_context(|| format!("--set {o}: expected key=value"))?;
            let value: toml::Value = toml::from_str::<toml::Table>(&format!("v = {v}"))
                .ok()
                .and_then(|mut t| t.remove("v"))
                .unwrap_or_else(|| toml::Value::String(v.to_string()));
            table.insert(k.trim().to_string(), value);
        }
        let src = format!("{} [render.{name}]", scene.name);
        let parse = |t: toml::Table| -> Result<TechniqueChoice> {
            Ok(match name {
                "brute-force" => {
                    let s: BruteForceSettings = t.try_into().with_context(|| src.clone())?;
                    s.validate().with_context(|| src.clone())?;
                    TechniqueChoice::BruteForce(s)
                }
                "interleaved" => {
                    let s: InterleavedSettings = t.try_into().with_context(|| src.clone())?;
                    s.validate().with_context(|| src.clone())?;
                    TechniqueChoice::Interleaved(s)
                }
                "subsampled" => {
                    let s: SubsampledSettings = t.try_into().with_context(|| src.clone())?;
                    s.validate().with_context(|| src.clone())?;
                    TechniqueChoice::Subsampled(s)
                }
                "epipolar" => {
                    let s: EpipolarSettings = t.try_into().with_context(|| src.clone())?;
                    s.validate().with_context(|| src.clone())?;
                    TechniqueChoice::Epipolar(s)
                }
                "prefiltered" => {
                    let s: PrefilteredSettings = t.try_into().with_context(|| src.clone())?;
                    s.validate().with_context(|| src.clone())?;
                    TechniqueChoice::Prefiltered(s)
                }
                "reference" => TechniqueChoice::Reference(t.try_into().with_context(|| src.clone())?),
                other => {
                    let known: Vec<_> = crepuscular::techniques::TECHNIQUES.iter().map(|t| t.name).collect();
                    bail!("unknown technique `{other}` (known: {})", known.join(", "))
                }
            })
        };
        parse(table).map_err(|e| anyhow::anyhow!("{}", format!("{e:#}").replace('\n', " ")))
    }
}

/// Everything a render produced.
pub struct RenderOutput {
    /// Linear in-scattering L_scatt.
    pub inscatter: Image,
    /// Surface radiance from the host renderer.
    pub surface: Image,
    /// Final radiance L = T(s)·L_surface + L_scatt.
    pub final_radiance: Image,
    /// Camera depth.
    pub depth: Vec<f32>,
    /// Stats, ready for `--stats`.
    pub stats: RenderStats,
}

/// The adapter a frame ran on.
#[derive(Clone, Debug, Serialize)]
pub struct AdapterStats {
    /// Adapter name ("cpu" on the CPU backend).
    pub name: String,
    /// wgpu backend (Vulkan, Metal, …) or "cpu".
    pub backend: String,
    /// Device type.
    pub device_type: String,
    /// Software rasterizer.
    pub software: bool,
    /// Driver and version.
    pub driver: String,
}

/// `--stats` JSON.
#[derive(Clone, Debug, Serialize)]
pub struct RenderStats {
    /// Adapter.
    pub adapter: AdapterStats,
    /// "gpu" or "cpu".
    pub backend: String,
    /// Scene name.
    pub scene: String,
    /// Width, height.
    pub resolution: [u32; 2],
    /// Shadow-map size and layers.
    pub shadow_map: [u32; 2],
    /// Technique and its settings.
    pub settings: TechniqueChoice,
    /// Host renderer passes (shadow map, surface).
    pub host_passes: Vec<PassTime>,
    /// The technique's own stats (passes, samples, memory).
    pub technique: TechniqueStats,
}

/// Options of one render.
pub struct RenderOptions<'a> {
    /// Technique.
    pub technique: TechniqueChoice,
    /// Progress for long CPU work: (done, total).
    pub progress: &'a (dyn Fn(u64, u64) + Sync),
}

/// The frame description of a scene at its render size.
pub fn frame_desc(scene: &Scene) -> FrameDesc {
    let r = &scene.render;
    let aspect = r.width as f32 / r.height as f32;
    let shadow = ShadowProjection::fit(&scene.light, &scene.camera, aspect, scene.geometry.bounds(), r.shadow.size);
    FrameDesc {
        camera: scene.camera.clone(),
        light: scene.light.clone(),
        medium: scene.medium.clone(),
        shadow,
        shadow_bias: r.shadow.bias,
        normal_offset_texels: r.shadow.normal_offset_texels,
        ambient: r.ambient,
        width: r.width,
        height: r.height,
    }
}

/// The adapter a frame runs on: the GPU's name, backend and driver, or the CPU backend.
pub fn adapter_stats(gpu: Option<&GpuContext>) -> AdapterStats {
    match gpu {
        Some(gpu) => {
            let info = &gpu.info;
            AdapterStats {
                name: info.name.clone(),
                backend: format!("{:?}", info.backend),
                device_type: format!("{:?}", info.device_type),
                software: gpu.software,
                driver: format!("{} {}", info.driver, info.driver_info),
            }
        }
        None => AdapterStats {
            name: "cpu".into(),
            backend: "cpu".into(),
            device_type: "Cpu".into(),
            software: true,
            driver: format!("rayon, {} threads", rayon::current_num_threads()),
        },
    }
}

/// Picks the GPU for a backend choice: Some(context) or None for the CPU.
pub fn open_gpu(backend: Backend, notice: &dyn Fn(&str)) -> Result<Option<GpuContext>> {
    match backend {
        Backend::Cpu => Ok(None),
        Backend::Gpu => Ok(Some(GpuContext::new().context("--backend gpu")?)),
        Backend::Auto => match GpuContext::new() {
            Ok(g) => Ok(Some(g)),
            Err(e) => {
                notice(&format!("notice: {e}; rendering on the CPU backend"));
                Ok(None)
            }
        },
    }
}

/// Renders a scene with a technique.
pub fn render(scene: &Scene, gpu: Option<&GpuContext>, opts: &RenderOptions) -> Result<RenderOutput> {
    let desc = frame_desc(scene);
    let spot = match &scene.light {
        crepuscular::Light::Spot { texture, .. } => texture.as_deref(),
        _ => None,
    };
    let (inscatter, surface, depth, host_passes, technique, adapter) = match gpu {
        Some(gpu) => {
            let host = GpuHost::new(gpu, &scene.geometry)?;
            let tex = host.render(gpu, &desc, spot)?;
            let adapter = adapter_stats(Some(gpu));
            let depth = gpu.read_texture_f32(&tex.depth, 0)?;
            let surface = gpu.read_image(&tex.surface)?;
            let (inscatter, stats) = match opts.technique.gpu_runner(gpu)? {
                Some(mut runner) => {
                    let out = gpu.create_output_texture(desc.width, desc.height);
                    let out_view = out.create_view(&Default::default());
                    let views = tex.views();
                    let frame = views.frame(&desc);
                    let stats = runner.render(gpu, Some(&host), &frame, &out_view)?;
                    (gpu.read_image(&out)?, stats)
                }
                None => {
                    // CPU-only techniques (the reference) run over the very shadow map the GPU drew.
                    let shadow_map = host::read_shadow_map(gpu, &tex, &desc)?;
                    let frame =
                        CpuFrame { desc: &desc, depth: &depth, shadow_map: &shadow_map, surface: Some(&surface) };
                    opts.technique.run_cpu(&frame, Some(&scene.geometry), opts.progress)?
                }
            };
            (inscatter, surface, depth, tex.passes, stats, adapter)
        }
        None => {
            let h = host_cpu::render(&scene.geometry, &desc);
            let frame = CpuFrame { desc: &desc, depth: &h.depth, shadow_map: &h.shadow_map, surface: Some(&h.surface) };
            let (inscatter, stats) = opts.technique.run_cpu(&frame, Some(&scene.geometry), opts.progress)?;
            (inscatter, h.surface, h.depth, h.passes, stats, adapter_stats(None))
        }
    };
    if !inscatter.all_finite() {
        bail!(
            "{}: the technique produced non-finite values (NaN/Inf) — a bug, please report it",
            opts.technique.name()
        );
    }
    let t = surface_transmittance(&desc, &depth);
    let final_radiance = composite(&surface, &inscatter, &t);
    let stats = RenderStats {
        backend: if gpu.is_some() { "gpu".into() } else { "cpu".into() },
        adapter,
        scene: scene.name.clone(),
        resolution: [desc.width, desc.height],
        shadow_map: [desc.shadow.size, desc.shadow.layers],
        settings: opts.technique.clone(),
        host_passes,
        technique,
    };
    Ok(RenderOutput { inscatter, surface, final_radiance, depth, stats })
}

/// A debug view of `render --debug`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum DebugView {
    /// `epipolar`: Engelhardt & Dachsbacher 2010, Fig. 9 bottom — every valid epipolar line's
    /// texels drawn faint over the final image, the initial ray-march samples in red and the
    /// samples the refinement placed at depth discontinuities in green.
    Classification,
    /// `epipolar`: the radiance texture (one row per epipolar line, one column per sample
    /// along it; culled lines black), scaled up to at least 1024 pixels wide.
    Radiance,
    /// `interleaved`: the interleaving pattern (Tóth & Umenhoffer 2009 §4.1) — each pixel
    /// coloured by its offset k of the M×M block (which of the N/M² terms of eq. 1 it
    /// marches), blended half and half over the final image.
    Pattern,
    /// `prefiltered`: the rectified shadow map (Klehm et al. 2014, §2.2, §4) — one row per
    /// epipolar slice, view rays left to right, grey = normalised occluder depth (white:
    /// unoccluded).
    RectifiedMap,
    /// `prefiltered`: the first filtered-basis layer (bases 0–2 as RGB), the prefix-summed
    /// Fourier bases as stored (§3.3, Appendix A).
    Basis,
    /// `prefiltered`: the prefiltered average visibility of every pixel's ray (Listing 4), the
    /// ray-marched epipole disc (§5) in red.
    Visibility,
}

impl DebugView {
    /// Name, as on the command line.
    pub fn name(self) -> &'static str {
        match self {
            DebugView::Classification => "classification",
            DebugView::Radiance => "radiance",
            DebugView::Pattern => "pattern",
            DebugView::RectifiedMap => "rectified-map",
            DebugView::Basis => "basis",
            DebugView::Visibility => "visibility",
        }
    }

    /// The debug views `technique` has (empty: none).
    pub fn of(technique: &TechniqueChoice) -> &'static [DebugView] {
        match technique {
            TechniqueChoice::Epipolar(_) => &[DebugView::Classification, DebugView::Radiance],
            TechniqueChoice::Interleaved(_) => &[DebugView::Pattern],
            TechniqueChoice::Prefiltered(_) => &[DebugView::RectifiedMap, DebugView::Basis, DebugView::Visibility],
            _ => &[],
        }
    }
}

/// A colour per block offset k of `m2` = M² offsets: a hue wheel, so neighbouring offsets differ.
fn offset_colour(k: u32, m2: u32) -> [f32; 3] {
    let h = (k as f32 + 0.5) / m2.max(1) as f32 * 6.0;
    // Hue → RGB at full saturation: each channel a trapezoid on the wheel, a third apart.
    let c = |n: f32| 1.0 - (((n + h) % 6.0 - 3.0).abs() - 1.0).clamp(0.0, 1.0);
    [c(0.0), c(4.0), c(2.0)]
}

/// Renders `view` for the frame `render` drew (`final_radiance` is that frame's final image,
/// the background of the classification). Runs the technique again with its debug readbacks,
/// on the same backend. Returns a linear image (tone-map it like the final image).
pub fn debug_view(
    scene: &Scene,
    gpu: Option<&GpuContext>,
    technique: &TechniqueChoice,
    view: DebugView,
    final_radiance: &Image,
) -> Result<Image> {
    if !DebugView::of(technique).contains(&view) {
        bail!("--debug {}: not a debug view of `{}` ({})", view.name(), technique.name(), debug_view_list());
    }
    if let TechniqueChoice::Interleaved(s) = technique {
        let m2 = s.block * s.block;
        let mut img = final_radiance.clone();
        for y in 0..img.height {
            for x in 0..img.width {
                let c = offset_colour(interleaved::cpu::block_offset(s, x, y), m2);
                let p = &mut img.pixels[(y * img.width + x) as usize];
                for i in 0..3 {
                    p[i] = 0.5 * p[i] + 0.5 * c[i];
                }
            }
        }
        return Ok(img);
    }
    if let TechniqueChoice::Prefiltered(s) = technique {
        return prefiltered_debug_view(scene, gpu, s, view);
    }
    let TechniqueChoice::Epipolar(settings) = technique else {
        bail!("--debug {}: not a debug view of `{}`", view.name(), technique.name());
    };
    let desc = frame_desc(scene);
    let debug = match gpu {
        Some(gpu) => {
            let spot = match &scene.light {
                crepuscular::Light::Spot { texture, .. } => texture.as_deref(),
                _ => None,
            };
            let host = GpuHost::new(gpu, &scene.geometry)?;
            let tex = host.render(gpu, &desc, spot)?;
            let mut runner = Epipolar::new(gpu, settings.clone())?;
            let out = gpu.create_output_texture(desc.width, desc.height);
            let views = tex.views();
            let frame = views.frame(&desc);
            runner.render(gpu, &frame, &out.create_view(&Default::default()))?;
            runner.read_debug(gpu)?
        }
        None => {
            let h = host_cpu::render(&scene.geometry, &desc);
            let frame = CpuFrame { desc: &desc, depth: &h.depth, shadow_map: &h.shadow_map, surface: Some(&h.surface) };
            epipolar::cpu::render_with_debug(&frame, settings)?.2
        }
    };
    Ok(match view {
        DebugView::Classification => epipolar::debug::classification_view(&debug, final_radiance),
        DebugView::Radiance => {
            let scale = 1024u32.div_ceil(debug.samples().max(1)).clamp(1, 16);
            epipolar::debug::radiance_view(&debug, scale)
        }
        other => bail!("--debug {}: not a debug view of `epipolar`", other.name()),
    })
}

/// `prefiltered`'s debug views: the frame rendered on the backend (with the host's rectified
/// raster where the rectification is projective), its maps read back, and the view drawn.
fn prefiltered_debug_view(
    scene: &Scene,
    gpu: Option<&GpuContext>,
    settings: &PrefilteredSettings,
    view: DebugView,
) -> Result<Image> {
    use prefiltered::debug;
    let desc = frame_desc(scene);
    let (passes, depth) = match gpu {
        Some(gpu) => {
            let spot = match &scene.light {
                crepuscular::Light::Spot { texture, .. } => texture.as_deref(),
                _ => None,
            };
            let host = GpuHost::new(gpu, &scene.geometry)?;
            let tex = host.render(gpu, &desc, spot)?;
            let mut runner = GpuRunner::Prefiltered(Prefiltered::new(gpu, settings.clone())?);
            let out = gpu.create_output_texture(desc.width, desc.height);
            let views = tex.views();
            runner.render(gpu, Some(&host), &views.frame(&desc), &out.create_view(&Default::default()))?;
            let GpuRunner::Prefiltered(t) = runner else { unreachable!("built above") };
            let rect = t.last_rectification().context("no frame rendered")?.clone();
            (
                debug::passes_from_gpu(rect, settings.channels(&desc.light), t.read_maps(gpu)?),
                gpu.read_texture_f32(&tex.depth, 0)?,
            )
        }
        None => {
            let h = host_cpu::render(&scene.geometry, &desc);
            let frame = CpuFrame { desc: &desc, depth: &h.depth, shadow_map: &h.shadow_map, surface: Some(&h.surface) };
            let rect = prefiltered::Rectification::new(&desc, &settings.rectify_options());
            let raster = rect.raster().map(|r| crepuscular_scene::raster::rasterize_rectified(&scene.geometry, &r));
            (prefiltered::cpu::passes(&frame, settings, raster.as_deref())?.0, h.depth)
        }
    };
    Ok(match view {
        DebugView::RectifiedMap => debug::rectified_map_view(&passes),
        DebugView::Basis => debug::basis_view(&passes, 0),
        DebugView::Visibility => {
            let epipole = prefiltered::epipole_pixel(&desc, settings.epipole_radius);
            debug::visibility_view(&passes, &desc, &depth, settings.bases, epipole, settings.epipole_radius)
        }
        other => bail!("--debug {}: not a debug view of `prefiltered`", other.name()),
    })
}

/// "epipolar: classification, radiance; interleaved: pattern" — for error messages and help.
pub fn debug_view_list() -> &'static str {
    "debug views: epipolar — classification, radiance; interleaved — pattern; prefiltered — rectified-map, basis, visibility"
}
