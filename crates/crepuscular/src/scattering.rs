//! The one way in: [`Scattering`], a technique on the caller's device, recorded into the
//! caller's encoder, and [`TechniqueSettings::render_cpu`], the same technique's CPU mirror.
//!
//! An engine's frame:
//!
//! ```no_run
//! # fn frame(device: &wgpu::Device, queue: &wgpu::Queue, frame: &crepuscular::GpuFrame,
//! #          output: &wgpu::TextureView) -> Result<(), crepuscular::Error> {
//! use crepuscular::{Scattering, TechniqueSettings};
//! let mut scattering = Scattering::new(device, queue, TechniqueSettings::named("epipolar")?)?;
//! let mut encoder = device.create_command_encoder(&Default::default());
//! scattering.encode(&mut encoder, frame, output)?; // records; never submits, polls or maps
//! queue.submit([encoder.finish()]);
//! scattering.end_frame(); // starts the non-blocking readback of this frame's timings
//! if let Some(stats) = scattering.stats() { println!("{:.2} ms", stats.total_ms()); }
//! # Ok(()) }
//! ```

use crate::error::Error;
use crate::frame::{CpuFrame, FrameDesc, GpuFrame};
use crate::gpu::{GpuContext, Recorder, StatsMode};
use crate::image::Image;
use crate::record::ApplyCounters;
use crate::stats::{PassTime, TechniqueStats};
use crate::techniques::{AnyGpuTechnique, TechniqueSettings};
use std::collections::VecDeque;
use std::sync::Arc;
use std::sync::atomic::{AtomicUsize, Ordering};

/// A technique's GPU side, kept between frames (what the engine's device and queue, the
/// technique's settings and its pipelines make). Build it once; [`Scattering::update`] changes
/// settings in place, [`Scattering::encode`] records a frame.
///
/// **What it needs from the device.** Every technique uses only WebGPU's core features and
/// default limits (compute shaders, write-only `Rgba32Float` / `Rgba16Float` / `R32Float` /
/// `R32Uint` storage textures, storage buffers, indirect dispatch), checked on creation
/// ([`Scattering::check_device`]). Per pass at most: 2 storage textures (prefiltered's
/// prefilter), 5 storage buffers (epipolar's refine), 5 sampled textures (prefiltered's
/// evaluate), 2 uniform buffers; workgroups of 64 invocations (8 × 8, or 64 × 1). Optional features change the path, never the answer:
/// `TIMESTAMP_QUERY` times the passes ([`StatsMode::Deferred`]); `DEPTH_CLIP_CONTROL` lets a host
/// rasterize prefiltered's rectified map with hardware depth clamping.
pub struct Scattering {
    gpu: GpuContext,
    /// The technique; for one that renders a light per run ([`crate::techniques::TechniqueInfo::per_light`]),
    /// one instance per light that reaches the view (made as lights appear), each with its own
    /// per-light textures and bind groups.
    techniques: Vec<AnyGpuTechnique>,
    /// The sum over lights of a per-light technique (made for the first frame with two lights).
    sum: Option<crate::light_sum::LightSum>,
    /// The in-scattering's format.
    output: wgpu::TextureFormat,
    mode: StatsMode,
    profiler: Option<wgpu_profiler::GpuProfiler>,
    /// Uploads the frame's uniforms inside the caller's encoder.
    belt: wgpu::util::StagingBelt,
    /// Frames encoded since the last [`Scattering::end_frame`].
    recorded: Vec<Pending>,
    /// Frames submitted whose timings and counters have not all arrived, oldest first.
    in_flight: VecDeque<InFlight>,
    /// Readback buffers no frame uses (the ring's free slots).
    free_readbacks: Vec<wgpu::Buffer>,
    latest: Option<TechniqueStats>,
}

/// One encoded frame's stats, waiting for its timings and counters: its passes in recorded
/// order (timestamps arrive in that order) and one part per technique run (per light for a
/// per-light technique), each with its GPU counters.
struct Pending {
    passes: Vec<PassTime>,
    timing: String,
    lights: usize,
    parts: Vec<Part>,
}

struct Part {
    stats: TechniqueStats,
    counters: Option<(wgpu::Buffer, ApplyCounters)>,
}

impl Pending {
    /// The frame's stats once its timings and counters are in: the parts' counters applied,
    /// the parts summed ([`TechniqueStats::sum`]) and the passes of the same name added.
    fn finish(self, mut take: impl FnMut(wgpu::Buffer) -> Vec<u8>) -> TechniqueStats {
        let parts = self
            .parts
            .into_iter()
            .map(|mut p| {
                if let Some((buffer, apply)) = p.counters {
                    let bytes = take(buffer);
                    apply(&bytes, &mut p.stats);
                }
                p.stats
            })
            .collect();
        let mut stats = TechniqueStats::sum(parts);
        stats.passes = PassTime::merge(self.passes);
        stats.timing = self.timing;
        stats.extra.insert("lights".into(), self.lights as f64);
        stats
    }
}

/// The frames of one submission, their readbacks being mapped.
struct InFlight {
    frames: Vec<Pending>,
    mapped: Arc<AtomicUsize>,
    expected: usize,
    timed: bool,
}

/// At most this many measured frames wait for their readbacks ([`StatsMode::Deferred`]): fewer
/// than wgpu-profiler's pending-frame limit (4), so it never drops a frame and every timing stays
/// paired with its frame; a frame encoded while this many wait is recorded unmeasured (it
/// yields no stats), so memory stays bounded in a loop that never asks for stats.
const MAX_MEASURED_IN_FLIGHT: usize = 3;

/// The smallest limits every technique needs (WebGPU's defaults cover them).
fn required_limits() -> wgpu::Limits {
    wgpu::Limits {
        max_bind_groups: 1,
        max_storage_textures_per_shader_stage: 2,
        max_storage_buffers_per_shader_stage: 5,
        max_sampled_textures_per_shader_stage: 5,
        max_uniform_buffers_per_shader_stage: 2,
        max_compute_invocations_per_workgroup: 64,
        max_compute_workgroup_size_x: 64,
        max_compute_workgroup_size_y: 8,
        ..wgpu::Limits::downlevel_webgl2_defaults()
    }
}

impl Scattering {
    /// Builds `settings`' technique on the caller's device and queue (pipelines, uniform
    /// buffers; size-dependent textures follow on the first frame). Statistics are
    /// [`StatsMode::Deferred`]: see [`Scattering::with_stats`]. Errors: settings out of range,
    /// a CPU-only technique (`reference`), a device below [`Scattering::check_device`].
    pub fn new(device: &wgpu::Device, queue: &wgpu::Queue, settings: TechniqueSettings) -> Result<Self, Error> {
        Self::from_gpu(&GpuContext::from_device(device, queue), settings)
    }

    /// [`Scattering::new`] on a [`GpuContext`] (the tools' device, or the caller's wrapped).
    pub fn from_gpu(gpu: &GpuContext, settings: TechniqueSettings) -> Result<Self, Error> {
        Self::check_device(&gpu.device)?;
        settings.validate()?;
        let output = wgpu::TextureFormat::Rgba32Float;
        let technique = AnyGpuTechnique::new(gpu, settings, output)?;
        let mut s = Self {
            gpu: gpu.clone(),
            techniques: vec![technique],
            sum: None,
            output,
            mode: StatsMode::Deferred,
            profiler: None,
            belt: wgpu::util::StagingBelt::new(gpu.device.clone(), 16 * 1024),
            recorded: Vec::new(),
            in_flight: VecDeque::new(),
            free_readbacks: Vec::new(),
            latest: None,
        };
        s.set_stats_mode(StatsMode::Deferred)?;
        Ok(s)
    }

    /// Checks that `device` has the limits every technique needs; the error names the limit.
    pub fn check_device(device: &wgpu::Device) -> Result<(), Error> {
        let have = device.limits();
        let mut missing = None;
        required_limits().check_limits_with_fail_fn(&have, true, |name, have, want| {
            missing.get_or_insert_with(|| Error::Invalid {
                key: format!("device limit {name}"),
                value: have.to_string(),
                reason: format!("the techniques need at least {want}"),
            });
        });
        missing.map_or(Ok(()), Err)
    }

    /// The same, with statistics in `mode` (builder style).
    pub fn with_stats(mut self, mode: StatsMode) -> Result<Self, Error> {
        self.set_stats_mode(mode)?;
        Ok(self)
    }

    /// The same, writing its in-scattering as `format` (builder style): `Rgba32Float` (the
    /// default) or `Rgba16Float` — half the memory and bandwidth of the output texture, at
    /// half-float precision (within one half-float ulp, 2⁻¹⁰ relative, per channel; the README
    /// has the measured PSNR cost). The technique's radiance intermediates follow it
    /// ([`crate::techniques::pass::intermediate_format`]); positions and depths stay 32-bit.
    /// Rebuilds the technique's pipelines; an error for another format.
    pub fn with_output_format(mut self, format: wgpu::TextureFormat) -> Result<Self, Error> {
        if !crate::techniques::pass::OUTPUT_FORMATS.contains(&format) {
            return Err(Error::invalid("output format", format!("{format:?}"), "must be Rgba32Float or Rgba16Float"));
        }
        if format != self.output {
            self.techniques = vec![AnyGpuTechnique::new(&self.gpu, self.settings(), format)?];
            self.sum = None;
            self.output = format;
        }
        Ok(self)
    }

    /// The in-scattering's format (see [`Scattering::with_output_format`]).
    pub fn output_format(&self) -> wgpu::TextureFormat {
        self.output
    }

    /// Changes how frames are measured from the next frame on (frames in flight still report).
    pub fn set_stats_mode(&mut self, mode: StatsMode) -> Result<(), Error> {
        self.mode = mode;
        if mode == StatsMode::Deferred && self.gpu.timestamps && self.profiler.is_none() {
            let settings = wgpu_profiler::GpuProfilerSettings {
                enable_timer_queries: true,
                enable_debug_groups: false,
                max_num_pending_frames: 4,
            };
            self.profiler = Some(
                wgpu_profiler::GpuProfiler::new(&self.gpu.device, settings)
                    .map_err(|e| Error::Gpu { context: "creating the pass timer".into(), message: e.to_string() })?,
            );
        }
        Ok(())
    }

    /// How frames are measured.
    pub fn stats_mode(&self) -> StatsMode {
        self.mode
    }

    /// The technique's name.
    pub fn name(&self) -> &'static str {
        self.techniques[0].name()
    }

    /// The technique's current settings.
    pub fn settings(&self) -> TechniqueSettings {
        self.techniques[0].settings()
    }

    /// The technique itself, for its debug views and intermediate textures (of the first light
    /// that reached the view, for a per-light technique).
    pub fn technique(&self) -> &AnyGpuTechnique {
        &self.techniques[0]
    }

    /// The device and queue this runs on.
    pub fn gpu(&self) -> &GpuContext {
        &self.gpu
    }

    /// Applies `settings` in place when they are of the same technique (pipelines kept; each
    /// technique rebuilds on its next frame only what the changed settings size or build) and
    /// returns true; returns false, changing nothing, for another technique (build a new
    /// [`Scattering`]). Settings out of range are an error and change nothing.
    pub fn update(&mut self, settings: &TechniqueSettings) -> Result<bool, Error> {
        settings.validate()?;
        let mut same = true;
        for t in &mut self.techniques {
            same &= t.update(settings);
        }
        Ok(same)
    }

    /// Bytes of GPU memory the technique holds (not counting the caller's textures).
    pub fn gpu_memory_bytes(&self) -> u64 {
        self.techniques.iter().map(|t| t.gpu_memory_bytes()).sum::<u64>()
            + self.sum.as_ref().map_or(0, |s| s.gpu_memory_bytes())
    }

    /// How many times the technique's bind groups were built, over its per-light instances.
    pub fn bind_group_builds(&self) -> u64 {
        self.techniques.iter().map(|t| t.bind_group_builds()).sum()
    }

    /// The host rasters this frame would use, one per light of `desc.lights` (None for most):
    /// `prefiltered`'s projective rectified shadow maps (Klehm et al. 2014, §4.2). A host that
    /// can rasterize its scene from these matrices passes the results as
    /// [`GpuFrame::rectified_shadow_maps`].
    pub fn raster_requests(&self, desc: &FrameDesc) -> Vec<Option<crate::techniques::prefiltered::RectifiedRaster>> {
        self.settings().raster_requests(desc)
    }

    /// Records the in-scattering of `frame` into `output` (a `STORAGE_BINDING` view of a
    /// texture of the frame's size in [`Scattering::output_format`], `Rgba32Float` by default) into the caller's `encoder`: no submit, no
    /// poll, no map (except in the tools' [`StatsMode::WallClock`], which submits and waits per
    /// pass and leaves `encoder` empty). Submit the encoder, then call
    /// [`Scattering::end_frame`]. Inputs that do not match the frame (sizes, formats, layer
    /// counts) are an [`Error::Invalid`] naming them; validation errors an [`Error::Gpu`].
    /// The in-scattering is in rgb; alpha is 1, except for `brute-force`, which writes minus each
    /// pixel's scattering distance there (0 where it has none) for the temporal stage
    /// ([`crate::TemporalSettings::scattering_distance`]): composite from rgb.
    pub fn encode(
        &mut self,
        encoder: &mut wgpu::CommandEncoder,
        frame: &GpuFrame,
        output: &wgpu::TextureView,
    ) -> Result<(), Error> {
        check_frame(&self.gpu, frame, output, self.output)?;
        // Readbacks the caller's own polls and submits delivered (this does not poll).
        self.collect();
        let measured = self.mode != StatsMode::Deferred || self.frames_in_flight() < MAX_MEASURED_IN_FLIGHT;
        let profiler = match self.mode {
            StatsMode::Deferred if measured => self.profiler.as_ref(),
            _ => None,
        };
        let mut rec = match self.mode {
            StatsMode::WallClock => Recorder::wall_clock(&self.gpu),
            StatsMode::Deferred => Recorder::encoder(&self.gpu, encoder, profiler, &mut self.belt, measured),
            StatsMode::Off => Recorder::encoder(&self.gpu, encoder, None, &mut self.belt, false),
        };
        let lights = frame.desc.scattering_lights().len();
        let result =
            Self::encode_lights(&self.gpu, &mut self.techniques, &mut self.sum, self.output, &mut rec, frame, output);
        let timing = rec.mode();
        let (passes, _) = rec.finish();
        // The uniform uploads recorded into the encoder are complete: the caller may submit.
        self.belt.finish();
        let parts = result?;
        let pending = Pending { passes, timing: timing.into(), lights, parts };
        match self.mode {
            StatsMode::WallClock => {
                let gpu = &self.gpu;
                let mut failed = None;
                let stats = pending.finish(|b| {
                    read_buffer(gpu, &b).unwrap_or_else(|e| {
                        failed = Some(e);
                        Vec::new()
                    })
                });
                if let Some(e) = failed {
                    return Err(e);
                }
                self.latest = Some(stats);
            }
            StatsMode::Off => self.latest = Some(pending.finish(|_| Vec::new())),
            // Too many frames wait for their readbacks: this one is not measured.
            StatsMode::Deferred if !measured => {}
            StatsMode::Deferred => {
                let mut pending = pending;
                for part in &mut pending.parts {
                    if let Some((buffer, apply)) = part.counters.take() {
                        let size = buffer.size();
                        let slot = self.take_readback(size);
                        encoder.copy_buffer_to_buffer(&buffer, 0, &slot, 0, size);
                        part.counters = Some((slot, apply));
                    }
                }
                if let Some(p) = self.profiler.as_mut().filter(|_| self.gpu.timestamps) {
                    p.resolve_queries(encoder);
                }
                self.recorded.push(pending);
            }
        }
        Ok(())
    }

    /// Records the technique for the frame's lights: once for a technique that marches every
    /// light at each sample; once per light that reaches the view, summed, for a per-light one.
    #[allow(clippy::too_many_arguments)]
    fn encode_lights(
        gpu: &GpuContext,
        techniques: &mut Vec<AnyGpuTechnique>,
        light_sum: &mut Option<crate::light_sum::LightSum>,
        format: wgpu::TextureFormat,
        rec: &mut Recorder,
        frame: &GpuFrame,
        output: &wgpu::TextureView,
    ) -> Result<Vec<Part>, Error> {
        let desc = frame.desc;
        let run = |t: &mut AnyGpuTechnique, rec: &mut Recorder, f: &GpuFrame, out: &wgpu::TextureView| {
            let stats = t.encode(gpu, rec, f, out)?;
            let counters = rec.take_counters().map(|c| (c.buffer, c.apply));
            Ok::<Part, Error>(Part { stats, counters })
        };
        if !techniques[0].info().per_light {
            return Ok(vec![run(&mut techniques[0], rec, frame, output)?]);
        }
        let lights = desc.scattering_lights();
        let settings = techniques[0].settings();
        while techniques.len() < lights.len() {
            techniques.push(AnyGpuTechnique::new(gpu, settings.clone(), format)?);
        }
        let descs: Vec<FrameDesc> = lights.iter().map(|&k| desc.with_light(k)).collect();
        let frames: Vec<GpuFrame> = lights.iter().zip(&descs).map(|(&k, d)| frame.with_light(d, k)).collect();
        match frames.as_slice() {
            [] => {
                let sum = match light_sum {
                    Some(s) => s,
                    None => light_sum.insert(crate::light_sum::LightSum::new(gpu, format)?),
                };
                sum.clear(gpu, rec, output)?;
                Ok(vec![Part { stats: TechniqueStats::empty(techniques[0].name(), "gpu"), counters: None }])
            }
            [one] => Ok(vec![run(&mut techniques[0], rec, one, output)?]),
            many => {
                let sum = match light_sum {
                    Some(s) => s,
                    None => light_sum.insert(crate::light_sum::LightSum::new(gpu, format)?),
                };
                let [light, a, b] = sum.views(gpu, desc.width, desc.height)?;
                let acc = [a, b];
                let mut parts = Vec::with_capacity(many.len());
                for (i, (f, t)) in many.iter().zip(techniques.iter_mut()).enumerate() {
                    if i == 0 {
                        parts.push(run(t, rec, f, &acc[0])?);
                        continue;
                    }
                    parts.push(run(t, rec, f, &light)?);
                    let out = if i == many.len() - 1 { output } else { &acc[i % 2] };
                    sum.add(gpu, rec, &acc[(i - 1) % 2], &light, out)?;
                }
                Ok(parts)
            }
        }
    }

    /// Marks the end of a frame: call it once after submitting the encoder(s) that hold the
    /// frames encoded since the last call. It starts the non-blocking readback of their
    /// timestamps and counters ([`StatsMode::Deferred`]); their stats arrive in
    /// [`Scattering::stats`] once the GPU has run them (one or more frames later).
    pub fn end_frame(&mut self) {
        self.belt.recall();
        if self.recorded.is_empty() {
            return;
        }
        let frames = std::mem::take(&mut self.recorded);
        let timed = match self.profiler.as_mut().filter(|_| self.gpu.timestamps) {
            Some(p) => p.end_frame().is_ok(),
            None => false,
        };
        let mapped = Arc::new(AtomicUsize::new(0));
        let mut expected = 0;
        for (buffer, _) in frames.iter().flat_map(|f| &f.parts).filter_map(|p| p.counters.as_ref()) {
            expected += 1;
            let mapped = mapped.clone();
            buffer.slice(..).map_async(wgpu::MapMode::Read, move |r| {
                if r.is_ok() {
                    mapped.fetch_add(1, Ordering::AcqRel);
                }
            });
        }
        self.in_flight.push_back(InFlight { frames, mapped, expected, timed });
    }

    /// How many measured frames wait for their timings and counters (at most 3; see
    /// [`StatsMode::Deferred`]).
    pub fn frames_in_flight(&self) -> usize {
        self.in_flight.iter().map(|f| f.frames.len()).sum::<usize>() + self.recorded.len()
    }

    /// The stats of the newest frame whose timings and counters have arrived (never waits;
    /// polls the device without blocking so that finished readbacks are delivered). With
    /// [`StatsMode::WallClock`] and [`StatsMode::Off`] they are the last encoded frame's.
    pub fn stats(&mut self) -> Option<&TechniqueStats> {
        if !self.in_flight.is_empty() {
            let _ = self.gpu.device.poll(wgpu::PollType::Poll);
        }
        self.collect();
        self.latest.as_ref()
    }

    /// Moves the frames whose timings and counters have arrived out of flight, oldest first,
    /// into `latest` (never polls or waits).
    fn collect(&mut self) {
        let period = self.gpu.queue.get_timestamp_period();
        while let Some(front) = self.in_flight.front() {
            if front.mapped.load(Ordering::Acquire) < front.expected {
                break;
            }
            let times = match (front.timed, self.profiler.as_mut()) {
                (true, Some(p)) => match p.process_finished_frame(period) {
                    Some(results) => Some(results),
                    None => break,
                },
                _ => None,
            };
            let done = self.in_flight.pop_front().expect("front exists");
            let mut times = times.into_iter().flatten();
            for mut f in done.frames {
                for pass in &mut f.passes {
                    if let Some(r) = times.next() {
                        pass.ms = r.time.map_or(0.0, |t| (t.end - t.start) * 1e3);
                    }
                }
                let free = &mut self.free_readbacks;
                self.latest = Some(f.finish(|buffer| {
                    let bytes = buffer.slice(..).get_mapped_range().to_vec();
                    buffer.unmap();
                    free.push(buffer);
                    bytes
                }));
            }
        }
    }

    /// A tool's whole frame: records `frame` into an encoder of its own, submits it, waits for
    /// the GPU and returns the frame's stats. Never use it in an engine's frame loop (it
    /// waits); use [`Scattering::encode`].
    pub fn render(&mut self, frame: &GpuFrame, output: &wgpu::TextureView) -> Result<TechniqueStats, Error> {
        // Frames the caller encoded before still in flight: let them land first, so that this
        // frame is measured and its own stats are returned.
        if self.frames_in_flight() > 0 {
            self.end_frame();
            self.gpu.wait()?;
            self.stats();
        }
        let mut encoder =
            self.gpu.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some(self.name()) });
        self.encode(&mut encoder, frame, output)?;
        self.gpu.scoped("submitting the frame", || self.gpu.queue.submit([encoder.finish()]))?;
        self.end_frame();
        self.gpu.wait()?;
        self.stats().cloned().ok_or_else(|| Error::Gpu {
            context: "reading the frame's stats".into(),
            message: "the frame's timings or counters did not arrive".into(),
        })
    }

    /// A readback buffer of `size` bytes from the ring (a new one when none is free).
    fn take_readback(&mut self, size: u64) -> wgpu::Buffer {
        match self.free_readbacks.iter().position(|b| b.size() == size) {
            Some(i) => self.free_readbacks.swap_remove(i),
            None => self.gpu.device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("counters readback"),
                size,
                usage: wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::MAP_READ,
                mapped_at_creation: false,
            }),
        }
    }
}

/// Copies a buffer into a new readback buffer, submits, waits and returns its bytes (tools and
/// [`StatsMode::WallClock`] only).
pub(crate) fn read_buffer(gpu: &GpuContext, buffer: &wgpu::Buffer) -> Result<Vec<u8>, Error> {
    let read = gpu.device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("readback"),
        size: buffer.size(),
        usage: wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::MAP_READ,
        mapped_at_creation: false,
    });
    let mut enc = gpu.device.create_command_encoder(&Default::default());
    enc.copy_buffer_to_buffer(buffer, 0, &read, 0, buffer.size());
    gpu.queue.submit([enc.finish()]);
    gpu.read_mapped(&read, "reading back a buffer", |d| d.to_vec())
}

/// The frame's textures against its description: sizes, formats, layer counts.
fn check_frame(
    gpu: &GpuContext,
    frame: &GpuFrame,
    output: &wgpu::TextureView,
    format: wgpu::TextureFormat,
) -> Result<(), Error> {
    let d = frame.desc;
    gpu.check_texture_size("image size", d.width, d.height)?;
    let size = |t: &wgpu::Texture| format!("{}×{}×{}", t.width(), t.height(), t.depth_or_array_layers());
    let (w, h) = (d.width, d.height);
    let out = output.texture();
    if out.format() != format {
        return Err(Error::invalid(
            "output",
            format!("{:?}", out.format()),
            format!("must be a {format:?} texture (Scattering::with_output_format)"),
        ));
    }
    if !out.usage().contains(wgpu::TextureUsages::STORAGE_BINDING) {
        return Err(Error::invalid("output", format!("{:?}", out.usage()), "needs STORAGE_BINDING usage"));
    }
    if (out.width(), out.height()) != (w, h) {
        return Err(Error::invalid("output", size(out), format!("must be the frame's size {w}×{h}")));
    }
    let depth = frame.depth.texture();
    let depth_ok = matches!(depth.format(), wgpu::TextureFormat::Depth32Float | wgpu::TextureFormat::R32Float);
    if !depth_ok {
        return Err(Error::invalid("depth", format!("{:?}", depth.format()), "must be Depth32Float or R32Float"));
    }
    if (depth.width(), depth.height()) != (w, h) {
        return Err(Error::invalid("depth", size(depth), format!("must be the frame's size {w}×{h}")));
    }
    d.validate_lights()?;
    let sm = frame.shadow_maps.texture();
    if !matches!(sm.format(), wgpu::TextureFormat::Depth32Float | wgpu::TextureFormat::R32Float) {
        return Err(Error::invalid("shadow_maps", format!("{:?}", sm.format()), "must be Depth32Float or R32Float"));
    }
    for (k, fl) in d.lights.iter().enumerate() {
        let sp = &fl.shadow;
        if fl.shadow_layer + sp.layers > sm.depth_or_array_layers() {
            return Err(Error::invalid(
                "shadow_maps",
                size(sm),
                format!(
                    "lights[{k}] ({}) needs layers {}..{} (shadow_layer {} + {} layer(s))",
                    fl.light.kind_name(),
                    fl.shadow_layer,
                    fl.shadow_layer + sp.layers,
                    fl.shadow_layer,
                    sp.layers
                ),
            ));
        }
        if sp.size > sm.width() || sp.size > sm.height() {
            return Err(Error::invalid(
                "shadow_maps",
                size(sm),
                format!("lights[{k}]'s shadow map is {0}×{0} (shadow.size), larger than the texture", sp.size),
            ));
        }
        if let Some(t) = fl.spot_texture() {
            let Some(view) = frame.spot_textures else {
                return Err(Error::invalid(
                    "spot_textures",
                    "None",
                    format!("lights[{k}] has a projected texture: pass the spot-texture array"),
                ));
            };
            let tex = view.texture();
            if fl.texture_layer >= tex.depth_or_array_layers() || t.width > tex.width() || t.height > tex.height() {
                return Err(Error::invalid(
                    "spot_textures",
                    size(tex),
                    format!(
                        "lights[{k}]'s {}×{} texture in layer {} does not fit",
                        t.width, t.height, fl.texture_layer
                    ),
                ));
            }
        }
    }
    if !frame.rectified_shadow_maps.is_empty() && frame.rectified_shadow_maps.len() != d.lights.len() {
        return Err(Error::invalid(
            "rectified_shadow_maps",
            frame.rectified_shadow_maps.len(),
            format!("one entry (or None) per light: the frame has {}", d.lights.len()),
        ));
    }
    Ok(())
}

impl TechniqueSettings {
    /// Runs the technique's CPU implementation on `frame`. `rectified` is the host's raster of
    /// [`TechniqueSettings::raster_request`] (`prefiltered` only; None: resampled from the
    /// shadow map). `progress(done, total)` is called as long work (the reference) advances.
    /// `rectified` holds one entry per light of the frame (or none at all). A technique that
    /// renders one light per run ([`crate::techniques::TechniqueInfo::per_light`]) runs once per light
    /// that reaches the view and the images are added, as on the GPU.
    pub fn render_cpu(
        &self,
        frame: &CpuFrame,
        rectified: &[Option<&[f32]>],
        progress: &(dyn Fn(u64, u64) + Sync),
    ) -> Result<(Image, TechniqueStats), Error> {
        self.validate()?;
        frame.validate()?;
        let desc = frame.desc;
        let lights = desc.scattering_lights();
        let (image, mut stats) = if !self.info().per_light {
            self.render_cpu_unchecked(frame, None, progress)?
        } else {
            let mut sum = Image::new(desc.width, desc.height);
            for p in &mut sum.pixels {
                *p = [0.0, 0.0, 0.0, 1.0];
            }
            let mut parts = Vec::new();
            for (i, &k) in lights.iter().enumerate() {
                let sub = desc.with_light(k);
                let part = frame.with_light(&sub, k);
                let (img, st) = self.render_cpu_unchecked(&part, rectified.get(k).copied().flatten(), progress)?;
                if i == 0 {
                    sum = img;
                } else {
                    // The GPU's light sum (light_sum.wgsl): rgb added, alpha of the first.
                    for (s, p) in sum.pixels.iter_mut().zip(&img.pixels) {
                        for c in 0..3 {
                            s[c] += p[c];
                        }
                    }
                }
                parts.push(st);
            }
            let stats =
                if parts.is_empty() { TechniqueStats::empty(self.name(), "cpu") } else { TechniqueStats::sum(parts) };
            (sum, stats)
        };
        stats.extra.insert("lights".into(), lights.len() as f64);
        if !image.all_finite() {
            return Err(Error::invalid(
                self.name(),
                "NaN/Inf",
                "the technique produced non-finite values — a bug, please report it",
            ));
        }
        Ok((image, stats))
    }

    /// The host rasters a frame would use, one per light of `desc.lights` (see
    /// [`crate::Scattering::raster_requests`]): a per-light technique's request for each light
    /// that reaches the view, None for the others.
    pub fn raster_requests(&self, desc: &FrameDesc) -> Vec<Option<crate::techniques::prefiltered::RectifiedRaster>> {
        let mut out = vec![None; desc.lights.len()];
        if self.info().per_light {
            for k in desc.scattering_lights() {
                out[k] = self.raster_request(&desc.with_light(k));
            }
        }
        out
    }

    /// The times of a host raster as the first pass of `stats` (what a tool that rasterized
    /// the rectified map adds).
    pub fn with_host_raster(stats: &mut TechniqueStats, ms: f64) {
        stats.passes.insert(0, PassTime { name: "rasterize (host)".into(), ms });
    }
}
