//! The GPU context, readbacks, and per-pass timing.

use crate::error::Error;
use crate::stats::PassTime;
use std::time::Instant;

/// Whether a technique's `render` waits for the GPU to report the frame's statistics.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum StatsMode {
    /// Time every pass and read the GPU's counters (epipolar's sample classification,
    /// subsampled's re-marched pixels): complete [`crate::stats::TechniqueStats`], at the price of
    /// waiting for the GPU at the end of each frame — and after each pass on software
    /// adapters, which are timed by synchronised wall clock. The default; what the command
    /// line's `render`, `bench` and the viewer use.
    #[default]
    Measured,
    /// Record and submit only: `render` returns once its passes are submitted, so the CPU
    /// prepares the next frame while the GPU works (no CPU–GPU synchronisation per frame: what
    /// an engine wants, and the only way a browser allows). The stats then list the passes
    /// with `ms` = 0 and `timing` = `"off"`; counts that need a readback (epipolar's and
    /// subsampled's GPU-classified pixels) are left out of `raymarched_samples` and `extra`.
    Off,
}

/// An adapter, device and queue, and what they can do.
pub struct GpuContext {
    /// The adapter.
    pub adapter: wgpu::Adapter,
    /// The device.
    pub device: wgpu::Device,
    /// The queue.
    pub queue: wgpu::Queue,
    /// Adapter information (name, backend, driver).
    pub info: wgpu::AdapterInfo,
    /// True for a software rasterizer (lavapipe, WARP, SwiftShader): its timestamp queries are
    /// not meaningful, so passes are timed by synchronised wall clock.
    pub software: bool,
    /// True when passes are timed with timestamp queries.
    pub timestamps: bool,
    /// Whether techniques wait for the GPU to report statistics; default
    /// [`StatsMode::Measured`]. Set [`StatsMode::Off`] to render without synchronising.
    pub stats: StatsMode,
    /// The first error wgpu reported outside any error scope, or the device-lost reason: set
    /// by the handlers [`GpuContext::from_adapter`] installs (wgpu's default handler panics),
    /// turned into an [`Error::Gpu`] by [`GpuContext::wait`].
    fault: std::sync::Arc<std::sync::Mutex<Option<String>>>,
}

impl std::fmt::Debug for GpuContext {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("GpuContext").field("info", &self.info).finish()
    }
}

/// How long [`wait_idle`] waits for the GPU before it reports an error instead of hanging:
/// `CREPUSCULAR_GPU_TIMEOUT_S` seconds if set, else 600 s (a 1080p brute-force frame at 256
/// steps takes ~30 s on llvmpipe with 2 cores).
pub fn gpu_timeout() -> std::time::Duration {
    let secs = std::env::var("CREPUSCULAR_GPU_TIMEOUT_S").ok().and_then(|v| v.parse::<f64>().ok());
    std::time::Duration::from_secs_f64(secs.filter(|s| s.is_finite() && *s > 0.0).unwrap_or(600.0))
}

/// Blocks until the queue is idle; an error (not a hang) after [`gpu_timeout`] or when wgpu
/// detects a lost device.
pub fn wait_idle(device: &wgpu::Device) -> Result<(), Error> {
    let timeout = gpu_timeout();
    device.poll(wgpu::PollType::Wait { submission_index: None, timeout: Some(timeout) }).map(|_| ()).map_err(|e| {
        let message = match e {
            wgpu::PollError::Timeout => format!("the GPU did not finish within {:.0} s", timeout.as_secs_f64()),
            e => e.to_string(),
        };
        Error::Gpu { context: "waiting for the GPU".into(), message }
    })
}

impl GpuContext {
    /// Finds an adapter (any backend wgpu was built with; software adapters included) and
    /// creates a device with the adapter's own limits and only the optional features it has.
    /// Blocks on [`GpuContext::new_async`]; in a browser, await that instead.
    pub fn new() -> Result<Self, Error> {
        pollster::block_on(Self::new_async())
    }

    /// [`GpuContext::new`] as a future, for executors and the browser (wasm32, where blocking
    /// the main thread is not allowed).
    pub async fn new_async() -> Result<Self, Error> {
        // Vulkan / Metal / DX12 first; the GL backend only when none of those has an adapter
        // (or when WGPU_BACKEND asks for it), since probing EGL is noisy on headless machines.
        let tries = match wgpu::Backends::from_env() {
            Some(b) => vec![b],
            None => vec![wgpu::Backends::PRIMARY, wgpu::Backends::GL],
        };
        let mut last = String::from("no backend tried");
        for backends in tries {
            let mut desc = wgpu::InstanceDescriptor::new_without_display_handle();
            desc.backends = backends;
            let instance = wgpu::Instance::new(desc);
            match instance
                .request_adapter(&wgpu::RequestAdapterOptions {
                    power_preference: wgpu::PowerPreference::HighPerformance,
                    force_fallback_adapter: false,
                    compatible_surface: None,
                    apply_limit_buckets: false,
                })
                .await
            {
                Ok(adapter) => return Self::from_adapter_async(adapter).await,
                Err(e) => last = e.to_string(),
            }
        }
        Err(Error::NoAdapter(last))
    }

    /// Creates the device on a given adapter (yours: the one your renderer presents with).
    /// Blocks on [`GpuContext::from_adapter_async`].
    pub fn from_adapter(adapter: wgpu::Adapter) -> Result<Self, Error> {
        pollster::block_on(Self::from_adapter_async(adapter))
    }

    /// [`GpuContext::from_adapter`] as a future.
    pub async fn from_adapter_async(adapter: wgpu::Adapter) -> Result<Self, Error> {
        let info = adapter.get_info();
        let software = info.device_type == wgpu::DeviceType::Cpu
            || info.name.to_lowercase().contains("llvmpipe")
            || info.name.to_lowercase().contains("swiftshader");
        let wanted = wgpu::Features::TIMESTAMP_QUERY | wgpu::Features::DEPTH_CLIP_CONTROL;
        let features = adapter.features() & wanted;
        let (device, queue) = adapter
            .request_device(&wgpu::DeviceDescriptor {
                label: Some("crepuscular"),
                required_features: features,
                required_limits: adapter.limits(),
                ..Default::default()
            })
            .await
            .map_err(|e| Error::Device(e.to_string()))?;
        let timestamps = !software && features.contains(wgpu::Features::TIMESTAMP_QUERY);
        let fault = std::sync::Arc::new(std::sync::Mutex::new(None::<String>));
        let record = |slot: &std::sync::Arc<std::sync::Mutex<Option<String>>>, message: String| {
            if let Ok(mut f) = slot.lock()
                && f.is_none()
            {
                *f = Some(message);
            }
        };
        let (on_error, on_lost) = (fault.clone(), fault.clone());
        device.on_uncaptured_error(std::sync::Arc::new(move |e: wgpu::Error| record(&on_error, e.to_string())));
        device.set_device_lost_callback(move |reason, message| {
            record(&on_lost, format!("device lost ({reason:?}): {message}"))
        });
        Ok(Self { adapter, device, queue, info, software, timestamps, stats: StatsMode::Measured, fault })
    }

    /// Waits for the GPU ([`wait_idle`]), then reports a lost device or an error wgpu raised
    /// outside an error scope since the last call, as [`Error::Gpu`].
    pub fn wait(&self) -> Result<(), Error> {
        let waited = wait_idle(&self.device);
        let fault = self.fault.lock().ok().and_then(|mut f| f.take());
        match fault {
            Some(message) => Err(Error::Gpu { context: "the last GPU work".into(), message }),
            None => waited,
        }
    }

    /// One line naming the adapter, backend and driver.
    pub fn describe(&self) -> String {
        format!(
            "{} ({:?}, {:?}{}, driver {} {})",
            self.info.name,
            self.info.backend,
            self.info.device_type,
            if self.software { ", software" } else { "" },
            self.info.driver,
            self.info.driver_info
        )
    }

    /// Checks a 2D texture size against the device limits (largest dimension; bytes of one
    /// Rgba32Float texture of that size against the largest buffer), before any allocation.
    pub fn check_texture_size(&self, what: &str, width: u32, height: u32) -> Result<(), Error> {
        let limit = self.device.limits().max_texture_dimension_2d;
        let big = width.max(height);
        if big > limit || width == 0 || height == 0 {
            return Err(Error::Limit { what: what.into(), value: big as u64, limit: limit as u64 });
        }
        // Every full-size texture here may be an Rgba32Float read back through one buffer
        // (rows padded to 256 bytes): refuse what no buffer of this device can hold.
        let bytes = (width as u64 * 16).next_multiple_of(256) * height as u64;
        let max_buffer = self.device.limits().max_buffer_size;
        if bytes > max_buffer {
            return Err(Error::Limit {
                what: format!("{what} {width}×{height}: bytes of one Rgba32Float texture"),
                value: bytes,
                limit: max_buffer,
            });
        }
        Ok(())
    }

    /// Runs `f` inside validation and out-of-memory error scopes and turns a captured error into
    /// [`Error::Gpu`] instead of wgpu's default panic. On wasm32 (WebGPU reports errors
    /// asynchronously and the browser forbids blocking on them) `f` runs without scopes; its
    /// errors reach the handler [`GpuContext::from_adapter`] installs and the next
    /// [`GpuContext::wait`].
    #[cfg(target_arch = "wasm32")]
    pub fn scoped<T>(&self, _context: &str, f: impl FnOnce() -> T) -> Result<T, Error> {
        Ok(f())
    }

    /// Runs `f` inside validation and out-of-memory error scopes and turns a captured error into
    /// [`Error::Gpu`] instead of wgpu's default panic. On wasm32 `f` runs without scopes (the
    /// browser forbids blocking on their result); its errors reach [`GpuContext::wait`].
    #[cfg(not(target_arch = "wasm32"))]
    pub fn scoped<T>(&self, context: &str, f: impl FnOnce() -> T) -> Result<T, Error> {
        let oom = self.device.push_error_scope(wgpu::ErrorFilter::OutOfMemory);
        let val = self.device.push_error_scope(wgpu::ErrorFilter::Validation);
        let out = f();
        let e1 = pollster::block_on(val.pop());
        let e2 = pollster::block_on(oom.pop());
        match e1.or(e2) {
            Some(e) => Err(Error::Gpu { context: context.into(), message: e.to_string() }),
            None => Ok(out),
        }
    }

    /// Reads back a whole single-layer 2D texture of a 4-byte-per-texel (`R32Float`,
    /// `Depth32Float`) or 16-byte-per-texel (`Rgba32Float`) format as f32s.
    pub fn read_texture_f32(&self, texture: &wgpu::Texture, layer: u32) -> Result<Vec<f32>, Error> {
        let bytes = self.read_texture_bytes(texture, layer)?;
        Ok(bytes.chunks_exact(4).map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]])).collect())
    }

    /// Reads back layer `layer` of a 2D (array) texture as its raw texels, rows tightly packed
    /// (the copy's row padding removed).
    pub fn read_texture_bytes(&self, texture: &wgpu::Texture, layer: u32) -> Result<Vec<u8>, Error> {
        let (w, h) = (texture.width(), texture.height());
        let bpp = texture.format().block_copy_size(Some(wgpu::TextureAspect::All)).unwrap_or(4);
        let aspect = if texture.format().is_depth_stencil_format() {
            wgpu::TextureAspect::DepthOnly
        } else {
            wgpu::TextureAspect::All
        };
        let row = w * bpp;
        let padded = row.div_ceil(wgpu::COPY_BYTES_PER_ROW_ALIGNMENT) * wgpu::COPY_BYTES_PER_ROW_ALIGNMENT;
        let buffer = self.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("readback"),
            size: (padded * h) as u64,
            usage: wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::MAP_READ,
            mapped_at_creation: false,
        });
        let mut enc = self.device.create_command_encoder(&Default::default());
        enc.copy_texture_to_buffer(
            wgpu::TexelCopyTextureInfo {
                texture,
                mip_level: 0,
                origin: wgpu::Origin3d { x: 0, y: 0, z: layer },
                aspect,
            },
            wgpu::TexelCopyBufferInfo {
                buffer: &buffer,
                layout: wgpu::TexelCopyBufferLayout { offset: 0, bytes_per_row: Some(padded), rows_per_image: Some(h) },
            },
            wgpu::Extent3d { width: w, height: h, depth_or_array_layers: 1 },
        );
        self.queue.submit([enc.finish()]);
        self.read_mapped(&buffer, "reading back a texture", |data| {
            let mut out = Vec::with_capacity((w * h * bpp) as usize);
            for y in 0..h {
                let start = (y * padded) as usize;
                out.extend_from_slice(&data[start..start + row as usize]);
            }
            out
        })
    }

    /// Maps a whole `MAP_READ` buffer once the GPU work before it has finished, hands its
    /// bytes to `f`, and unmaps it: the one readback path of the library (textures, counters,
    /// timestamps). A failed map or a GPU fault is an [`Error::Gpu`] naming `context`.
    pub fn read_mapped<T>(&self, buffer: &wgpu::Buffer, context: &str, f: impl FnOnce(&[u8]) -> T) -> Result<T, Error> {
        let err = |message: String| Error::Gpu { context: context.into(), message };
        let slice = buffer.slice(..);
        let (tx, rx) = std::sync::mpsc::channel();
        slice.map_async(wgpu::MapMode::Read, move |r| {
            let _ = tx.send(r);
        });
        self.wait()?;
        // Unmap only what was mapped: a failed map leaves the buffer unmapped.
        rx.try_recv().map_err(|e| err(format!("map_async did not complete: {e}")))?.map_err(|e| err(e.to_string()))?;
        let value = slice.get_mapped_range().map(|data| f(&data));
        buffer.unmap();
        value.map_err(|e| err(e.to_string()))
    }

    /// Reads back an `Rgba32Float` texture as an [`crate::Image`].
    pub fn read_image(&self, texture: &wgpu::Texture) -> Result<crate::Image, Error> {
        let f = self.read_texture_f32(texture, 0)?;
        Ok(crate::Image {
            width: texture.width(),
            height: texture.height(),
            pixels: f.chunks_exact(4).map(|c| [c[0], c[1], c[2], c[3]]).collect(),
        })
    }

    /// Creates a texture and uploads data with a tightly packed layout (`bytes_per_texel` per
    /// texel, `layers` layers).
    pub fn upload_texture(
        &self,
        label: &str,
        format: wgpu::TextureFormat,
        width: u32,
        height: u32,
        layers: u32,
        bytes_per_texel: u32,
        data: &[u8],
    ) -> wgpu::Texture {
        let tex = self.device.create_texture(&wgpu::TextureDescriptor {
            label: Some(label),
            size: wgpu::Extent3d { width, height, depth_or_array_layers: layers },
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format,
            usage: wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
            view_formats: &[],
        });
        self.queue.write_texture(
            wgpu::TexelCopyTextureInfo {
                texture: &tex,
                mip_level: 0,
                origin: wgpu::Origin3d::ZERO,
                aspect: wgpu::TextureAspect::All,
            },
            data,
            wgpu::TexelCopyBufferLayout {
                offset: 0,
                bytes_per_row: Some(width * bytes_per_texel),
                rows_per_image: Some(height),
            },
            wgpu::Extent3d { width, height, depth_or_array_layers: layers },
        );
        tex
    }

    /// Uploads a spot texture as `Rgba32Float` (or a 1×1 white texture for `None`).
    pub fn upload_rgb_texture(&self, tex: Option<&crate::RgbTexture>) -> wgpu::Texture {
        match tex {
            Some(t) => self.upload_texture(
                "spot texture",
                wgpu::TextureFormat::Rgba32Float,
                t.width,
                t.height,
                1,
                16,
                bytemuck::cast_slice(&t.texels),
            ),
            None => self.upload_texture(
                "white",
                wgpu::TextureFormat::Rgba32Float,
                1,
                1,
                1,
                16,
                bytemuck::cast_slice(&[1.0f32; 4]),
            ),
        }
    }

    /// Creates the `Rgba32Float` storage texture a technique writes its in-scattering into.
    pub fn create_output_texture(&self, width: u32, height: u32) -> wgpu::Texture {
        storage_texture(&self.device, "in-scattering", wgpu::TextureFormat::Rgba32Float, width, height)
    }
}

/// A `width`×`height` 2D texture that a pass writes (storage), the next reads (sampled) and a
/// test or debug view reads back (copy source): every intermediate of the techniques.
pub fn storage_texture(
    device: &wgpu::Device,
    label: &str,
    format: wgpu::TextureFormat,
    width: u32,
    height: u32,
) -> wgpu::Texture {
    device.create_texture(&wgpu::TextureDescriptor {
        label: Some(label),
        size: wgpu::Extent3d { width, height, depth_or_array_layers: 1 },
        mip_level_count: 1,
        sample_count: 1,
        dimension: wgpu::TextureDimension::D2,
        format,
        usage: wgpu::TextureUsages::STORAGE_BINDING
            | wgpu::TextureUsages::TEXTURE_BINDING
            | wgpu::TextureUsages::COPY_SRC,
        view_formats: &[],
    })
}

/// Timestamp slots for one pass, handed to the pass descriptor.
#[derive(Clone, Copy)]
pub struct TimestampSlot<'a> {
    set: &'a wgpu::QuerySet,
    index: u32,
}

impl<'a> TimestampSlot<'a> {
    /// For a compute pass descriptor.
    pub fn compute(self) -> wgpu::ComputePassTimestampWrites<'a> {
        wgpu::ComputePassTimestampWrites {
            query_set: self.set,
            beginning_of_pass_write_index: Some(self.index),
            end_of_pass_write_index: Some(self.index + 1),
        }
    }
    /// For a render pass descriptor.
    pub fn render(self) -> wgpu::RenderPassTimestampWrites<'a> {
        wgpu::RenderPassTimestampWrites {
            query_set: self.set,
            beginning_of_pass_write_index: Some(self.index),
            end_of_pass_write_index: Some(self.index + 1),
        }
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
        timestamp_writes: ts.map(|t| t.compute()),
    })
}

/// Times passes. On hardware adapters with timestamp queries each pass writes begin/end
/// timestamps; elsewhere (software adapters) each pass is submitted on its own and waited for,
/// and its synchronised wall-clock time is recorded. With [`StatsMode::Off`] it only submits.
pub struct PassTimer {
    off: bool,
    query_set: Option<wgpu::QuerySet>,
    names: Vec<String>,
    wall_ms: Vec<f64>,
    capacity: u32,
}

impl PassTimer {
    /// A timer for up to `max_passes` passes.
    pub fn new(gpu: &GpuContext, max_passes: u32) -> Self {
        let off = gpu.stats == StatsMode::Off;
        let query_set = (gpu.timestamps && !off).then(|| {
            gpu.device.create_query_set(&wgpu::QuerySetDescriptor {
                label: Some("pass timestamps"),
                ty: wgpu::QueryType::Timestamp,
                count: max_passes * 2,
            })
        });
        Self { off, query_set, names: Vec::new(), wall_ms: Vec::new(), capacity: max_passes }
    }

    /// "timestamp-queries", "wall-clock" or "off".
    pub fn mode(&self) -> &'static str {
        match (self.off, &self.query_set) {
            (true, _) => "off",
            (false, Some(_)) => "timestamp-queries",
            (false, None) => "wall-clock",
        }
    }

    /// False with [`StatsMode::Off`]: the frame's counters should not be read back either.
    pub fn measuring(&self) -> bool {
        !self.off
    }

    /// Records one pass: `record` gets a fresh encoder (inside a debug group named `name`) and
    /// the timestamp slot to put in its pass descriptor; the encoder is submitted afterwards.
    pub fn pass(
        &mut self,
        gpu: &GpuContext,
        name: &str,
        record: impl FnOnce(&mut wgpu::CommandEncoder, Option<TimestampSlot<'_>>),
    ) -> Result<(), Error> {
        let index = self.names.len() as u32;
        let slot = match &self.query_set {
            Some(set) if index < self.capacity => Some(TimestampSlot { set, index: index * 2 }),
            _ => None,
        };
        // No clock with StatsMode::Off: std's Instant panics on wasm32.
        let start = (!self.off).then(Instant::now);
        gpu.scoped(name, || {
            let mut enc = gpu.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some(name) });
            enc.push_debug_group(name);
            record(&mut enc, slot);
            enc.pop_debug_group();
            gpu.queue.submit([enc.finish()]);
        })?;
        if self.query_set.is_none() && !self.off {
            gpu.wait()?;
        }
        self.wall_ms.push(start.map_or(0.0, |t| t.elapsed().as_secs_f64() * 1e3));
        self.names.push(name.to_string());
        Ok(())
    }

    /// Records one pass named `name` that is a single compute dispatch: `pipeline` with
    /// `bind_group` at group 0 and `groups` workgroups, in a compute pass labelled `label`.
    pub fn dispatch(
        &mut self,
        gpu: &GpuContext,
        name: &str,
        label: &str,
        pipeline: &wgpu::ComputePipeline,
        bind_group: &wgpu::BindGroup,
        groups: [u32; 3],
    ) -> Result<(), Error> {
        self.pass(gpu, name, |enc, ts| {
            let mut pass = compute_pass(enc, label, ts);
            pass.set_pipeline(pipeline);
            pass.set_bind_group(0, bind_group, &[]);
            pass.dispatch_workgroups(groups[0], groups[1], groups[2]);
        })
    }

    /// Waits for the passes and returns their times (with [`StatsMode::Off`]: their names, 0 ms,
    /// without waiting).
    pub fn finish(self, gpu: &GpuContext) -> Result<Vec<PassTime>, Error> {
        let Some(set) = &self.query_set else {
            return Ok(self.names.into_iter().zip(self.wall_ms).map(|(name, ms)| PassTime { name, ms }).collect());
        };
        let n = (self.names.len() as u32).min(self.capacity) * 2;
        let resolve = gpu.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("timestamps"),
            size: (n.max(2) * 8) as u64,
            usage: wgpu::BufferUsages::QUERY_RESOLVE | wgpu::BufferUsages::COPY_SRC,
            mapped_at_creation: false,
        });
        let read = gpu.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("timestamps readback"),
            size: (n.max(2) * 8) as u64,
            usage: wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::MAP_READ,
            mapped_at_creation: false,
        });
        let mut enc = gpu.device.create_command_encoder(&Default::default());
        enc.resolve_query_set(set, 0..n, &resolve, 0);
        enc.copy_buffer_to_buffer(&resolve, 0, &read, 0, (n * 8) as u64);
        gpu.queue.submit([enc.finish()]);
        let period = gpu.queue.get_timestamp_period() as f64;
        let ticks: Vec<u64> = gpu.read_mapped(&read, "reading timestamps", |d| bytemuck::cast_slice(d).to_vec())?;
        Ok(self
            .names
            .into_iter()
            .enumerate()
            .map(|(i, name)| {
                let ms = match (ticks.get(2 * i), ticks.get(2 * i + 1)) {
                    (Some(a), Some(b)) => b.saturating_sub(*a) as f64 * period * 1e-6,
                    _ => self.wall_ms[i],
                };
                PassTime { name, ms }
            })
            .collect())
    }
}

/// The GPU adapter for tests: `Some` when one exists; `None` with a printed reason when none
/// does — unless `CREPUSCULAR_REQUIRE_GPU=1`, in which case a missing adapter fails the test.
#[doc(hidden)]
pub fn test_gpu(test: &str) -> Option<GpuContext> {
    match GpuContext::new() {
        Ok(g) => {
            eprintln!("{test}: GPU adapter {}", g.describe());
            Some(g)
        }
        Err(e) => {
            if std::env::var("CREPUSCULAR_REQUIRE_GPU").is_ok_and(|v| v == "1") {
                panic!("{test}: CREPUSCULAR_REQUIRE_GPU=1 but {e}");
            }
            eprintln!("SKIPPED {test}: {e} (set CREPUSCULAR_REQUIRE_GPU=1 to make this a failure)");
            None
        }
    }
}

/// A CPU frame's depth, shadow map and spot texture uploaded as GPU textures (`R32Float`
/// depth and shadow layers, `Rgba32Float` spot texture), so a GPU technique can run on exactly
/// the inputs the CPU mirror sees.
pub struct UploadedFrame {
    /// Camera depth (`R32Float`).
    pub depth: wgpu::TextureView,
    /// Shadow map (`R32Float` array).
    pub shadow_map: wgpu::TextureView,
    /// Spot texture, if the light has one.
    pub spot_texture: Option<wgpu::TextureView>,
}

impl UploadedFrame {
    /// Uploads the inputs of `frame`.
    pub fn new(gpu: &GpuContext, frame: &crate::CpuFrame) -> Result<Self, Error> {
        let d = frame.desc;
        let sp = &frame.shadow_map.projection;
        gpu.check_texture_size("image size", d.width, d.height)?;
        gpu.check_texture_size("shadow_map_size", sp.size, sp.size)?;
        gpu.scoped("uploading a CPU frame", || {
            let depth = gpu.upload_texture(
                "depth",
                wgpu::TextureFormat::R32Float,
                d.width,
                d.height,
                1,
                4,
                bytemuck::cast_slice(frame.depth),
            );
            let shadow = gpu.upload_texture(
                "shadow map",
                wgpu::TextureFormat::R32Float,
                sp.size,
                sp.size,
                sp.layers,
                4,
                bytemuck::cast_slice(&frame.shadow_map.depth),
            );
            Self {
                depth: depth.create_view(&Default::default()),
                shadow_map: shadow.create_view(&wgpu::TextureViewDescriptor {
                    dimension: Some(wgpu::TextureViewDimension::D2Array),
                    ..Default::default()
                }),
                spot_texture: frame
                    .spot_texture()
                    .map(|t| gpu.upload_rgb_texture(Some(t)).create_view(&Default::default())),
            }
        })
    }

    /// The frame boundary over these textures.
    pub fn frame<'a>(&'a self, desc: &'a crate::frame::FrameDesc) -> crate::GpuFrame<'a> {
        crate::GpuFrame {
            desc,
            depth: &self.depth,
            shadow_map: &self.shadow_map,
            spot_texture: self.spot_texture.as_ref(),
        }
    }
}
