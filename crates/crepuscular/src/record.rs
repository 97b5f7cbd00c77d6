//! Recording a technique's passes. A technique's `encode` is a short list of
//! [`Recorder::pass`] / [`Recorder::dispatch`] calls; the recorder decides where they go:
//!
//! - into the **caller's command encoder** ([`crate::StatsMode::Deferred`] and
//!   [`crate::StatsMode::Off`]): nothing is submitted, polled or mapped; with `Deferred`, each
//!   pass writes begin/end timestamps through wgpu-profiler (where the device can time passes)
//!   and the frame's GPU counters are copied into a readback buffer, both read a frame or more
//!   later by [`crate::Scattering::stats`];
//! - into **one encoder per pass, submitted and waited for** ([`crate::StatsMode::WallClock`],
//!   the tools' opt-in mode for software adapters): each pass is timed by synchronised wall
//!   clock and the counters are read at once.

use crate::error::Error;
use crate::gpu::GpuContext;
use crate::stats::PassTime;

/// The timestamp writes of one pass, handed to its pass descriptor.
#[derive(Clone, Copy)]
pub struct TimestampSlot<'a>(&'a wgpu_profiler::GpuProfilerQuery);

impl<'a> TimestampSlot<'a> {
    /// For a compute pass descriptor.
    pub fn compute(self) -> Option<wgpu::ComputePassTimestampWrites<'a>> {
        self.0.compute_pass_timestamp_writes()
    }
    /// For a render pass descriptor.
    pub fn render(self) -> Option<wgpu::RenderPassTimestampWrites<'a>> {
        self.0.render_pass_timestamp_writes()
    }
}

/// Begins a compute pass labelled `label` that writes `ts`'s timestamps, if any.
pub fn compute_pass<'e>(
    enc: &'e mut wgpu::CommandEncoder,
    label: &str,
    ts: Option<TimestampSlot<'_>>,
) -> wgpu::ComputePass<'e> {
    enc.begin_compute_pass(&wgpu::ComputePassDescriptor {
        label: Some(label),
        timestamp_writes: ts.and_then(|t| t.compute()),
    })
}

enum Target<'a> {
    /// The caller's encoder, with the profiler that times its passes (None: untimed) and the
    /// staging belt that uploads uniforms in order inside it.
    Encoder {
        encoder: &'a mut wgpu::CommandEncoder,
        profiler: Option<&'a wgpu_profiler::GpuProfiler>,
        belt: &'a mut wgpu::util::StagingBelt,
    },
    /// One submitted, waited-for encoder per pass, timed by wall clock.
    WallClock,
}

/// Where one frame's passes are recorded (see the module documentation). Made by
/// [`crate::Scattering`]; a technique only calls [`Recorder::pass`], [`Recorder::dispatch`] and
/// [`Recorder::read_counters`].
pub struct Recorder<'a> {
    gpu: &'a GpuContext,
    target: Target<'a>,
    measuring: bool,
    passes: Vec<PassTime>,
    counters: Option<Counters>,
}

/// What a frame's GPU counters complete in its stats, given their bytes.
pub(crate) type ApplyCounters = Box<dyn FnOnce(&[u8], &mut crate::stats::TechniqueStats) + Send>;

/// A buffer of GPU counters to read after the frame, and what they complete.
pub(crate) struct Counters {
    /// The counters (`COPY_SRC`).
    pub buffer: wgpu::Buffer,
    /// Completes the stats from the buffer's bytes.
    pub apply: ApplyCounters,
}

impl<'a> Recorder<'a> {
    /// Records into the caller's `encoder`; `profiler` times the passes (None: untimed);
    /// `measuring` false ([`crate::StatsMode::Off`]) also drops the counter readback.
    pub(crate) fn encoder(
        gpu: &'a GpuContext,
        encoder: &'a mut wgpu::CommandEncoder,
        profiler: Option<&'a wgpu_profiler::GpuProfiler>,
        belt: &'a mut wgpu::util::StagingBelt,
        measuring: bool,
    ) -> Self {
        Self { gpu, target: Target::Encoder { encoder, profiler, belt }, measuring, passes: Vec::new(), counters: None }
    }

    /// Writes `data` to the start of `buffer` (a `COPY_DST` buffer; `data` a multiple of 4
    /// bytes) before the passes recorded after this call: in the caller's encoder, through a
    /// staging belt (so several frames recorded into one encoder each see their own values);
    /// in wall-clock mode through the queue.
    pub fn write_buffer(&mut self, buffer: &wgpu::Buffer, data: &[u8]) {
        let Some(size) = wgpu::BufferSize::new(data.len() as u64) else { return };
        match &mut self.target {
            Target::Encoder { encoder, belt, .. } => belt.write_buffer(encoder, buffer, 0, size).copy_from_slice(data),
            Target::WallClock => self.gpu.queue.write_buffer(buffer, 0, data),
        }
    }

    /// Submits and waits for every pass on its own, timed by wall clock: the tools' mode (a
    /// tool's own host renderer times its passes this way too).
    pub fn wall_clock(gpu: &'a GpuContext) -> Self {
        Self { gpu, target: Target::WallClock, measuring: true, passes: Vec::new(), counters: None }
    }

    /// "timestamp-queries", "wall-clock", "unmeasured" (deferred mode on a device that cannot
    /// time passes: every pass 0 ms) or "off".
    pub fn mode(&self) -> &'static str {
        match (&self.target, self.measuring) {
            (Target::WallClock, _) => "wall-clock",
            (Target::Encoder { .. }, false) => "off",
            (Target::Encoder { profiler: Some(_), .. }, true) if self.gpu.timestamps => "timestamp-queries",
            (Target::Encoder { .. }, true) => "unmeasured",
        }
    }

    /// Records one pass named `name`: `record` gets the encoder (inside a debug group named
    /// `name`) and the timestamp slot to put in its pass descriptor. Validation errors become
    /// [`Error::Gpu`] naming the pass.
    pub fn pass(
        &mut self,
        name: &str,
        record: impl FnOnce(&mut wgpu::CommandEncoder, Option<TimestampSlot<'_>>),
    ) -> Result<(), Error> {
        let gpu = self.gpu;
        match &mut self.target {
            Target::Encoder { encoder, profiler, .. } => {
                gpu.scoped(name, || {
                    encoder.push_debug_group(name);
                    match (*profiler).filter(|_| gpu.timestamps) {
                        Some(p) => {
                            let query = p.begin_pass_query(name, encoder);
                            record(encoder, Some(TimestampSlot(&query)));
                            p.end_query(&mut **encoder, query);
                        }
                        None => record(encoder, None),
                    }
                    encoder.pop_debug_group();
                })?;
                self.passes.push(PassTime { name: name.to_string(), ms: 0.0 });
            }
            Target::WallClock => {
                let start = std::time::Instant::now();
                gpu.scoped(name, || {
                    let mut enc =
                        gpu.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some(name) });
                    enc.push_debug_group(name);
                    record(&mut enc, None);
                    enc.pop_debug_group();
                    gpu.queue.submit([enc.finish()]);
                })?;
                gpu.wait()?;
                self.passes.push(PassTime { name: name.to_string(), ms: start.elapsed().as_secs_f64() * 1e3 });
            }
        }
        Ok(())
    }

    /// Records one pass named `name` that is a single compute dispatch: `pipeline` with
    /// `bind_group` at group 0 and `groups` workgroups, in a compute pass labelled `label`.
    pub fn dispatch(
        &mut self,
        name: &str,
        label: &str,
        pipeline: &wgpu::ComputePipeline,
        bind_group: &wgpu::BindGroup,
        groups: [u32; 3],
    ) -> Result<(), Error> {
        self.pass(name, |enc, ts| {
            let mut pass = compute_pass(enc, label, ts);
            pass.set_pipeline(pipeline);
            pass.set_bind_group(0, bind_group, &[]);
            pass.dispatch_workgroups(groups[0], groups[1], groups[2]);
        })
    }

    /// Asks for `buffer` (a `COPY_SRC` buffer of the frame's GPU counters, written by the passes
    /// recorded so far) to be read once the frame has run; `apply` then completes the frame's
    /// stats from its bytes. Ignored with [`crate::StatsMode::Off`].
    pub fn read_counters(
        &mut self,
        buffer: &wgpu::Buffer,
        apply: impl FnOnce(&[u8], &mut crate::stats::TechniqueStats) + Send + 'static,
    ) {
        if self.measuring {
            self.counters = Some(Counters { buffer: buffer.clone(), apply: Box::new(apply) });
        }
    }

    /// The counters asked for since the last call (one technique run's).
    pub(crate) fn take_counters(&mut self) -> Option<Counters> {
        self.counters.take()
    }

    /// The recorded passes (0 ms except in wall-clock mode).
    pub fn into_passes(self) -> Vec<PassTime> {
        self.passes
    }

    /// The recorded passes (0 ms except in wall-clock mode) and the counters to read.
    pub(crate) fn finish(self) -> (Vec<PassTime>, Option<Counters>) {
        (self.passes, self.counters)
    }
}
