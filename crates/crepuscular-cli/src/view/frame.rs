//! The viewer's frame: rendering the scene and the technique into the window's texture
//! (`Viewer::redraw`, `Viewer::render_scene`), and what leaves the window — screenshots with the
//! view's state beside them, the frame read back for the error view.

use super::*;

impl Viewer {
    pub(super) fn redraw(&mut self) -> Result<Flow> {
        let now = Instant::now();
        let dt = now.duration_since(self.last_frame).as_secs_f32().min(0.25);
        self.last_frame = now;
        let raw = self.egui_state.take_egui_input(&self.window);
        let ctx = self.egui_ctx.clone();
        let full = ctx.run_ui(raw, |ui| self.ui(ui, dt));
        self.egui_state.handle_platform_output(&self.window, full.platform_output);
        let repaint_now = full
            .viewport_output
            .get(&egui::ViewportId::ROOT)
            .is_some_and(|v| v.repaint_delay < Duration::from_millis(50));

        if self.dirty || self.continuous || self.screenshot_after.is_some() {
            self.dirty = false;
            match self.render_scene() {
                Ok(()) => self.render_error = None,
                Err(e) => {
                    if self.screenshot_after.is_some() {
                        return Err(e);
                    }
                    self.render_error = Some(format!("{e:#}").replace('\n', " "));
                }
            }
        }
        for action in std::mem::take(&mut self.pending) {
            if let Err(e) = self.act(action) {
                self.status = format!("error: {}", format!("{e:#}").replace('\n', " "));
            }
        }

        let frame = match self.surface.get_current_texture() {
            wgpu::CurrentSurfaceTexture::Success(t) | wgpu::CurrentSurfaceTexture::Suboptimal(t) => Some(t),
            wgpu::CurrentSurfaceTexture::Outdated | wgpu::CurrentSurfaceTexture::Lost => {
                self.surface.configure(&self.gpu.device, &self.config);
                None
            }
            wgpu::CurrentSurfaceTexture::Timeout | wgpu::CurrentSurfaceTexture::Occluded => None,
            wgpu::CurrentSurfaceTexture::Validation => bail!("view: the window surface reported a validation error"),
        };
        let ppp = full.pixels_per_point;
        for (id, delta) in &full.textures_delta.set {
            self.renderer.update_texture(&self.gpu.device, &self.gpu.queue, *id, delta);
        }
        if let Some(frame) = frame {
            let prims = ctx.tessellate(full.shapes, ppp);
            let screen = egui_wgpu::ScreenDescriptor {
                size_in_pixels: [self.config.width, self.config.height],
                pixels_per_point: ppp,
            };
            let view = frame.texture.create_view(&Default::default());
            let mut enc = self.gpu.device.create_command_encoder(&Default::default());
            let mut cmds = self.renderer.update_buffers(&self.gpu.device, &self.gpu.queue, &mut enc, &prims, &screen);
            {
                let pass = enc.begin_render_pass(&wgpu::RenderPassDescriptor {
                    label: Some("egui"),
                    color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                        view: &view,
                        depth_slice: None,
                        resolve_target: None,
                        ops: wgpu::Operations {
                            load: wgpu::LoadOp::Clear(wgpu::Color::BLACK),
                            store: wgpu::StoreOp::Store,
                        },
                    })],
                    depth_stencil_attachment: None,
                    timestamp_writes: None,
                    occlusion_query_set: None,
                    multiview_mask: None,
                });
                self.renderer.render(&mut pass.forget_lifetime(), &prims, &screen);
            }
            cmds.push(enc.finish());
            self.gpu.queue.submit(cmds);
            if self.screenshot_after.is_some_and(|n| self.frames_rendered >= n)
                && let Some(path) = std::env::var_os("CREPUSCULAR_VIEW_UI_SHOT")
            {
                self.save_window(&frame.texture, std::path::Path::new(&path))?;
            }
            self.window.pre_present_notify();
            frame.present();
        }
        for id in &full.textures_delta.free {
            self.renderer.free_texture(id);
        }

        if let Some(n) = self.screenshot_after
            && self.frames_rendered >= n
        {
            let path = self.output.clone();
            self.save_screenshot(&path)?;
            output::write_atomic(&path.with_extension("json"), self.view_state_json()?.as_bytes())?;
            eprintln!("wrote {} (and its .json) after {} frames", path.display(), self.frames_rendered);
            if let Some(f) = self.history.back() {
                let (w, h) = self.render_size();
                let passes: Vec<String> = f.passes.iter().map(|p| format!("{} {:.1}", p.name, p.ms)).collect();
                eprintln!("last frame at {w}x{h}: {:.1} ms ({} ms)", f.wall_ms, passes.join(", "));
            }
            return Ok(Flow::Exit);
        }
        if repaint_now {
            self.window.request_redraw();
        }
        Ok(Flow::Continue)
    }

    /// Renders the scene: host renderer, technique, composite into the display texture.
    pub(super) fn render_scene(&mut self) -> Result<()> {
        let start = Instant::now();
        if self.runner.is_none() {
            let built = Instant::now();
            self.runner = render::scattering(&self.gpu, &self.technique)?;
            self.runner_builds += 1;
            self.runner_build_ms = built.elapsed().as_secs_f64() * 1e3;
        }
        let scene = self.current_scene();
        let desc = render::frame_desc(&scene)?;
        let (w, h) = (desc.width, desc.height);
        if self.targets.as_ref().is_none_or(|t| t.width != w || t.height != h) {
            self.gpu.check_texture_size("render size", w, h)?;
            let inscatter = self.gpu.create_output_texture(w, h);
            let resolved = self.gpu.create_output_texture(w, h);
            let display = self.gpu.device.create_texture(&wgpu::TextureDescriptor {
                label: Some("view display"),
                size: wgpu::Extent3d { width: w, height: h, depth_or_array_layers: 1 },
                mip_level_count: 1,
                sample_count: 1,
                dimension: wgpu::TextureDimension::D2,
                format: wgpu::TextureFormat::Rgba8Unorm,
                usage: wgpu::TextureUsages::RENDER_ATTACHMENT
                    | wgpu::TextureUsages::TEXTURE_BINDING
                    | wgpu::TextureUsages::COPY_SRC,
                view_formats: &[],
            });
            let view = display.create_view(&Default::default());
            match self.display_id {
                Some(id) => self.renderer.update_egui_texture_from_wgpu_texture(
                    &self.gpu.device,
                    &view,
                    wgpu::FilterMode::Linear,
                    id,
                ),
                None => {
                    self.display_id =
                        Some(self.renderer.register_native_texture(&self.gpu.device, &view, wgpu::FilterMode::Linear))
                }
            }
            self.targets = Some(Targets { width: w, height: h, inscatter, resolved, display });
        }
        let targets = self.targets.as_ref().expect("targets were just created");
        let tex = self.host.render(&self.gpu, &desc)?;
        let runner = self.runner.as_mut().expect("runner was just built");
        if self.temporal.is_some() {
            // Each frame's samples elsewhere: jitter on, frame_index advanced (no rebuild).
            if self.technique.ray_march().is_some() {
                runner.update(&self.technique.jittered(self.frames_rendered))?;
            }
        }
        let out_view = targets.inscatter.create_view(&Default::default());
        let views = tex.views();
        let frame = views.frame(&desc);
        let mut stats = render::render_gpu(runner, Some(&self.host), &frame, &out_view)?;
        let out_view = match &mut self.temporal {
            Some(t) => {
                let start = Instant::now();
                let resolved = targets.resolved.create_view(&Default::default());
                let mut enc = self.gpu.device.create_command_encoder(&Default::default());
                t.encode(&mut enc, &desc, frame.depth, &out_view, &resolved, None)?;
                self.gpu.queue.submit([enc.finish()]);
                self.gpu.wait()?;
                stats.passes.push(PassTime { name: "temporal".into(), ms: start.elapsed().as_secs_f64() * 1e3 });
                resolved
            }
            None => out_view,
        };

        // The library's composite, with the display transform, into the display texture.
        let composite_start = Instant::now();
        let surface_view = tex.surface.create_view(&Default::default());
        let display_view = targets.display.create_view(&Default::default());
        let inputs = crepuscular::CompositeInputs {
            desc: &desc,
            depth: frame.depth,
            inscatter: &out_view,
            surface: &surface_view,
        };
        let mut enc = self.gpu.device.create_command_encoder(&Default::default());
        self.composite.encode(
            &mut enc,
            &inputs,
            crepuscular::CompositeTarget::Into(&display_view),
            Some(ToneMap::new(self.exposure)),
        )?;
        self.gpu.queue.submit([enc.finish()]);
        self.gpu.wait()?;
        let composite_ms = composite_start.elapsed().as_secs_f64() * 1e3;

        let mut passes: Vec<PassTime> =
            tex.passes.iter().map(|p| PassTime { name: format!("host: {}", p.name), ms: p.ms }).collect();
        passes.extend(stats.passes.iter().cloned());
        passes.push(PassTime { name: "composite".into(), ms: composite_ms });
        let now = Instant::now();
        self.history.push_back(FrameTiming { at: now, passes, wall_ms: start.elapsed().as_secs_f64() * 1e3 });
        while self.history.front().is_some_and(|f| now.duration_since(f.at).as_secs_f64() > HISTORY_S) {
            self.history.pop_front();
        }
        self.last_stats = Some(stats);
        self.last_host = Some((tex, desc));
        self.frames_rendered += 1;
        Ok(())
    }

    /// The scene image as tone-mapped 8-bit RGB (what the window shows behind the panels).
    pub(super) fn read_display(&self) -> Result<(u32, u32, Vec<u8>)> {
        let t = self.targets.as_ref().context("nothing rendered yet")?;
        let raw = self.gpu.read_texture_f32(&t.display, 0)?;
        let rgba: &[u8] = bytemuck::cast_slice(&raw);
        let rgb = rgba.chunks_exact(4).flat_map(|p| [p[0], p[1], p[2]]).collect();
        Ok((t.width, t.height, rgb))
    }

    /// Saves the window as presented (scene and panels): a debugging aid for the CI check.
    pub(super) fn save_window(&self, texture: &wgpu::Texture, path: &std::path::Path) -> Result<()> {
        if !texture.usage().contains(wgpu::TextureUsages::COPY_SRC) {
            bail!("CREPUSCULAR_VIEW_UI_SHOT: this surface cannot be read back");
        }
        let raw = self.gpu.read_texture_f32(texture, 0)?;
        let bgra = matches!(texture.format(), wgpu::TextureFormat::Bgra8Unorm | wgpu::TextureFormat::Bgra8UnormSrgb);
        let rgb: Vec<u8> = bytemuck::cast_slice::<f32, u8>(&raw)
            .chunks_exact(4)
            .flat_map(|p| if bgra { [p[2], p[1], p[0]] } else { [p[0], p[1], p[2]] })
            .collect();
        output::write_png_rgb8(path, texture.width(), texture.height(), &rgb)
    }

    /// What a screenshot shows, beside it as JSON: the scene, camera, light, medium, exposure,
    /// technique and settings (as `--set` takes them), the render size and the frame's
    /// statistics, so the view can be reproduced with `render` and compared.
    pub(super) fn view_state_json(&self) -> Result<String> {
        let scene = self.current_scene();
        let v3 = |v: Vec3| [v.x, v.y, v.z];
        let light_json = |l: &Light, scattering: f32| match l {
            Light::Directional { direction, color, intensity } => serde_json::json!({
                "kind": "directional", "direction": v3(*direction), "color": v3(*color), "intensity": intensity,
                "scattering": scattering,
            }),
            Light::Spot {
                position,
                direction,
                outer_angle_degrees,
                inner_angle_degrees,
                color,
                intensity,
                texture,
            } => {
                serde_json::json!({
                    "kind": "spot", "position": v3(*position), "direction": v3(*direction),
                    "outer_angle_degrees": outer_angle_degrees, "inner_angle_degrees": inner_angle_degrees,
                    "color": v3(*color), "intensity": intensity, "textured": texture.is_some(),
                    "scattering": scattering,
                })
            }
            Light::Point { position, color, intensity } => serde_json::json!({
                "kind": "point", "position": v3(*position), "color": v3(*color), "intensity": intensity,
                "scattering": scattering,
            }),
        };
        let lights: Vec<serde_json::Value> = scene.lights.iter().map(|l| light_json(&l.light, l.scattering)).collect();
        let light = lights[self.controls.selected.min(lights.len() - 1)].clone();
        let state = serde_json::json!({
            "scene": scene.name,
            "technique": self.technique.name(),
            "preset": self.preset.map(|p| p.name()),
            "settings": settings_fields(&self.technique),
            "size": [scene.render.width, scene.render.height],
            "camera": scene.camera,
            "light": light,
            "lights": lights,
            "selected_light": self.controls.selected,
            "medium": scene.medium,
            "exposure": scene.render.exposure,
            "stats": self.last_stats,
            "temporal": self.temporal.as_ref().map(|t| t.settings()),
            "adapter": self.gpu.describe(),
        });
        Ok(serde_json::to_string_pretty(&state)?)
    }

    pub(super) fn save_screenshot(&self, path: &std::path::Path) -> Result<()> {
        let (w, h, rgb) = self.read_display()?;
        output::write_png_rgb8(path, w, h, &rgb)
    }

    /// The current frame's in-scattering and final radiance, read back (for the CPU-side views).
    pub(super) fn read_frame(&self) -> Result<(Image, Image, Vec<f32>)> {
        let (tex, desc) = self.last_host.as_ref().context("nothing rendered yet")?;
        let t = self.targets.as_ref().context("nothing rendered yet")?;
        let inscatter = self.gpu.read_image(if self.temporal.is_some() { &t.resolved } else { &t.inscatter })?;
        let surface = self.gpu.read_image(&tex.surface)?;
        let depth = self.gpu.read_texture_f32(&tex.depth, 0)?;
        let tr = surface_transmittance(desc, &depth);
        let fin = composite(&surface, &inscatter, &tr);
        Ok((inscatter, fin, depth))
    }

    pub(super) fn show_image(&mut self, title: String, caption: String, w: u32, h: u32, rgb: &[u8]) {
        let img = egui::ColorImage::from_rgb([w as usize, h as usize], rgb);
        let texture = self.egui_ctx.load_texture(&title, img, egui::TextureOptions::LINEAR);
        self.shown.retain(|s| s.title != title);
        self.shown.push(Shown { title, caption, texture, open: true });
    }
}
