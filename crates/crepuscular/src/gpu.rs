//! The GPU context, readbacks, and per-pass timing.

use crate::error::Error;

/// How a [`crate::Scattering`] measures its frames: per-pass GPU times and the counts only the
/// GPU knows (epipolar's classified and re-marched samples, subsampled's re-marched pixels).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum StatsMode {
    /// The engine's mode, and the default: timestamp queries (where the device has
    /// `TIMESTAMP_QUERY` and is not a software adapter) and counter copies are recorded into
    /// the caller's encoder, and read back one or more frames later (a ring of query sets and
    /// readback buffers, through wgpu-profiler): [`crate::Scattering::encode`] never submits,
    /// polls or maps, and [`crate::Scattering::stats`] returns the newest frame whose results
    /// have arrived. At most 3 measured frames wait at a time; a frame encoded while they do is
    /// recorded unmeasured, so nothing grows in a loop that never asks for stats. Cost: two
    /// timestamps per pass and one small buffer copy per frame.
    #[default]
    Deferred,
    /// The tools' mode on software adapters, whose timestamps mean nothing: every pass is
    /// recorded into its own encoder, submitted and waited for, and timed by synchronised wall
    /// clock; counters are read back at once. `encode` then submits (one submit per pass) and
    /// waits: never use it in a frame loop. Opt-in only.
    WallClock,
    /// Nothing measured: the passes are listed with 0 ms and `timing` = `"off"`, and the
    /// GPU-only counts are left out of `raymarched_samples` and `extra`.
    Off,
}

/// A device and queue — the caller's own ([`GpuContext::from_device`]), or one this library
/// opened for a tool ([`GpuContext::new`], [`GpuContext::from_adapter`]) — and what they can do.
/// Cloning it clones the handles (wgpu's device and queue are reference-counted).
#[derive(Clone)]
pub struct GpuContext {
    /// The adapter, when this library opened the device (`None` for the caller's device).
    pub adapter: Option<wgpu::Adapter>,
    /// The device.
    pub device: wgpu::Device,
    /// The queue.
    pub queue: wgpu::Queue,
    /// Adapter information (name, backend, driver).
    pub info: wgpu::AdapterInfo,
    /// True for a software rasterizer (lavapipe, WARP, SwiftShader): its timestamp queries are
    /// not meaningful, so tools time passes by synchronised wall clock
    /// ([`StatsMode::WallClock`]).
    pub software: bool,
    /// True when the device can time passes with timestamp queries (it has `TIMESTAMP_QUERY`
    /// and is not a software adapter).
    pub timestamps: bool,
    /// The first error wgpu reported outside any error scope, or the device-lost reason: set
    /// by the handlers [`GpuContext::from_adapter`] installs (wgpu's default handler panics),
    /// turned into an [`Error::Gpu`] by [`GpuContext::wait`]. `None` on the caller's device,
    /// whose handlers stay the caller's.
    fault: Option<std::sync::Arc<std::sync::Mutex<Option<String>>>>,
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
    /// Finds an adapter (Vulkan, Metal or DX12, software adapters included; GL only when
    /// `WGPU_BACKEND=gl` asks for it) and creates a device with the adapter's own limits and
    /// only the optional features it has.
    /// Blocks on [`GpuContext::new_async`]; in a browser, await that instead.
    pub fn new() -> Result<Self, Error> {
        pollster::block_on(Self::new_async())
    }

    /// [`GpuContext::new`] as a future, for executors and the browser (wasm32, where blocking
    /// the main thread is not allowed).
    pub async fn new_async() -> Result<Self, Error> {
        // Vulkan / Metal / DX12 (or what WGPU_BACKEND asks for). Not the GL backend unless asked:
        // on Mesa's llvmpipe GL (Mesa 22.3.6) the techniques' compute passes gave wrong answers
        // (brute-force differed from its CPU mirror on every value, interleaved wrote zeros)
        // where the same passes on Vulkan match it, so a machine with only GL gets the CPU
        // backend (or a skipped GPU test) instead of a wrong picture.
        let tries = match wgpu::Backends::from_env() {
            Some(b) => vec![b],
            None => vec![wgpu::Backends::PRIMARY],
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
        let mut gpu = Self::from_device(&device, &queue);
        gpu.adapter = Some(adapter);
        gpu.fault = Some(fault);
        Ok(gpu)
    }

    /// Wraps the caller's own device and queue (an engine's: the effect then reads the
    /// engine's depth and shadow textures directly). Nothing is created or changed on the
    /// device: its error handlers stay the caller's. The optional features it has — see
    /// [`crate::Scattering`] for which ones a technique uses — choose code paths, never results.
    pub fn from_device(device: &wgpu::Device, queue: &wgpu::Queue) -> Self {
        let info = device.adapter_info();
        let name = info.name.to_lowercase();
        let software =
            info.device_type == wgpu::DeviceType::Cpu || name.contains("llvmpipe") || name.contains("swiftshader");
        let timestamps = !software && device.features().contains(wgpu::Features::TIMESTAMP_QUERY);
        Self { adapter: None, device: device.clone(), queue: queue.clone(), info, software, timestamps, fault: None }
    }

    /// Waits for the GPU ([`wait_idle`]), then reports a lost device or an error wgpu raised
    /// outside an error scope since the last call, as [`Error::Gpu`].
    pub fn wait(&self) -> Result<(), Error> {
        let waited = wait_idle(&self.device);
        let fault = self.fault.as_ref().and_then(|f| f.lock().ok().and_then(|mut f| f.take()));
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

    /// [`GpuContext::scoped`] for an `f` that may fail itself: its error or the GPU's.
    pub fn try_scoped<T>(&self, context: &str, f: impl FnOnce() -> Result<T, Error>) -> Result<T, Error> {
        self.scoped(context, f)?
    }

    /// Reads back layer `layer` of a 2D texture of a 32-bit float format (`R32Float`,
    /// `Depth32Float`, `Rgba32Float`) or a 16-bit one (`R16Float`, `Rg16Float`, `Rgba16Float`,
    /// widened exactly) as f32s.
    pub fn read_texture_f32(&self, texture: &wgpu::Texture, layer: u32) -> Result<Vec<f32>, Error> {
        use wgpu::TextureFormat::{R16Float, Rg16Float, Rgba16Float};
        let bytes = self.read_texture_bytes(texture, layer)?;
        if matches!(texture.format(), R16Float | Rg16Float | Rgba16Float) {
            return Ok(bytes.chunks_exact(2).map(|c| half::f16::from_le_bytes([c[0], c[1]]).to_f32()).collect());
        }
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
        let value = f(&slice.get_mapped_range());
        buffer.unmap();
        Ok(value)
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

    /// Uploads spot textures as one `Rgba32Float` array, one layer each, each in the top-left
    /// corner of a layer as large as the largest (a 1×1 white layer for none): what
    /// [`crate::GpuFrame::spot_textures`] binds, in [`crate::FrameDesc::assign_layers`]'s order.
    pub fn upload_spot_textures(&self, textures: &[&crate::RgbTexture]) -> wgpu::Texture {
        if textures.is_empty() {
            return self.upload_texture(
                "white",
                wgpu::TextureFormat::Rgba32Float,
                1,
                1,
                1,
                16,
                bytemuck::cast_slice(&[1.0f32; 4]),
            );
        }
        let w = textures.iter().map(|t| t.width).max().unwrap_or(1);
        let h = textures.iter().map(|t| t.height).max().unwrap_or(1);
        let mut texels = vec![[1.0f32; 4]; (w * h) as usize * textures.len()];
        for (layer, t) in textures.iter().enumerate() {
            for y in 0..t.height {
                for x in 0..t.width {
                    texels[((layer as u32 * h + y) * w + x) as usize] = t.texels[(y * t.width + x) as usize];
                }
            }
        }
        self.upload_texture(
            "spot textures",
            wgpu::TextureFormat::Rgba32Float,
            w,
            h,
            textures.len() as u32,
            16,
            bytemuck::cast_slice(&texels),
        )
    }

    /// An `Rgba32Float` texture holding `img` (sampled and copy source), uploaded through the
    /// queue: a CPU image given to a GPU pass (the temporal stage's input in the tools).
    pub fn upload_image(&self, label: &str, img: &crate::Image) -> wgpu::Texture {
        self.upload(label, wgpu::TextureFormat::Rgba32Float, img.width, img.height, bytemuck::cast_slice(&img.pixels))
    }

    /// An `R32Float` texture of `width`×`height` values (a depth buffer read back earlier).
    pub fn upload_f32(&self, label: &str, width: u32, height: u32, values: &[f32]) -> wgpu::Texture {
        self.upload(label, wgpu::TextureFormat::R32Float, width, height, bytemuck::cast_slice(values))
    }

    fn upload(&self, label: &str, format: wgpu::TextureFormat, width: u32, height: u32, bytes: &[u8]) -> wgpu::Texture {
        use wgpu::TextureUsages as U;
        let texture =
            texture_2d(&self.device, label, format, width, height, U::TEXTURE_BINDING | U::COPY_DST | U::COPY_SRC);
        let texel = format.block_copy_size(None).unwrap_or(4);
        self.queue.write_texture(
            texture.as_image_copy(),
            bytes,
            wgpu::TexelCopyBufferLayout { offset: 0, bytes_per_row: Some(width * texel), rows_per_image: Some(height) },
            wgpu::Extent3d { width, height, depth_or_array_layers: 1 },
        );
        texture
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
    use wgpu::TextureUsages as U;
    texture_2d(device, label, format, width, height, U::STORAGE_BINDING | U::TEXTURE_BINDING | U::COPY_SRC)
}

/// A `width`×`height` single-level 2D texture of `format` with `usage`.
fn texture_2d(
    device: &wgpu::Device,
    label: &str,
    format: wgpu::TextureFormat,
    width: u32,
    height: u32,
    usage: wgpu::TextureUsages,
) -> wgpu::Texture {
    device.create_texture(&wgpu::TextureDescriptor {
        label: Some(label),
        size: wgpu::Extent3d { width, height, depth_or_array_layers: 1 },
        mip_level_count: 1,
        sample_count: 1,
        dimension: wgpu::TextureDimension::D2,
        format,
        usage,
        view_formats: &[],
    })
}

pub use crate::record::{Recorder, TimestampSlot, compute_pass};

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

/// A CPU frame's depth, shadow maps and spot textures uploaded as GPU textures (`R32Float`
/// depth and shadow layers, `Rgba32Float` spot textures), so a GPU technique can run on exactly
/// the inputs the CPU mirror sees. Each light's map goes to its `shadow_layer`, each texture to
/// its `texture_layer` ([`crate::FrameDesc::assign_layers`]).
pub struct UploadedFrame {
    /// Camera depth (`R32Float`).
    pub depth: wgpu::TextureView,
    /// Shadow maps (`R32Float` array).
    pub shadow_maps: wgpu::TextureView,
    /// Spot textures, if a light has one.
    pub spot_textures: Option<wgpu::TextureView>,
}

impl UploadedFrame {
    /// Uploads the inputs of `frame`.
    pub fn new(gpu: &GpuContext, frame: &crate::CpuFrame) -> Result<Self, Error> {
        frame.validate()?;
        let d = frame.desc;
        gpu.check_texture_size("image size", d.width, d.height)?;
        let size = d.lights.iter().map(|l| l.shadow.size).max().unwrap_or(1);
        let layers = d.lights.iter().map(|l| l.shadow_layer + l.shadow.layers).max().unwrap_or(1);
        gpu.check_texture_size("shadow_map_size", size, size)?;
        let mut depths = vec![1.0f32; (size * size * layers) as usize];
        for (fl, sm) in d.lights.iter().zip(frame.shadow_maps) {
            let n = fl.shadow.size;
            for l in 0..fl.shadow.layers {
                for y in 0..n {
                    for x in 0..n {
                        depths[(((fl.shadow_layer + l) * size + y) * size + x) as usize] = sm.texel(l, x, y);
                    }
                }
            }
        }
        let mut textures: Vec<(u32, &crate::RgbTexture)> =
            d.lights.iter().filter_map(|l| l.spot_texture().map(|t| (l.texture_layer, t))).collect();
        textures.sort_by_key(|(layer, _)| *layer);
        if textures.iter().enumerate().any(|(i, (layer, _))| *layer != i as u32) {
            return Err(Error::invalid(
                "lights[].texture_layer",
                format!("{:?}", textures.iter().map(|(l, _)| *l).collect::<Vec<_>>()),
                "the textured spot lights must use layers 0, 1, … in turn (FrameDesc::assign_layers)",
            ));
        }
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
                "shadow maps",
                wgpu::TextureFormat::R32Float,
                size,
                size,
                layers,
                4,
                bytemuck::cast_slice(&depths),
            );
            let array = wgpu::TextureViewDescriptor {
                dimension: Some(wgpu::TextureViewDimension::D2Array),
                ..Default::default()
            };
            let spot = (!textures.is_empty()).then(|| {
                let list: Vec<&crate::RgbTexture> = textures.iter().map(|(_, t)| *t).collect();
                gpu.upload_spot_textures(&list).create_view(&array)
            });
            Self {
                depth: depth.create_view(&Default::default()),
                shadow_maps: shadow.create_view(&array),
                spot_textures: spot,
            }
        })
    }

    /// The frame boundary over these textures.
    pub fn frame<'a>(&'a self, desc: &'a crate::frame::FrameDesc) -> crate::GpuFrame<'a> {
        crate::GpuFrame {
            desc,
            depth: &self.depth,
            shadow_maps: &self.shadow_maps,
            spot_textures: self.spot_textures.as_ref(),
            rectified_shadow_maps: &[],
        }
    }
}
