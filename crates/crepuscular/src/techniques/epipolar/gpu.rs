//! The GPU side of `epipolar`: its passes (`prefilter`, `lines`, `coordinates`, `refine`,
//! `args`, `march`, `interpolate`, `upsample`; the module documentation of `epipolar` says what
//! each does), their textures and buffers, and the frame's encode.

use super::*;
use crate::gpu::compute_pass;
use crate::techniques::pass::ShaderVariant;

/// The textures and buffers whose size depends on (samples, slices) and the image size.
struct Sized {
    key: [u32; 4],
    lines: wgpu::Buffer,
    list: wgpu::Buffer,
    claims: wgpu::Buffer,
    coords: wgpu::Texture,
    interp: wgpu::Texture,
    marched: wgpu::Texture,
    radiance: wgpu::Texture,
    /// Views of coords, interp, marched, radiance (made once, so the bind groups stay valid).
    views: [wgpu::TextureView; 4],
}

impl Sized {
    fn bytes(&self) -> u64 {
        let texels = self.key[0] as u64 * self.key[1] as u64;
        let pixels = self.key[2] as u64 * self.key[3] as u64;
        let radiance = pass::texel_bytes(self.marched.format());
        self.lines.size() + self.list.size() + self.claims.size() + texels * (16 + 4 + radiance) + pixels * radiance
    }
}

/// The prefiltered spot texture (technique-owned).
struct Prefiltered {
    texture: wgpu::Texture,
    view: wgpu::TextureView,
    /// The same texture as the one-layer array the march binds.
    array: wgpu::TextureView,
}

/// The GPU side of `epipolar`: pipelines, uniform and counter buffers, and the line textures,
/// built once and reused (the line textures are reallocated only when `samples` or `slices`
/// change, the prefiltered spot texture when its size does).
pub struct Epipolar {
    /// Current settings; changes apply on the next `Epipolar::encode`.
    pub settings: EpipolarSettings,
    passes: Passes,
    buffers: pass::FrameBuffers,
    /// The lights as the march reads them (the prefiltered spot texture's layer and size).
    march_lights: wgpu::Buffer,
    params_buffer: wgpu::Buffer,
    counters: wgpu::Buffer,
    indirect: wgpu::Buffer,
    white: wgpu::TextureView,
    sized: Option<Sized>,
    prefiltered: Option<Prefiltered>,
    last_params: Option<EpipolarParams>,
    binds: pass::BindCache<Binds>,
    /// `march = "minmax"`: the tree and the walk's pipeline, built on the first such frame.
    minmax: Option<MinmaxMarch>,
    /// The format of the marched and interpolated radiance ([`pass::intermediate_format`]).
    inter: wgpu::TextureFormat,
}

/// What `march = "minmax"` adds: the min-max tree of the frame and the march that walks it.
struct MinmaxMarch {
    tree: crate::techniques::minmax::TreeBuilder,
    march: Pass,
    binds: pass::BindCache<wgpu::BindGroup>,
}

impl MinmaxMarch {
    fn new(device: &wgpu::Device, inter: wgpu::TextureFormat) -> Result<Self, Error> {
        let src = pass::with_storage_format(&march_minmax_source(), "marched_tex", inter);
        let march = Pass::new(device, "epipolar/march (minmax)", &src, "march")?;
        Ok(Self { tree: crate::techniques::minmax::TreeBuilder::new(device)?, march, binds: Default::default() })
    }
}

/// The bind groups of one frame's passes (`prefilter` only with a prefiltered spot texture).
struct Binds {
    prefilter: Option<wgpu::BindGroup>,
    lines: wgpu::BindGroup,
    coordinates: wgpu::BindGroup,
    refine: wgpu::BindGroup,
    args: wgpu::BindGroup,
    march: wgpu::BindGroup,
    interpolate: wgpu::BindGroup,
    upsample: wgpu::BindGroup,
}

/// The passes, in frame order (lines.wgsl and refine.wgsl hold two entry points each).
struct Passes {
    prefilter: Pass,
    lines: Pass,
    coordinates: Pass,
    refine: Pass,
    args: Pass,
    march: Pass,
    interpolate: Pass,
    upsample: Pass,
}

impl Passes {
    fn new(device: &wgpu::Device, output: wgpu::TextureFormat) -> Result<Self, Error> {
        let inter = pass::intermediate_format(output);
        let pass = |name: &str, src: &str, entry: &str| {
            Pass::new(device, &format!("epipolar/{name}"), &pass_source(src), entry)
        };
        Ok(Self {
            prefilter: pass("prefilter", PREFILTER_WGSL, "prefilter")?,
            lines: pass("lines", LINES_WGSL, "lines")?,
            coordinates: pass("coordinates", LINES_WGSL, "coordinates")?,
            refine: pass("refine", REFINE_WGSL, "refine")?,
            args: pass("args", REFINE_WGSL, "args")?,
            march: pass("march", &pass::with_storage_format(MARCH_WGSL, "marched_tex", inter), "march")?,
            interpolate: pass(
                "interpolate",
                &pass::with_storage_format(INTERPOLATE_WGSL, "radiance_tex", inter),
                "interpolate",
            )?,
            upsample: pass("upsample", &pass::with_output(UPSAMPLE_WGSL, output), "upsample")?,
        })
    }
}

impl Epipolar {
    /// Builds the passes and the size-independent buffers.
    pub(crate) fn new(
        gpu: &GpuContext,
        settings: EpipolarSettings,
        output: wgpu::TextureFormat,
    ) -> Result<Self, Error> {
        settings.validate()?;
        gpu.try_scoped("creating the epipolar pipelines", || {
            let device = &gpu.device;
            let inter = pass::intermediate_format(output);
            let passes = Passes::new(device, output)?;
            let buf = |label, size, usage| {
                device.create_buffer(&wgpu::BufferDescriptor {
                    label: Some(label),
                    size,
                    usage,
                    mapped_at_creation: false,
                })
            };
            use wgpu::BufferUsages as U;
            Ok(Self {
                settings,
                passes,
                buffers: pass::FrameBuffers::new(device),
                march_lights: pass::uniform_buffer(
                    device,
                    "epipolar march lights",
                    std::mem::size_of::<crate::LightsUniforms>() as u64,
                ),
                params_buffer: pass::uniform_buffer(
                    device,
                    "epipolar params",
                    std::mem::size_of::<EpipolarParams>() as u64,
                ),
                counters: buf("epipolar counters", 16, U::STORAGE | U::COPY_DST | U::COPY_SRC),
                indirect: buf("epipolar march dispatch", 12, U::STORAGE | U::INDIRECT),
                white: pass::white_array(gpu),
                sized: None,
                prefiltered: None,
                last_params: None,
                binds: Default::default(),
                minmax: None,
                inter,
            })
        })
    }

    /// Bytes of GPU memory this technique holds: uniform, counter and indirect buffers, the
    /// 1×1 white texture, the line buffer, the sample list, the per-pixel claims (4 B per
    /// pixel), the three line textures (coordinates 16 B, interpolation 4 B, radiance 16 B per
    /// texel), the marched texture (16 B per pixel) and the prefiltered spot texture; the
    /// radiance and marched textures take 8 B when the output is `Rgba16Float`.
    pub fn gpu_memory_bytes(&self) -> u64 {
        let pre = self.prefiltered.as_ref().map_or(0, |p| p.texture.width() as u64 * p.texture.height() as u64 * 16);
        self.buffers.size()
            + self.params_buffer.size()
            + self.counters.size()
            + self.indirect.size()
            + 16
            + self.sized.as_ref().map_or(0, Sized::bytes)
            + pre
            + self.minmax.as_ref().map_or(0, |m| m.tree.gpu_memory_bytes())
    }

    /// The coordinate texture of the last frame (`Rgba32Float`, `samples` × `slices`: p.x,
    /// p.y, view distance s of pixel ⌊p⌋, valid); None before the first render.
    pub fn coordinate_texture(&self) -> Option<&wgpu::Texture> {
        self.sized.as_ref().map(|s| &s.coords)
    }
    /// The interpolation texture of the last frame (`R32Uint`: left | right << 16; left =
    /// right = t marks a ray-march sample; 0 on culled lines).
    pub fn interpolation_texture(&self) -> Option<&wgpu::Texture> {
        self.sized.as_ref().map(|s| &s.interp)
    }
    /// The ray-marched samples of the last frame, by pixel (the output's format, image size:
    /// in-scattering, s); pixels that were not ray-marched hold stale values.
    pub fn marched_texture(&self) -> Option<&wgpu::Texture> {
        self.sized.as_ref().map(|s| &s.marched)
    }
    /// The radiance texture of the last frame (the output's format: in-scattering interpolated
    /// along the lines, view distance s in alpha; 0 on culled lines).
    pub fn radiance_texture(&self) -> Option<&wgpu::Texture> {
        self.sized.as_ref().map(|s| &s.radiance)
    }
    /// The uniform block of the last frame (with its epipole).
    pub fn last_params(&self) -> Option<&EpipolarParams> {
        self.last_params.as_ref()
    }

    /// Reads the last frame's lines and line textures back for the debug views and tests.
    pub fn read_debug(&self, gpu: &GpuContext) -> Result<EpipolarDebug, Error> {
        let (Some(s), Some(p)) = (self.sized.as_ref(), self.last_params.as_ref()) else {
            return Err(Error::invalid("epipolar debug", "none", "no frame rendered yet"));
        };
        let rgba = |t: &wgpu::Texture| -> Result<Vec<[f32; 4]>, Error> {
            Ok(gpu.read_texture_f32(t, 0)?.chunks_exact(4).map(|c| [c[0], c[1], c[2], c[3]]).collect())
        };
        let interp: Vec<u32> = gpu.read_texture_f32(&s.interp, 0)?.into_iter().map(f32::to_bits).collect();
        let lines: Vec<EpipolarLine> = bytemuck::cast_slice(&crate::scattering::read_buffer(gpu, &s.lines)?).to_vec();
        Ok(EpipolarDebug { params: *p, lines, coords: rgba(&s.coords)?, interp, radiance: rgba(&s.radiance)? })
    }

    /// (Re)allocates the line textures and buffers for `samples` × `slices` and the per-pixel
    /// ones for `width` × `height`.
    fn ensure_sized(
        &mut self,
        gpu: &GpuContext,
        samples: u32,
        slices: u32,
        width: u32,
        height: u32,
    ) -> Result<(), Error> {
        let key = [samples, slices, width, height];
        if self.sized.as_ref().is_some_and(|s| s.key == key) {
            return Ok(());
        }
        gpu.check_texture_size("epipolar line textures (samples × slices)", samples, slices)?;
        gpu.check_texture_size("epipolar marched texture", width, height)?;
        let texels = samples as u64 * slices as u64;
        let pixels = width as u64 * height as u64;
        let list_bytes = texels.min(pixels) * 4;
        let limit = gpu.device.limits().max_storage_buffer_binding_size;
        for (what, bytes) in [
            ("epipolar sample list (4 bytes × min(samples × slices, pixels))", list_bytes),
            ("epipolar pixel claims (4 bytes × pixels)", pixels * 4),
        ] {
            if bytes > limit {
                return Err(Error::Limit { what: what.into(), value: bytes, limit });
            }
        }
        self.sized = None;
        self.sized = Some(gpu.scoped("allocating the epipolar line textures", || {
            let device = &gpu.device;
            let texture =
                |label, format, width, height| crate::gpu::storage_texture(device, label, format, width, height);
            let buffer = |label, size| {
                device.create_buffer(&wgpu::BufferDescriptor {
                    label: Some(label),
                    size,
                    usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC | wgpu::BufferUsages::COPY_DST,
                    mapped_at_creation: false,
                })
            };
            use wgpu::TextureFormat as F;
            let coords = texture("epipolar coordinates", F::Rgba32Float, samples, slices);
            let interp = texture("epipolar interpolation", F::R32Uint, samples, slices);
            let marched = texture("epipolar marched radiance", self.inter, width, height);
            let radiance = texture("epipolar radiance", self.inter, samples, slices);
            let views = [&coords, &interp, &marched, &radiance].map(|t| t.create_view(&Default::default()));
            Sized {
                key,
                lines: buffer("epipolar lines", slices as u64 * 32),
                list: buffer("epipolar sample list", list_bytes.max(4)),
                claims: buffer("epipolar pixel claims", pixels * 4),
                coords,
                interp,
                marched,
                radiance,
                views,
            }
        })?);
        Ok(())
    }

    /// (Re)allocates the prefiltered spot texture for a `pre_size` of (w, h) texels, or drops it.
    fn ensure_prefiltered(&mut self, gpu: &GpuContext, pre_size: Option<(u32, u32)>) -> Result<(), Error> {
        match pre_size {
            Some((w, h)) => {
                if self.prefiltered.as_ref().is_none_or(|p| p.texture.width() != w || p.texture.height() != h) {
                    self.prefiltered = Some(gpu.scoped("allocating the prefiltered spot texture", || {
                        let texture = crate::gpu::storage_texture(
                            &gpu.device,
                            "epipolar prefiltered spot texture",
                            wgpu::TextureFormat::Rgba32Float,
                            w,
                            h,
                        );
                        let view = texture.create_view(&Default::default());
                        let array = texture.create_view(&wgpu::TextureViewDescriptor {
                            dimension: Some(wgpu::TextureViewDimension::D2Array),
                            ..Default::default()
                        });
                        Prefiltered { texture, view, array }
                    })?);
                }
            }
            None => self.prefiltered = None,
        }
        Ok(())
    }

    /// The frame's bind groups: what each pass reads and writes, named as its shader names it.
    /// `spot` is the light's spot texture (when it has one).
    fn bind(
        &self,
        gpu: &GpuContext,
        frame: &GpuFrame,
        output: &wgpu::TextureView,
        spot: Option<&wgpu::TextureView>,
    ) -> Result<Binds, Error> {
        let sized = self.sized.as_ref().expect("allocated before binding");
        let [coords, interp, marched, radiance] = &sized.views;
        let march_spot = self.march_spot(frame);
        use wgpu::BindingResource as R;
        let device = &gpu.device;
        let p = &self.passes;
        let prefilter = match (&self.prefiltered, spot) {
            (Some(pre), Some(src)) => Some(p.prefilter.bind(
                device,
                &[
                    ("params", self.params_buffer.as_entire_binding()),
                    ("lights", self.buffers.lights.as_entire_binding()),
                    ("src_tex", R::TextureView(src)),
                    ("dst_tex", R::TextureView(&pre.view)),
                ],
            )?),
            _ => None,
        };
        // Every pass reads the uniforms; each names what else it reads and writes.
        let frame_res = || pass::frame_resources(&self.buffers, &self.params_buffer, frame, &self.white);
        let uniforms = || pass::uniform_resources(&self.buffers, &self.params_buffer);
        let lines = pass::with(
            uniforms(),
            [
                ("depth_tex", R::TextureView(frame.depth)),
                ("lines_buf", sized.lines.as_entire_binding()),
                ("coord_tex", R::TextureView(coords)),
                ("counters", self.counters.as_entire_binding()),
            ],
        );
        let refine = pass::with(
            uniforms(),
            [
                ("coord_tex", R::TextureView(coords)),
                ("lines_buf", sized.lines.as_entire_binding()),
                ("interp_tex", R::TextureView(interp)),
                ("list", sized.list.as_entire_binding()),
                ("counters", self.counters.as_entire_binding()),
                ("dispatch", self.indirect.as_entire_binding()),
                ("claims", sized.claims.as_entire_binding()),
            ],
        );
        // The march reads the prefiltered spot texture through its own lights.
        let march = pass::with(
            frame_res(),
            [
                ("spot_tex", R::TextureView(march_spot)),
                ("lights", self.march_lights.as_entire_binding()),
                ("marched_tex", R::TextureView(marched)),
                ("list", sized.list.as_entire_binding()),
                ("counters", self.counters.as_entire_binding()),
            ],
        );
        let interpolate = pass::with(
            uniforms(),
            [
                ("coord_tex", R::TextureView(coords)),
                ("interp_tex", R::TextureView(interp)),
                ("marched_tex", R::TextureView(marched)),
                ("radiance_tex", R::TextureView(radiance)),
            ],
        );
        let upsample = pass::with(
            frame_res(),
            [
                ("radiance_tex", R::TextureView(radiance)),
                ("lines_buf", sized.lines.as_entire_binding()),
                ("counters", self.counters.as_entire_binding()),
                ("out_tex", R::TextureView(output)),
            ],
        );
        Ok(Binds {
            prefilter,
            lines: p.lines.bind(device, &lines)?,
            coordinates: p.coordinates.bind(device, &lines)?,
            refine: p.refine.bind(device, &refine)?,
            args: p.args.bind(device, &refine)?,
            march: p.march.bind(device, &march)?,
            interpolate: p.interpolate.bind(device, &interpolate)?,
            upsample: p.upsample.bind(device, &upsample)?,
        })
    }

    /// The spot texture the march reads: the prefiltered one when it runs, else the frame's
    /// (or the white stand-in).
    fn march_spot<'a>(&'a self, frame: &GpuFrame<'a>) -> &'a wgpu::TextureView {
        let frame_spot = frame.spot_textures.unwrap_or(&self.white);
        self.prefiltered.as_ref().map_or(frame_spot, |p| &p.array)
    }

    /// Records the in-scattering of `frame` into `output` (an `Rgba32Float` storage view of
    /// the frame's size) through `rec`. Passes, each timed: `prefilter` (when it runs),
    /// `lines`, `refine`, `march`, `interpolate`, `upsample` (see the module documentation).
    /// The stats' counts come from the GPU's counters once they are read back (the fields:
    /// module documentation, Stats).
    pub(crate) fn encode(
        &mut self,
        gpu: &GpuContext,
        rec: &mut Recorder,
        frame: &GpuFrame,
        output: &wgpu::TextureView,
    ) -> Result<TechniqueStats, Error> {
        self.settings.validate()?;
        let desc = frame.desc;
        let light = desc.single_light()?;
        let s = self.settings.clone();
        let max_wg = gpu.device.limits().max_compute_workgroups_per_dimension.max(1);
        let mut params = EpipolarParams::new(&s, desc, max_wg);
        self.ensure_sized(gpu, params.samples, params.slices, desc.width, desc.height)?;
        let spot = frame.spot_textures.filter(|_| light.spot_texture().is_some());
        if spot.is_none() {
            params.prefilter_level = 0;
        }
        // The prefiltered spot texture: ⌈w/2^L⌉ × ⌈h/2^L⌉ of the light's own texture.
        let pre_size = light.spot_texture().filter(|_| spot.is_some() && params.prefilter_level > 0).map(|t| {
            let n = 1u32 << params.prefilter_level;
            (t.width.div_ceil(n), t.height.div_ceil(n))
        });
        self.ensure_prefiltered(gpu, pre_size)?;
        self.buffers.write(rec, desc);
        // The march reads the prefiltered texture: layer 0 of its own array, at its size.
        let mut march_lights = desc.lights_uniforms();
        if let Some((w, h)) = pre_size {
            march_lights.items[0].texture_layer = 0;
            march_lights.items[0].texture_size = [w, h];
        }
        rec.write_buffer(&self.march_lights, bytemuck::bytes_of(&march_lights));
        rec.write_buffer(&self.params_buffer, bytemuck::bytes_of(&params));
        let sized = self.sized.as_ref().expect("allocated above");
        let [coords, _, marched, _] = &sized.views;
        // Field by field (not `self.march_spot`), so the borrow leaves `binds` and `minmax` free.
        let frame_spot = frame.spot_textures.unwrap_or(&self.white);
        let march_spot = self.prefiltered.as_ref().map_or(frame_spot, |p| &p.array);
        let mut key = pass::frame_key(frame, output);
        key.extend([Bound::View(coords.clone()), Bound::View(march_spot.clone())]);
        key.push(match (&self.prefiltered, spot) {
            (Some(p), Some(_)) => Bound::View(p.view.clone()),
            _ => Bound::Choice(0),
        });
        if !self.binds.is_current(&key) {
            let binds = gpu.try_scoped("binding the epipolar inputs", || self.bind(gpu, frame, output, spot))?;
            self.binds.store(key, binds);
        }
        let b = self.binds.value();
        let (samples, slices) = (params.samples, params.slices);
        let (w, h) = (desc.width, desc.height);
        let p = &self.passes;
        let variant = frame.shader_variant();
        if let (Some(bind), Some(pre)) = (&b.prefilter, &self.prefiltered) {
            let groups = p.prefilter.groups_2d(pre.texture.width(), pre.texture.height());
            p.prefilter.dispatch(rec, variant, "prefilter", bind, groups)?;
        }
        rec.pass("lines", |enc, ts| {
            enc.clear_buffer(&self.counters, 0, None);
            stage(
                variant,
                compute_pass(enc, "epipolar lines", ts),
                &[
                    (&p.lines, &b.lines, [slices.div_ceil(p.lines.workgroup_size()[0]), 1, 1]),
                    (&p.coordinates, &b.coordinates, p.coordinates.groups_2d(samples, slices)),
                ],
            );
        })?;
        rec.pass("refine", |enc, ts| {
            enc.clear_buffer(&sized.claims, 0, None);
            stage(
                variant,
                compute_pass(enc, "epipolar refine", ts),
                // One thread per initial segment (at most K − 1 on a line) and line.
                &[
                    (&p.refine, &b.refine, p.refine.groups_2d(params.initial_samples - 1, slices)),
                    (&p.args, &b.args, [1, 1, 1]),
                ],
            );
        })?;
        let minmax_march = s.march == EpipolarMarch::Minmax;
        let indirect = |kernel: &Pass, bind: &wgpu::BindGroup, rec: &mut Recorder| {
            rec.pass("march", |enc, ts| {
                let mut pass = compute_pass(enc, kernel.label(), ts);
                pass.set_pipeline(kernel.pipeline(variant));
                pass.set_bind_group(0, bind, &[]);
                pass.dispatch_workgroups_indirect(&self.indirect, 0);
            })
        };
        if minmax_march {
            // The tree (minmax's `rectify` and `build`), then the walk per listed pixel.
            if self.minmax.is_none() {
                self.minmax =
                    Some(gpu.try_scoped("creating the epipolar min-max march", || {
                        MinmaxMarch::new(&gpu.device, self.inter)
                    })?);
            }
            let mm = self.minmax.as_mut().expect("built above");
            let march_frame = GpuFrame { spot_textures: Some(march_spot), ..*frame };
            // Always resampled (epipolar asks the host for no rectified raster), as on the CPU.
            mm.tree.encode(gpu, rec, &march_frame, &s.minmax(), &self.buffers, false)?;
            let tree = mm.tree.tree().expect("built by encode").clone();
            let mut key = pass::frame_key(frame, marched);
            key.extend([Bound::Buffer(tree.clone()), Bound::View(march_spot.clone())]);
            if !mm.binds.is_current(&key) {
                let group = gpu.try_scoped("binding the epipolar min-max march", || {
                    use wgpu::BindingResource as R;
                    let res = pass::with(
                        pass::frame_resources(&self.buffers, mm.tree.params_buffer(), frame, &self.white),
                        [
                            ("spot_tex", R::TextureView(march_spot)),
                            ("lights", self.march_lights.as_entire_binding()),
                            ("marched_tex", R::TextureView(marched)),
                            ("tree", tree.as_entire_binding()),
                            ("list", sized.list.as_entire_binding()),
                            ("counters", self.counters.as_entire_binding()),
                        ],
                    );
                    mm.march.bind(&gpu.device, &res)
                })?;
                mm.binds.store(key, group);
            }
            indirect(&mm.march, mm.binds.value(), rec)?;
        } else {
            indirect(&p.march, &b.march, rec)?;
        }
        p.interpolate.dispatch(
            rec,
            variant,
            "interpolate",
            &b.interpolate,
            p.interpolate.groups_2d(samples, slices),
        )?;
        p.upsample.dispatch(rec, variant, "upsample", &b.upsample, p.upsample.groups_2d(w, h))?;
        self.last_params = Some(params);
        // The GPU-classified counts join the stats once the counters are read back (never with
        // StatsMode::Off: reading them at once would stall the frame).
        let steps = s.ray_march.steps as u64;
        rec.read_counters(&self.counters, move |data, stats| {
            let v: &[u32] = bytemuck::cast_slice(&data[..16]);
            let [marched_n, remarched, valid_lines, sample_texels] = [v[0], v[1], v[2], v[3]].map(u64::from);
            // The min-max march walks its samples instead of stepping them.
            stats.raymarched_samples = (if minmax_march { remarched } else { marched_n + remarched }) * steps;
            stats.extra = stats_extra(&params, (w, h), valid_lines, marched_n, remarched, sample_texels);
        });
        let mut extra = stats_extra(&params, (w, h), 0, 0, 0, 0);
        for k in ["valid_lines", "marched_samples", "sample_texels", "remarched_pixels", "marched_share"] {
            extra.remove(k);
        }
        Ok(TechniqueStats {
            technique: "epipolar".into(),
            backend: "gpu".into(),
            timing: String::new(),
            passes: Vec::new(),
            raymarched_samples: 0,
            gpu_memory_bytes: self.gpu_memory_bytes(),
            extra,
        })
    }
}

/// Records `steps` (a pass, its bind group, its workgroups) into one compute pass, each in
/// `variant`'s pipeline: a timed stage whose entry points share it.
fn stage(variant: ShaderVariant, mut pass: wgpu::ComputePass<'_>, steps: &[(&Pass, &wgpu::BindGroup, [u32; 3])]) {
    for (kernel, bind, [x, y, z]) in steps {
        pass.set_pipeline(kernel.pipeline(variant));
        pass.set_bind_group(0, *bind, &[]);
        pass.dispatch_workgroups(*x, *y, *z);
    }
}

gpu_technique!(Epipolar, EpipolarSettings);
