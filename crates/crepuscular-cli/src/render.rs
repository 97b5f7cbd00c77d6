//! One frame, end to end: scene → shadow map, depth and surface (host renderer) → technique →
//! composite. The GPU and CPU backends run the same steps.

use anyhow::{Context, Result, bail};
use crepuscular::frame::{FrameDesc, surface_transmittance};
use crepuscular::gpu::GpuContext;
use crepuscular::stats::{PassTime, TechniqueStats};
use crepuscular::tonemap::composite;
use crepuscular::{
    Composite, CompositeInputs, CompositeTarget, CpuFrame, GpuFrame, Image, Scattering, StatsMode, TechniqueSettings,
};
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

/// The options [`load_scene`] reads after a scene's name, each `:key=value`.
const SCENE_OPTIONS: [&str; 2] = ["lights", "shadow_filter"];

/// The last option after a scene's name, as (the name before it, key, value), where the text
/// after the last `:` is `key=value` with a key of [`SCENE_OPTIONS`].
fn last_option(name_or_path: &str) -> Option<(&str, &str, &str)> {
    let (base, option) = name_or_path.rsplit_once(':')?;
    let (key, value) = option.split_once('=')?;
    SCENE_OPTIONS.contains(&key).then_some((base, key, value))
}

/// The scene's name or path without the options [`load_scene`] reads after it
/// (`colonnade:shadow_filter=bilinear` → `colonnade`): what a built-in scene is known by, for
/// lookups by name such as its `animate` path.
pub fn scene_base(name_or_path: &str) -> &str {
    match last_option(name_or_path) {
        Some((base, _, _)) => scene_base(base),
        None => name_or_path,
    }
}

/// Loads a built-in scene by name or a scene file by path, with options after it, each
/// `:key=value`, in any order:
///
/// - `NAME:lights=N` keeps the scene's first N lights (what `bench --preset lights` sweeps);
///   `NAME:lights=0` keeps the first light with its scattering off, so that no light reaches
///   the effect (its light-independent cost).
/// - `NAME:shadow_filter=bilinear` (or `nearest`) reads every light's shadow map with that
///   filter (the scene file's `render.shadow_filter`; `crepuscular::ShadowFilter`).
pub fn load_scene(name_or_path: &str) -> Result<Scene> {
    if let Some((base, key, value)) = last_option(name_or_path) {
        if key == "lights" {
            let n: usize =
                value.parse().with_context(|| format!("{name_or_path}: `lights=` takes a count, not `{value}`"))?;
            let mut scene = load_scene(base)?;
            if n > scene.lights.len() {
                let count = scene.lights.len();
                bail!("{name_or_path}: lights={n}: `{}` has {count} light(s); keep 0 to {count}", scene.name);
            }
            scene.lights.truncate(n.max(1));
            if n == 0 {
                scene.lights[0].scattering = 0.0;
            }
            scene.name = format!("{}:lights={n}", scene.name);
            return Ok(scene);
        }
        // The other key of SCENE_OPTIONS: shadow_filter.
        let filter = crepuscular::ShadowFilter::parse(value).map_err(|e| anyhow::anyhow!("{name_or_path}: {e}"))?;
        let mut scene = load_scene(base)?;
        scene.render.shadow.filter = filter;
        scene.name = format!("{}:shadow_filter={}", scene.name, filter.name());
        return Ok(scene);
    }
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

/// A technique's settings from the scene's `[render.<name>]` table and `key=value` overrides
/// (values in TOML syntax). Errors name the source, key and value.
pub fn parse_technique(name: &str, scene: &Scene, overrides: &[String]) -> Result<TechniqueSettings> {
    let table = scene.render.techniques.get(name).cloned().unwrap_or_default();
    parse_technique_table(name, table, &format!("{} [render.{name}]", scene.name), overrides)
}

/// [`parse_technique`] over a settings table of the caller's (`src` names it in errors).
pub fn parse_technique_table(
    name: &str,
    table: toml::Table,
    src: &str,
    overrides: &[String],
) -> Result<TechniqueSettings> {
    let table = with_overrides("--set", table, overrides)?;
    let src = src.to_string();
    let parse = || -> Result<TechniqueSettings> {
        let settings = TechniqueSettings::deserialize_named(name, toml::Value::Table(table))
            .with_context(|| src.clone())?
            .ok_or_else(|| TechniqueSettings::named(name).expect_err("unknown name"))?;
        settings.validate().with_context(|| src.clone())?;
        Ok(settings)
    };
    parse().map_err(|e| anyhow::anyhow!("{}", format!("{e:#}").replace('\n', " ")))
}

/// `table` with each `key=value` of `overrides` set (the value read as a TOML value, else as a
/// string); `flag` names the option in errors.
fn with_overrides(flag: &str, mut table: toml::Table, overrides: &[String]) -> Result<toml::Table> {
    for o in overrides {
        let (k, v) = o.split_once('=').with_context(|| format!("{flag} {o}: expected key=value"))?;
        let value: toml::Value = toml::from_str::<toml::Table>(&format!("v = {v}"))
            .ok()
            .and_then(|mut t| t.remove("v"))
            .unwrap_or_else(|| toml::Value::String(v.to_string()));
        table.insert(k.trim().to_string(), value);
    }
    Ok(table)
}

/// The temporal stage's settings from `key=value` overrides (`--temporal-set`) over the
/// defaults; errors name the key and value.
pub fn parse_temporal(overrides: &[String]) -> Result<crepuscular::TemporalSettings> {
    let table = with_overrides("--temporal-set", toml::Table::new(), overrides)?;
    let settings: crepuscular::TemporalSettings = toml::Value::Table(table)
        .try_into()
        .map_err(|e| anyhow::anyhow!("--temporal-set: {}", e.to_string().replace('\n', " ")))?;
    settings.validate().map_err(|e| anyhow::anyhow!("--temporal-set: {e}"))?;
    Ok(settings)
}

/// How the tools measure a GPU technique: synchronised wall clock on software adapters (their
/// timestamps mean nothing), timestamp queries read back after the frame on hardware.
pub fn tool_stats_mode(gpu: &GpuContext) -> StatsMode {
    if gpu.software { StatsMode::WallClock } else { StatsMode::Deferred }
}

/// The technique's GPU side for the tools (pipelines built here); None for CPU-only techniques
/// (the reference).
pub fn scattering(gpu: &GpuContext, settings: &TechniqueSettings) -> Result<Option<Scattering>> {
    if !settings.has_gpu() {
        return Ok(None);
    }
    Ok(Some(Scattering::from_gpu(gpu, settings.clone())?.with_stats(tool_stats_mode(gpu))?))
}

/// Renders the in-scattering of `frame` into `output` (Rgba32Float storage, frame size) and
/// waits for it. `host` is the renderer that drew the frame's textures: where the technique
/// asks for a host raster (`prefiltered`'s projective rectified shadow map, Klehm et al. 2014,
/// §4.2) the host draws it, timed by synchronised wall clock as the frame's first pass; without
/// a host the technique resamples the map from the shadow map.
pub fn render_gpu(
    scattering: &mut Scattering,
    host: Option<&GpuHost>,
    frame: &GpuFrame,
    output: &wgpu::TextureView,
) -> Result<TechniqueStats> {
    let requests = scattering.raster_requests(frame.desc);
    let Some(host) = host.filter(|_| requests.iter().any(Option::is_some)) else {
        return Ok(scattering.render(frame, output)?);
    };
    let gpu = scattering.gpu().clone();
    let start = std::time::Instant::now();
    let maps = requests
        .iter()
        .map(|r| r.as_ref().map(|request| host.render_rectified(&gpu, request)).transpose())
        .collect::<Result<Vec<_>, _>>()?;
    gpu.wait()?;
    let ms = start.elapsed().as_secs_f64() * 1e3;
    let views: Vec<Option<wgpu::TextureView>> = maps
        .iter()
        .map(|m| {
            m.as_ref().map(|m| {
                m.create_view(&wgpu::TextureViewDescriptor {
                    aspect: wgpu::TextureAspect::DepthOnly,
                    ..Default::default()
                })
            })
        })
        .collect();
    let refs: Vec<Option<&wgpu::TextureView>> = views.iter().map(Option::as_ref).collect();
    let mut stats = scattering.render(&GpuFrame { rectified_shadow_maps: &refs, ..*frame }, output)?;
    TechniqueSettings::with_host_raster(&mut stats, ms);
    Ok(stats)
}

/// Runs the technique's CPU implementation on a frame; `geometry` (the scene's) lets
/// `prefiltered` rasterize its projective rectified shadow map as the GPU host does.
pub fn render_cpu(
    settings: &TechniqueSettings,
    frame: &CpuFrame,
    geometry: Option<&Geometry>,
    progress: &(dyn Fn(u64, u64) + Sync),
) -> Result<(Image, TechniqueStats)> {
    let start = std::time::Instant::now();
    let maps: Vec<Option<Vec<f32>>> = match geometry {
        Some(g) => settings
            .raster_requests(frame.desc)
            .iter()
            .map(|r| r.as_ref().map(|request| crepuscular_scene::raster::rasterize_rectified(g, request)))
            .collect(),
        None => Vec::new(),
    };
    let ms = start.elapsed().as_secs_f64() * 1e3;
    let refs: Vec<Option<&[f32]>> = maps.iter().map(|m| m.as_deref()).collect();
    let (img, mut stats) = settings.render_cpu(frame, &refs, progress)?;
    if refs.iter().any(Option::is_some) {
        TechniqueSettings::with_host_raster(&mut stats, ms);
    }
    Ok((img, stats))
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
    /// The frame's lights.
    pub lights: usize,
    /// The lights that reach the view (the others cost the effect nothing).
    pub scattering_lights: usize,
    /// Technique and its settings.
    pub settings: TechniqueSettings,
    /// Host renderer passes (shadow map, surface).
    pub host_passes: Vec<PassTime>,
    /// The technique's own stats (passes, samples, memory).
    pub technique: TechniqueStats,
}

/// Options of one render.
pub struct RenderOptions<'a> {
    /// Technique.
    pub technique: TechniqueSettings,
    /// Progress for long CPU work: (done, total).
    pub progress: &'a (dyn Fn(u64, u64) + Sync),
}

/// The frame description of a scene at its render size ([`Scene::frame_desc`]); its error
/// names the scene.
pub fn frame_desc(scene: &Scene) -> Result<FrameDesc> {
    scene.frame_desc().with_context(|| format!("scene `{}`", scene.name))
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

/// An error where a technique produced NaN or infinity.
fn check_finite(inscatter: &Image, technique: &TechniqueSettings) -> Result<()> {
    if !inscatter.all_finite() {
        bail!("{}: the technique produced non-finite values (NaN/Inf) — a bug, please report it", technique.name());
    }
    Ok(())
}

/// A linear `Rgba32Float` render target the composite writes and a readback reads.
pub fn composite_target(gpu: &GpuContext, width: u32, height: u32) -> wgpu::Texture {
    gpu.device.create_texture(&wgpu::TextureDescriptor {
        label: Some("final radiance"),
        size: wgpu::Extent3d { width, height, depth_or_array_layers: 1 },
        mip_level_count: 1,
        sample_count: 1,
        dimension: wgpu::TextureDimension::D2,
        format: wgpu::TextureFormat::Rgba32Float,
        usage: wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::COPY_SRC,
        view_formats: &[],
    })
}

/// Renders a scene with a technique.
pub fn render(scene: &Scene, gpu: Option<&GpuContext>, opts: &RenderOptions) -> Result<RenderOutput> {
    let desc = frame_desc(scene)?;
    let (inscatter, surface, depth, final_radiance, host_passes, technique, adapter) = match gpu {
        Some(gpu) => {
            let host = GpuHost::for_scene(gpu, &scene)?;
            let tex = host.render(gpu, &desc)?;
            let adapter = adapter_stats(Some(gpu));
            let depth = gpu.read_texture_f32(&tex.depth, 0)?;
            let surface = gpu.read_image(&tex.surface)?;
            let (inscatter, final_radiance, stats) = match scattering(gpu, &opts.technique)? {
                Some(mut runner) => {
                    let out = gpu.create_output_texture(desc.width, desc.height);
                    let out_view = out.create_view(&Default::default());
                    let views = tex.views();
                    let frame = views.frame(&desc);
                    let stats = render_gpu(&mut runner, Some(&host), &frame, &out_view)?;
                    let inscatter = gpu.read_image(&out)?;
                    check_finite(&inscatter, &opts.technique)?;
                    // The library's GPU composite, into a linear Rgba32Float target.
                    let target = composite_target(gpu, desc.width, desc.height);
                    let mut enc = gpu.device.create_command_encoder(&Default::default());
                    let surface_view = tex.surface.create_view(&Default::default());
                    let inputs = CompositeInputs {
                        desc: &desc,
                        depth: frame.depth,
                        inscatter: &out_view,
                        surface: &surface_view,
                    };
                    let target_view = target.create_view(&Default::default());
                    Composite::new(&gpu.device)?.encode(
                        &mut enc,
                        &inputs,
                        CompositeTarget::Into(&target_view),
                        None,
                    )?;
                    gpu.queue.submit([enc.finish()]);
                    (inscatter, gpu.read_image(&target)?, stats)
                }
                None => {
                    // CPU-only techniques (the reference) run over the very shadow map the GPU
                    // drew, and are composited by the CPU mirror of the composite.
                    let shadow_maps = host::read_shadow_maps(gpu, &tex, &desc)?;
                    let frame =
                        CpuFrame { desc: &desc, depth: &depth, shadow_maps: &shadow_maps, surface: Some(&surface) };
                    let (inscatter, stats) = render_cpu(&opts.technique, &frame, Some(&scene.geometry), opts.progress)?;
                    check_finite(&inscatter, &opts.technique)?;
                    let final_radiance = composite(&surface, &inscatter, &surface_transmittance(&desc, &depth));
                    (inscatter, final_radiance, stats)
                }
            };
            (inscatter, surface, depth, final_radiance, tex.passes, stats, adapter)
        }
        None => {
            let h = host_cpu::render(&scene.geometry, &scene.shading(), &desc);
            let frame =
                CpuFrame { desc: &desc, depth: &h.depth, shadow_maps: &h.shadow_maps, surface: Some(&h.surface) };
            let (inscatter, stats) = render_cpu(&opts.technique, &frame, Some(&scene.geometry), opts.progress)?;
            check_finite(&inscatter, &opts.technique)?;
            let final_radiance = composite(&h.surface, &inscatter, &surface_transmittance(&desc, &h.depth));
            (inscatter, h.surface, h.depth, final_radiance, h.passes, stats, adapter_stats(None))
        }
    };
    let stats = RenderStats {
        backend: if gpu.is_some() { "gpu".into() } else { "cpu".into() },
        adapter,
        scene: scene.name.clone(),
        resolution: [desc.width, desc.height],
        shadow_map: {
            let (size, layers) = desc.shadow_array_extent();
            [size, layers]
        },
        lights: desc.lights.len(),
        scattering_lights: desc.scattering_lights().len(),
        settings: opts.technique.clone(),
        host_passes,
        technique,
    };
    Ok(RenderOutput { inscatter, surface, final_radiance, depth, stats })
}

pub use crepuscular::debug::DebugView;

/// Renders `view` for the frame `render` drew (`final_radiance` is that frame's final image,
/// the background of the classification) through the library's debug views
/// ([`crepuscular::Scattering::debug_view`] on the GPU, [`crepuscular::debug::debug_view_cpu`]
/// on the CPU): the frame of the scene's first light that reaches the view is rendered again
/// on the same backend. Returns a linear image (tone-map it like the final image).
pub fn debug_view(
    scene: &Scene,
    gpu: Option<&GpuContext>,
    technique: &TechniqueSettings,
    view: DebugView,
    final_radiance: &Image,
) -> Result<Image> {
    view.check(technique).with_context(|| format!("--debug {}", view.name()))?;
    if let TechniqueSettings::Interleaved(s) = technique {
        return Ok(crepuscular::debug::pattern_view(s, final_radiance));
    }
    // Epipolar lines and rectified maps are one light's.
    let desc = {
        let desc = frame_desc(scene)?;
        let k = desc.scattering_lights().first().copied().unwrap_or(0);
        desc.with_light(k)
    };
    let cpu_host = || host_cpu::render(&scene.geometry, &scene.shading(), &desc);
    match gpu {
        Some(gpu) => {
            let host = GpuHost::for_scene(gpu, scene)?;
            let tex = host.render(gpu, &desc)?;
            let mut runner = Scattering::from_gpu(gpu, technique.clone())?.with_stats(tool_stats_mode(gpu))?;
            let out = gpu.create_output_texture(desc.width, desc.height);
            let views = tex.views();
            render_gpu(&mut runner, Some(&host), &views.frame(&desc), &out.create_view(&Default::default()))?;
            // The depth as the GPU rendered it; the CPU host's shadow maps for minmax only (its
            // walk is counted on the CPU over the GPU's tree), none for the others.
            let depth = gpu.read_texture_f32(&tex.depth, 0)?;
            let shadow_maps = match technique {
                TechniqueSettings::Minmax(_) => cpu_host().shadow_maps,
                _ => Vec::new(),
            };
            let frame = CpuFrame { desc: &desc, depth: &depth, shadow_maps: &shadow_maps, surface: None };
            Ok(runner.debug_view(view, &frame, final_radiance)?)
        }
        None => {
            let h = cpu_host();
            let frame =
                CpuFrame { desc: &desc, depth: &h.depth, shadow_maps: &h.shadow_maps, surface: Some(&h.surface) };
            // The host's rectified raster where the rectification is projective (as render_cpu).
            let raster = technique
                .raster_requests(&desc)
                .into_iter()
                .next()
                .flatten()
                .map(|r| crepuscular_scene::raster::rasterize_rectified(&scene.geometry, &r));
            Ok(crepuscular::debug::debug_view_cpu(technique, view, &frame, raster.as_deref(), final_radiance)?)
        }
    }
}
