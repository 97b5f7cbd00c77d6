//! The viewer's egui panels: the layout (`Viewer::ui`), camera input, the technique, scene,
//! stats and tools panels, and the editors they use (lights, colour, phase).

use super::*;

impl Viewer {
    pub(super) fn ui(&mut self, ui: &mut egui::Ui, dt: f32) {
        let ctx = ui.ctx().clone();
        let rect = ctx.content_rect();
        if let Some(id) = self.display_id {
            ctx.layer_painter(egui::LayerId::background()).image(
                id,
                rect,
                egui::Rect::from_min_max(egui::pos2(0.0, 0.0), egui::pos2(1.0, 1.0)),
                egui::Color32::WHITE,
            );
        }
        self.camera_input(ui, rect, dt);

        // Anchored to the corners, clear of the middle of the picture (where the camera and
        // light are dragged): technique top left, timings bottom left, scene top right.
        let h = rect.height();
        egui::Window::new("technique")
            .anchor(egui::Align2::LEFT_TOP, [8.0, 8.0])
            .max_height((h - 340.0).max(120.0))
            .vscroll(true)
            .show(&ctx, |ui| self.technique_panel(ui));
        egui::Window::new("scene")
            .anchor(egui::Align2::RIGHT_TOP, [-8.0, 8.0])
            .max_height((h - 60.0).max(120.0))
            .vscroll(true)
            .show(&ctx, |ui| {
                self.scene_panel(ui);
                ui.separator();
                self.tools_panel(ui);
            });
        egui::Window::new("timings")
            .anchor(egui::Align2::LEFT_BOTTOM, [8.0, -8.0])
            .default_open(true)
            .show(&ctx, |ui| self.stats_panel(ui));
        for s in &mut self.shown {
            egui::Window::new(&s.title).open(&mut s.open).vscroll(true).show(&ctx, |ui| {
                ui.label(&s.caption);
                let size = s.texture.size_vec2();
                let scale = (480.0 / size.x).min(1.0);
                ui.add(egui::Image::new(egui::load::SizedTexture::new(s.texture.id(), size * scale)));
            });
        }
        self.shown.retain(|s| s.open);
    }

    /// Camera and light input on the scene area; see [`Controls::input`].
    pub(super) fn camera_input(&mut self, ui: &mut egui::Ui, rect: egui::Rect, dt: f32) {
        let o = self.controls.input(ui, rect, dt);
        self.keys_down = o.keys_down;
        if o.screenshot {
            self.pending.push(Action::Screenshot);
        }
        if o.cycle_scene != 0 {
            let names = crepuscular_scene::builtin::builtin_names();
            let at = names.iter().position(|(n, _)| *n == self.scene.name).map_or(0, |k| k as i32 + o.cycle_scene);
            let next = names[at.rem_euclid(names.len() as i32) as usize].0;
            match self.open_scene(next) {
                Ok(()) => self.status = format!("opened {next}"),
                Err(e) => self.status = format!("error: {}", format!("{e:#}").replace('\n', " ")),
            }
        }
        if o.cycle_technique != 0 {
            let gpu: Vec<&str> = crepuscular::techniques::TECHNIQUES.iter().filter(|t| t.gpu).map(|t| t.name).collect();
            let at = gpu.iter().position(|n| *n == self.technique.name()).map_or(0, |k| k as i32 + o.cycle_technique);
            let next = gpu[at.rem_euclid(gpu.len() as i32) as usize];
            let parsed = parse_technique(next, &self.scene, self.preset, &[]);
            self.set_technique(parsed, true);
        }
        if o.changed {
            self.dirty = true;
        }
    }

    pub(super) fn technique_panel(&mut self, ui: &mut egui::Ui) {
        let mut name = self.technique.name();
        ui.horizontal(|ui| {
            ui.label("technique");
            egui::ComboBox::from_id_salt("technique").selected_text(name).show_ui(ui, |ui| {
                for t in crepuscular::techniques::TECHNIQUES.iter().filter(|t| t.gpu) {
                    ui.selectable_value(&mut name, t.name, t.name).on_hover_text(t.summary);
                }
            });
        });
        if name != self.technique.name() {
            let parsed = parse_technique(name, &self.scene, self.preset, &[]);
            self.set_technique(parsed, true);
        }
        let mut preset = self.preset;
        ui.horizontal(|ui| {
            ui.label("preset");
            egui::ComboBox::from_id_salt("preset")
                .selected_text(preset.map(|p| p.name()).unwrap_or("(custom)"))
                .show_ui(ui, |ui| {
                    for p in Preset::ALL {
                        ui.selectable_value(&mut preset, Some(p), p.name());
                    }
                });
        });
        if preset != self.preset
            && let Some(p) = preset
        {
            self.preset = Some(p);
            let mut scene = self.scene.clone();
            scene.render.techniques.remove(self.technique.name());
            let parsed = parse_technique(self.technique.name(), &scene, Some(p), &[]);
            self.set_technique(parsed, true);
        }
        let technique = self.technique.name();
        let mut changed = false;
        egui::Grid::new("settings").num_columns(2).striped(true).show(ui, |ui| {
            let keys: Vec<String> = self.fields.keys().cloned().collect();
            for key in keys {
                let doc = setting_doc(technique, &key);
                let label = ui.label(&key);
                if let Some(doc) = doc {
                    label.on_hover_text(doc);
                }
                let Some(value) = self.fields.get_mut(&key) else { continue };
                let r = match value {
                    serde_json::Value::Bool(b) => Some(ui.checkbox(b, "")),
                    serde_json::Value::Number(n) if n.is_u64() || n.is_i64() => {
                        let mut v = n.as_i64().unwrap_or(0);
                        let r = ui.add(egui::DragValue::new(&mut v).speed(1.0));
                        if r.changed() {
                            *value = serde_json::Value::from(v);
                        }
                        Some(r)
                    }
                    serde_json::Value::Number(n) => {
                        let mut v = n.as_f64().unwrap_or(0.0) as f32 as f64;
                        let speed = (v.abs() * 0.01).max(0.001);
                        let r = ui.add(egui::DragValue::new(&mut v).speed(speed).max_decimals(4));
                        if r.changed() {
                            *value = serde_json::Value::from(v);
                        }
                        Some(r)
                    }
                    serde_json::Value::String(s) => match ENUM_VALUES.iter().find(|(k, _)| *k == key) {
                        Some((_, values)) => {
                            let before = s.clone();
                            egui::ComboBox::from_id_salt(("setting", key.as_str())).selected_text(s.as_str()).show_ui(
                                ui,
                                |ui| {
                                    for v in *values {
                                        ui.selectable_value(s, v.to_string(), *v);
                                    }
                                },
                            );
                            if *s != before {
                                changed = true;
                            }
                            None
                        }
                        None => {
                            let r = ui.text_edit_singleline(s);
                            Some(r)
                        }
                    },
                    _ => {
                        let text = self.text_fields.entry(key.clone()).or_default();
                        let r = ui.add(egui::TextEdit::singleline(text).hint_text("default (TOML value)"));
                        Some(r)
                    }
                };
                if let Some(r) = r {
                    let commit = if matches!(value, serde_json::Value::String(_) | serde_json::Value::Null)
                        || value.is_array()
                        || value.is_object()
                    {
                        r.lost_focus()
                    } else {
                        r.changed()
                    };
                    if commit {
                        changed = true;
                    }
                    if let Some(doc) = doc {
                        r.on_hover_text(doc);
                    }
                }
                ui.end_row();
            }
        });
        if changed {
            self.preset = None;
            self.apply_fields();
        }
        if let Some(e) = &self.settings_error {
            ui.colored_label(egui::Color32::from_rgb(255, 110, 90), format!("settings not applied: {e}"));
        }
        if ui.button("reset to defaults").clicked() {
            let parsed = render::parse_technique(self.technique.name(), &self.scene, &[]);
            self.preset = None;
            self.set_technique(parsed, true);
        }
    }

    pub(super) fn scene_panel(&mut self, ui: &mut egui::Ui) {
        let mut changed = false;
        let mut open: Option<String> = None;
        ui.horizontal(|ui| {
            ui.label(egui::RichText::new("scene").strong());
            egui::ComboBox::from_id_salt("scene").selected_text(self.scene.name.as_str()).show_ui(ui, |ui| {
                for (name, summary) in crepuscular_scene::builtin::builtin_names() {
                    if ui.selectable_label(self.scene.name == *name, *name).on_hover_text(*summary).clicked() {
                        open = Some(name.to_string());
                    }
                }
            });
        });
        ui.horizontal(|ui| {
            let r = ui.add(
                egui::TextEdit::singleline(&mut self.scene_path)
                    .hint_text("scene file (.toml), or drop one on the window")
                    .desired_width(200.0),
            );
            let enter = r.lost_focus() && ui.input(|i| i.key_pressed(egui::Key::Enter));
            if (ui.button("open").clicked() || enter) && !self.scene_path.trim().is_empty() {
                open = Some(self.scene_path.trim().to_string());
            }
        });
        if let Some(path) = ui.input(|i| i.raw.dropped_files.first().and_then(|f| f.path.clone())) {
            self.scene_path = path.display().to_string();
            open = Some(self.scene_path.clone());
        }
        if let Some(spec) = open {
            match self.open_scene(&spec) {
                Ok(()) => self.status = format!("opened {spec}"),
                Err(e) => self.status = format!("error: {}", format!("{e:#}").replace('\n', " ")),
            }
        }
        ui.label(egui::RichText::new("medium").strong());
        let rgb = |ui: &mut egui::Ui, label: &str, v: &mut Vec3, tip: &str| {
            let mut c = false;
            ui.horizontal(|ui| {
                ui.label(label).on_hover_text(tip);
                for x in [&mut v.x, &mut v.y, &mut v.z] {
                    c |= ui.add(egui::DragValue::new(x).speed(0.0005).range(0.0..=10.0).max_decimals(4)).changed();
                }
            });
            c
        };
        changed |= rgb(ui, "σs", &mut self.medium.scattering, "scattering coefficient, 1/m, RGB");
        changed |= rgb(ui, "σa", &mut self.medium.absorption, "absorption coefficient, 1/m, RGB");
        changed |= phase_editor(ui, &mut self.medium.phase);
        ui.label(egui::RichText::new("lights & view").strong());
        changed |= lights_editor(ui, &mut self.controls);
        match self.controls.light_mut() {
            Light::Directional { intensity, direction, color } => {
                ui.label(format!("sun, travelling along ({:.2}, {:.2}, {:.2})", direction.x, direction.y, direction.z));
                ui.horizontal(|ui| {
                    ui.label("intensity").on_hover_text("irradiance scale E of the colour");
                    changed |= ui.add(egui::DragValue::new(intensity).speed(0.05).range(0.0..=1e6)).changed();
                    changed |= color_editor(ui, color);
                });
            }
            Light::Spot { intensity, position, color, outer_angle_degrees, inner_angle_degrees, .. } => {
                ui.label(format!("spot at ({:.2}, {:.2}, {:.2}) m", position.x, position.y, position.z));
                ui.horizontal(|ui| {
                    ui.label("intensity").on_hover_text("intensity I per steradian of the colour");
                    changed |= ui.add(egui::DragValue::new(intensity).speed(1.0).range(0.0..=1e9)).changed();
                    changed |= color_editor(ui, color);
                });
                ui.horizontal(|ui| {
                    ui.label("cone °").on_hover_text("outer half-angle (falls to 0), inner half-angle (full strength)");
                    changed |= ui.add(egui::DragValue::new(outer_angle_degrees).speed(0.2).range(0.5..=89.0)).changed();
                    let outer = *outer_angle_degrees;
                    changed |=
                        ui.add(egui::DragValue::new(inner_angle_degrees).speed(0.2).range(0.0..=outer)).changed();
                    *inner_angle_degrees = inner_angle_degrees.min(outer);
                });
            }
            Light::Point { intensity, position, color } => {
                ui.label(format!("point light at ({:.2}, {:.2}, {:.2}) m", position.x, position.y, position.z));
                ui.horizontal(|ui| {
                    ui.label("intensity").on_hover_text("intensity I per steradian of the colour");
                    changed |= ui.add(egui::DragValue::new(intensity).speed(1.0).range(0.0..=1e9)).changed();
                    changed |= color_editor(ui, color);
                });
            }
        }
        ui.horizontal(|ui| {
            ui.label("exposure");
            changed |= ui.add(egui::DragValue::new(&mut self.exposure).speed(0.01).range(0.0..=100.0)).changed();
            ui.label("scale").on_hover_text("render resolution = window × scale; cost ∝ scale²");
            changed |= ui.add(egui::Slider::new(&mut self.scale, 0.1..=1.0)).changed();
        });
        ui.horizontal(|ui| {
            if ui.button("reset camera & lights").clicked() {
                self.controls = Controls::of(&self.scene);
                self.medium = self.scene.medium.clone();
                changed = true;
            }
            ui.checkbox(&mut self.continuous, "continuous").on_hover_text("re-render every frame (for timing)");
            let filter = &mut self.scene.render.shadow.filter;
            let mut bilinear = *filter == crepuscular::ShadowFilter::Bilinear;
            let tip = "shadow filter of the volume lookups (docs/MODEL.md §1 \"Visibility\"): off, the nearest \
                       texel; on, the 2×2 bilinear percentage-closer filter (4 reads per sample; the reference \
                       and the marches read it; minmax and prefiltered keep their own outside the epipole disc)";
            if ui.checkbox(&mut bilinear, "bilinear shadows").on_hover_text(tip).changed() {
                *filter =
                    if bilinear { crepuscular::ShadowFilter::Bilinear } else { crepuscular::ShadowFilter::Nearest };
                changed = true;
            }
        });
        ui.small("left drag orbit · shift/middle drag pan · wheel dolly · WASD QE fly · right (ctrl) drag the selected light, + shift moves spot/point · F12/P screenshot · N scene · T technique");
        if changed {
            self.dirty = true;
        }
    }

    pub(super) fn stats_panel(&mut self, ui: &mut egui::Ui) {
        if let Some(e) = &self.render_error {
            ui.colored_label(egui::Color32::from_rgb(255, 110, 90), format!("render failed: {e}"));
        }
        let (w, h) = self.render_size();
        if let Some(s) = &self.last_stats {
            ui.label(format!(
                "{w}×{h}: {} ray-marched samples ({:.1} per pixel), GPU memory {:.2} MiB",
                s.raymarched_samples,
                s.raymarched_samples as f64 / (w as f64 * h as f64),
                s.gpu_memory_bytes as f64 / (1024.0 * 1024.0)
            ));
        }
        if let Some(last) = self.history.back() {
            let tech: f64 =
                last.passes.iter().filter(|p| !p.name.starts_with("host") && p.name != "composite").map(|p| p.ms).sum();
            ui.label(format!("frame {:.1} ms (technique {:.1} ms); {}", last.wall_ms, tech, self.gpu.info.name));
            ui.small(format!(
                "technique pipelines built {}× (last {:.0} ms); settings changes reuse them",
                self.runner_builds, self.runner_build_ms
            ));
        }
        // Stacked bars per frame over the last seconds, one colour per pass.
        let width = ui.available_width().clamp(200.0, 420.0);
        let (rect, _) = ui.allocate_exact_size(egui::vec2(width, 70.0), egui::Sense::hover());
        let painter = ui.painter_at(rect);
        painter.rect_filled(rect, 2.0, egui::Color32::from_black_alpha(120));
        let max_ms = self.history.iter().map(|f| f.passes.iter().map(|p| p.ms).sum::<f64>()).fold(1.0, f64::max);
        let n = self.history.len().max(1);
        let bar = (rect.width() / n as f32).min(12.0);
        let mut names: Vec<String> = Vec::new();
        for (i, f) in self.history.iter().enumerate() {
            let x0 = rect.left() + i as f32 * bar;
            let mut y = rect.bottom();
            for p in &f.passes {
                let k = names.iter().position(|n| *n == p.name).unwrap_or_else(|| {
                    names.push(p.name.clone());
                    names.len() - 1
                });
                let hgt = (p.ms / max_ms) as f32 * (rect.height() - 12.0);
                painter.rect_filled(
                    egui::Rect::from_min_max(egui::pos2(x0, y - hgt), egui::pos2(x0 + (bar - 1.0).max(1.0), y)),
                    0.0,
                    pass_color(k),
                );
                y -= hgt;
            }
        }
        painter.text(
            rect.left_top() + egui::vec2(4.0, 2.0),
            egui::Align2::LEFT_TOP,
            format!("per-pass ms, last {HISTORY_S:.0} s (max {max_ms:.1} ms)"),
            egui::FontId::monospace(10.0),
            egui::Color32::WHITE,
        );
        if let Some(last) = self.history.back() {
            // The legend, wrapped: a colour swatch and the pass's last time each.
            ui.horizontal_wrapped(|ui| {
                for p in &last.passes {
                    let k = names.iter().position(|n| *n == p.name).unwrap_or(0);
                    let (r, _) = ui.allocate_exact_size(egui::vec2(10.0, 10.0), egui::Sense::hover());
                    ui.painter().rect_filled(r, 1.0, pass_color(k));
                    ui.small(format!("{} {:.1} ms", p.name, p.ms));
                }
            });
        }
    }

    pub(super) fn tools_panel(&mut self, ui: &mut egui::Ui) {
        ui.horizontal(|ui| {
            if ui.button("screenshot (F12)").clicked() {
                self.pending.push(Action::Screenshot);
            }
            for &view in DebugView::of(&self.technique) {
                if ui.button(view.name()).on_hover_text(view.label()).clicked() {
                    self.pending.push(Action::Debug(view));
                }
            }
        });
        ui.horizontal(|ui| {
            let mut on = self.temporal.is_some();
            let tip = "temporal accumulation (docs/MODEL.md §7): jitter per frame, the history reprojected, \
                       rejected where the surface changed, clipped to the neighbourhood and blended; the view \
                       renders continuously while it is on";
            if ui.checkbox(&mut on, "temporal").on_hover_text(tip).changed() {
                self.temporal = if on {
                    match crepuscular::Temporal::new(&self.gpu.device, crepuscular::TemporalSettings::default()) {
                        Ok(t) => Some(t),
                        Err(e) => {
                            self.status = format!("error: {e}");
                            None
                        }
                    }
                } else {
                    // Back to the technique's own settings (jitter as set): in place, or a
                    // new runner on the next frame, as for any settings change.
                    if !self.runner.as_mut().is_some_and(|r| r.update(&self.technique).unwrap_or(false)) {
                        self.runner = None;
                    }
                    None
                };
                self.dirty = true;
            }
            if self.temporal.is_some()
                && ui
                    .button("history weight")
                    .on_hover_text("the temporal stage's history weight per pixel (black: rejected)")
                    .clicked()
            {
                self.pending.push(Action::HistoryWeight);
            }
        });
        ui.horizontal(|ui| {
            if ui
                .button("error vs reference")
                .on_hover_text("CPU reference on this frame's depth and shadow map; FLIP heat map (slow: seconds)")
                .clicked()
            {
                self.pending.push(Action::ErrorView);
            }
            ui.label("steps");
            ui.add(egui::DragValue::new(&mut self.reference_steps).range(8..=4096))
                .on_hover_text("ray-marching steps of the CPU reference; cost linear");
        });
        if !self.status.is_empty() {
            if self.status.starts_with("error") {
                ui.colored_label(egui::Color32::from_rgb(255, 110, 90), &self.status);
            } else {
                ui.small(&self.status);
            }
        }
    }
}

/// The scene's lights: one button per light selects the one the mouse steers and the panel
/// edits; "+ sun", "+ spot", "+ point" add a light (a local one 3 m above the camera's target,
/// a spot aimed at it), "remove" drops the selected one (not the last), and "scattering" scales
/// the selected light's in-scattering (0 opts it out; it still lights surfaces).
pub(super) fn lights_editor(ui: &mut egui::Ui, controls: &mut Controls) -> bool {
    let mut changed = false;
    ui.horizontal_wrapped(|ui| {
        for i in 0..controls.lights.len() {
            let name = format!("{} {}", i + 1, controls.lights[i].light.kind_name());
            if ui.selectable_label(controls.selected == i, name).clicked() {
                controls.selected = i;
            }
        }
    });
    let target = controls.orbit.target;
    let above = target + Vec3::new(0.0, 3.0, 0.0);
    ui.horizontal(|ui| {
        let full = controls.lights.len() >= crepuscular::MAX_LIGHTS;
        let add = |ui: &mut egui::Ui, label: &str| {
            ui.add_enabled(!full, egui::Button::new(label))
                .on_hover_text(format!("add a light (at most {})", crepuscular::MAX_LIGHTS))
                .clicked()
        };
        if add(ui, "+ sun") {
            changed |= controls.add_light(Light::Directional {
                direction: Vec3::new(0.3, -0.6, -0.75).normalize(),
                color: Vec3::ONE,
                intensity: 2.0,
            });
        }
        if add(ui, "+ spot") {
            changed |= controls.add_light(Light::Spot {
                position: above,
                direction: Vec3::NEG_Y,
                outer_angle_degrees: 25.0,
                inner_angle_degrees: 20.0,
                color: Vec3::ONE,
                intensity: 200.0,
                texture: None,
            });
        }
        if add(ui, "+ point") {
            changed |= controls.add_light(Light::Point { position: above, color: Vec3::ONE, intensity: 100.0 });
        }
        let one = controls.lights.len() <= 1;
        if ui.add_enabled(!one, egui::Button::new("remove")).on_hover_text("remove the selected light").clicked() {
            changed |= controls.remove_light();
        }
    });
    let i = controls.selected.min(controls.lights.len() - 1);
    ui.horizontal(|ui| {
        ui.label("scattering").on_hover_text(
            "scale of this light's in-scattering: 1 as it shines, 0 opts it out of the effect (it still lights surfaces)",
        );
        changed |= ui.add(egui::DragValue::new(&mut controls.lights[i].scattering).speed(0.01).range(0.0..=100.0)).changed();
    });
    changed
}

/// A linear-RGB colour picker; returns whether it changed.
pub(super) fn color_editor(ui: &mut egui::Ui, color: &mut Vec3) -> bool {
    let mut c = color.to_array();
    let changed = egui::color_picker::color_edit_button_rgb(ui, &mut c).on_hover_text("colour, linear RGB").changed();
    if changed {
        *color = Vec3::from_array(c).max(Vec3::ZERO);
    }
    changed
}

/// The phase function's kind (isotropic, Henyey–Greenstein, Rayleigh, Hoffman–Preetham) and
/// its parameters; returns whether it changed. A new kind starts from the scene file's
/// defaults for it, keeping the asymmetry g when both kinds have one.
pub(super) fn phase_editor(ui: &mut egui::Ui, phase: &mut Phase) -> bool {
    const KINDS: [(&str, &str); 4] = [
        ("isotropic", "p = 1/4π"),
        ("henyey-greenstein", "Henyey–Greenstein: one lobe of asymmetry g"),
        ("rayleigh", "Rayleigh: 3/16π (1 + cos²θ), small particles"),
        ("hoffman-preetham", "Hoffman & Preetham 2002: per-channel mix of Rayleigh and a Mie lobe"),
    ];
    let kind = |p: &Phase| match p {
        Phase::Isotropic => KINDS[0].0,
        Phase::HenyeyGreenstein { .. } => KINDS[1].0,
        Phase::Rayleigh => KINDS[2].0,
        Phase::HoffmanPreetham { .. } => KINDS[3].0,
    };
    let mut changed = false;
    let mut picked = kind(phase);
    ui.horizontal(|ui| {
        ui.label("phase").on_hover_text("phase function p(θ), θ = 0 looking into the light");
        egui::ComboBox::from_id_salt("phase").selected_text(picked).show_ui(ui, |ui| {
            for (k, tip) in KINDS {
                ui.selectable_value(&mut picked, k, k).on_hover_text(tip);
            }
        });
    });
    if picked != kind(phase)
        && let Some(p) = phase_of_kind(picked, phase)
    {
        *phase = p;
        changed = true;
    }
    match phase {
        Phase::HenyeyGreenstein { g } | Phase::HoffmanPreetham { g, .. } => {
            ui.horizontal(|ui| {
                ui.label("g").on_hover_text("asymmetry of the (Mie) lobe; > 0 scatters forward");
                changed |= ui.add(egui::Slider::new(g, -0.99..=0.99)).changed();
            });
        }
        Phase::Isotropic | Phase::Rayleigh => {}
    }
    if let Phase::HoffmanPreetham { rayleigh_fraction: f, .. } = phase {
        ui.horizontal(|ui| {
            ui.label("Rayleigh fraction").on_hover_text("share of σs that is Rayleigh, per RGB channel, in [0, 1]");
            for x in [&mut f.x, &mut f.y, &mut f.z] {
                changed |= ui.add(egui::DragValue::new(x).speed(0.005).range(0.0..=1.0).max_decimals(3)).changed();
            }
        });
    }
    changed
}

pub(super) fn ctx_wants_keyboard(ui: &egui::Ui) -> bool {
    ui.ctx().egui_wants_keyboard_input()
}

pub(super) fn pass_color(k: usize) -> egui::Color32 {
    const P: [(u8, u8, u8); 8] = [
        (90, 160, 255),
        (255, 170, 60),
        (110, 210, 120),
        (230, 90, 110),
        (190, 130, 255),
        (240, 230, 90),
        (80, 220, 220),
        (200, 200, 200),
    ];
    let (r, g, b) = P[k % P.len()];
    egui::Color32::from_rgb(r, g, b)
}
