//! The viewer's camera and light controls: an orbit/fly camera and a movable light, driven by
//! egui's mouse and keyboard input (`Controls::input`), kept apart from the window and the GPU
//! so that tests can drive them with synthetic events.

use super::*;
use crepuscular_scene::SceneLight;

/// Orbit camera about `target`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Orbit {
    pub(crate) target: Vec3,
    pub(crate) yaw: f32,
    pub(crate) pitch: f32,
    pub(crate) distance: f32,
}

impl Orbit {
    pub(crate) fn from_camera(c: &crepuscular::Camera) -> Self {
        let off = c.position - c.look_at;
        let distance = off.length().max(1e-3);
        Self { target: c.look_at, yaw: off.x.atan2(off.z), pitch: (off.y / distance).clamp(-1.0, 1.0).asin(), distance }
    }
    pub(crate) fn position(&self) -> Vec3 {
        let (sy, cy) = self.yaw.sin_cos();
        let (sp, cp) = self.pitch.sin_cos();
        self.target + self.distance * Vec3::new(cp * sy, sp, cp * cy)
    }
    pub(crate) fn forward(&self) -> Vec3 {
        (self.target - self.position()).normalize()
    }
    pub(crate) fn right(&self) -> Vec3 {
        self.forward().cross(Vec3::Y).normalize_or_zero()
    }
}

/// Rotates a direction by `yaw` about +Y and by `pitch` about its horizontal perpendicular,
/// keeping it off the vertical.
pub(crate) fn rotate_direction(d: Vec3, yaw: f32, pitch: f32) -> Vec3 {
    let d = Quat::from_rotation_y(yaw) * d.normalize();
    let axis = Vec3::Y.cross(d).normalize_or_zero();
    if axis == Vec3::ZERO {
        return d;
    }
    let e = Quat::from_axis_angle(axis, pitch) * d;
    if e.y.abs() > 0.995 { d } else { e.normalize() }
}

/// The camera and light as the user steers them with the mouse and keyboard.
#[derive(Clone, Debug)]
pub(crate) struct Controls {
    /// The camera.
    pub(crate) orbit: Orbit,
    /// The lights (direction, position, aim, scattering), at least one.
    pub(crate) lights: Vec<SceneLight>,
    /// The light the mouse steers and the panel edits (an index into `lights`).
    pub(crate) selected: usize,
    /// Ignore the wheel until egui's smooth scrolling has run out, so that the rest of a wheel
    /// turn does not move a camera just reset or loaded.
    pub(crate) settle_scroll: bool,
}

/// What one frame's input did.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub(crate) struct InputOutcome {
    /// The camera or the light moved: re-render.
    pub(crate) changed: bool,
    /// A fly key is held: keep redrawing while it is.
    pub(crate) keys_down: bool,
    /// F12 or P was pressed.
    pub(crate) screenshot: bool,
    /// N / shift+N: open the next / previous built-in scene (+1 / −1).
    pub(crate) cycle_scene: i32,
    /// T / shift+T: switch to the next / previous GPU technique (+1 / −1).
    pub(crate) cycle_technique: i32,
}

impl Controls {
    /// The camera and light of `scene`.
    pub(crate) fn of(scene: &Scene) -> Self {
        Self {
            orbit: Orbit::from_camera(&scene.camera),
            lights: scene.lights.clone(),
            selected: 0,
            settle_scroll: true,
        }
    }

    /// The selected light.
    #[cfg(test)]
    pub(crate) fn light(&self) -> &Light {
        &self.lights[self.selected.min(self.lights.len() - 1)].light
    }

    /// The selected light, to edit.
    pub(crate) fn light_mut(&mut self) -> &mut Light {
        let i = self.selected.min(self.lights.len() - 1);
        &mut self.lights[i].light
    }

    /// Adds `light` (scattering as it shines) and selects it; refused (false) at
    /// [`crepuscular::MAX_LIGHTS`].
    pub(crate) fn add_light(&mut self, light: Light) -> bool {
        if self.lights.len() >= crepuscular::MAX_LIGHTS {
            return false;
        }
        self.lights.push(SceneLight::new(light));
        self.selected = self.lights.len() - 1;
        true
    }

    /// Removes the selected light; refused (false) for the last one (a frame needs a light).
    pub(crate) fn remove_light(&mut self) -> bool {
        if self.lights.len() <= 1 {
            return false;
        }
        self.lights.remove(self.selected.min(self.lights.len() - 1));
        self.selected = self.selected.min(self.lights.len() - 1);
        true
    }

    /// Reads one frame's pointer and keyboard input over `rect` (the scene area, behind the
    /// panels): left drag orbits, shift/middle drag pans, the wheel dollies, W A S D Q E fly
    /// (shift: 4× faster), right or ctrl drag moves the light ([`Controls::drag_light`]),
    /// F12 or P asks for a screenshot, N / T (shift: backwards) cycle the built-in scenes and
    /// the techniques. Keys are ignored while a text field has focus.
    pub(crate) fn input(&mut self, ui: &mut egui::Ui, rect: egui::Rect, dt: f32) -> InputOutcome {
        let resp = ui.interact(rect, egui::Id::new("scene view"), egui::Sense::click_and_drag());
        let (modifiers, scroll) = ui.input(|i| (i.modifiers, i.smooth_scroll_delta.y));
        let d = resp.drag_delta();
        let mut out = InputOutcome::default();
        if d != egui::Vec2::ZERO {
            let pan = resp.dragged_by(egui::PointerButton::Middle)
                || (resp.dragged_by(egui::PointerButton::Primary) && modifiers.shift);
            let light = resp.dragged_by(egui::PointerButton::Secondary)
                || (resp.dragged_by(egui::PointerButton::Primary) && modifiers.ctrl);
            if light {
                self.drag_light(d, modifiers.shift);
            } else if pan {
                let s = self.orbit.distance * 0.0015;
                let right = self.orbit.right();
                let up = right.cross(self.orbit.forward());
                self.orbit.target += (-d.x * right + d.y * up) * s;
            } else if resp.dragged_by(egui::PointerButton::Primary) {
                self.orbit.yaw -= d.x * 0.008;
                self.orbit.pitch = (self.orbit.pitch + d.y * 0.008).clamp(-1.5, 1.5);
            }
            out.changed = true;
        }
        if scroll == 0.0 {
            self.settle_scroll = false;
        }
        if resp.hovered() && scroll != 0.0 && !self.settle_scroll {
            self.orbit.distance = (self.orbit.distance * (-scroll * 0.002).exp()).clamp(0.05, 5000.0);
            out.changed = true;
        }
        if !ctx_wants_keyboard(ui) {
            let (fwd, right) = (self.orbit.forward(), self.orbit.right());
            let mut m = Vec3::ZERO;
            ui.input(|i| {
                use egui::Key;
                for (k, v) in [
                    (Key::W, fwd),
                    (Key::S, -fwd),
                    (Key::D, right),
                    (Key::A, -right),
                    (Key::E, Vec3::Y),
                    (Key::Q, -Vec3::Y),
                ] {
                    if i.key_down(k) {
                        m += v;
                    }
                }
                if i.key_pressed(Key::F12) || i.key_pressed(Key::P) {
                    out.screenshot = true;
                }
                let step = if modifiers.shift { -1 } else { 1 };
                if i.key_pressed(Key::N) {
                    out.cycle_scene = step;
                }
                if i.key_pressed(Key::T) {
                    out.cycle_technique = step;
                }
            });
            if m != Vec3::ZERO {
                let speed = self.orbit.distance.max(1.0) * 0.6 * if modifiers.shift { 4.0 } else { 1.0 };
                self.orbit.target += m.normalize() * speed * dt;
                out.keys_down = true;
                out.changed = true;
            }
        }
        out
    }

    /// Right drag: rotates a sun's direction or a spot's aim; with shift (or for a point
    /// light) moves a spot's or point light's position in the view plane.
    pub(crate) fn drag_light(&mut self, d: egui::Vec2, shift: bool) {
        let (yaw, pitch) = (-d.x * 0.005, d.y * 0.005);
        let right = self.orbit.right();
        let up = right.cross(self.orbit.forward());
        let mv = |p: &mut Vec3, dist: f32| *p += (d.x * right - d.y * up) * dist.max(0.5) * 0.002;
        let eye = self.orbit.position();
        match self.light_mut() {
            Light::Directional { direction, .. } => *direction = rotate_direction(*direction, yaw, pitch),
            Light::Spot { direction, position, .. } => {
                if shift {
                    let dist = (*position - eye).length();
                    mv(position, dist);
                } else {
                    *direction = rotate_direction(*direction, yaw, pitch);
                }
            }
            Light::Point { position, .. } => {
                let dist = (*position - eye).length();
                mv(position, dist);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Feeds `frames` of synthetic egui input (what egui-winit makes of the window's mouse and
    /// keyboard events) to [`Controls::input`] over a 320×180 scene area, 1/30 s apart, as the
    /// viewer does every frame; `focus_text` puts a focused text field in the same UI.
    fn drive(controls: &mut Controls, frames: Vec<Vec<egui::Event>>, focus_text: bool) -> Vec<InputOutcome> {
        let ctx = egui::Context::default();
        let dt = 1.0 / 30.0;
        let mut outs = Vec::new();
        // The modifiers held: those of the last button press, until its release (egui 0.35 reads
        // them from the raw input, as egui-winit fills it, not from an event).
        let mut held = egui::Modifiers::default();
        for (i, events) in frames.into_iter().enumerate() {
            let mut modifiers = held;
            for e in &events {
                if let egui::Event::PointerButton { pressed, modifiers: m, .. } = e {
                    modifiers = *m;
                    held = if *pressed { *m } else { egui::Modifiers::default() };
                }
            }
            let raw = egui::RawInput {
                screen_rect: Some(egui::Rect::from_min_size(egui::Pos2::ZERO, egui::vec2(320.0, 180.0))),
                time: Some(i as f64 * dt as f64),
                events,
                modifiers,
                ..Default::default()
            };
            let mut out = InputOutcome::default();
            let _ = ctx.run_ui(raw, |ui| {
                if focus_text {
                    let mut text = String::new();
                    let r = ui.text_edit_singleline(&mut text);
                    r.request_focus();
                }
                out = controls.input(ui, ui.ctx().content_rect(), dt);
            });
            outs.push(out);
        }
        outs
    }

    fn controls(light: Light) -> Controls {
        let camera =
            crepuscular::Camera { position: Vec3::new(0.0, 2.0, 10.0), look_at: Vec3::ZERO, ..Default::default() };
        Controls { orbit: Orbit::from_camera(&camera), lights: vec![light.into()], selected: 0, settle_scroll: false }
    }

    fn sun() -> Light {
        crepuscular_scene::builtin::builtin("colonnade").unwrap().lights[0].light.clone()
    }

    /// A press at `from`, moves in `steps` equal steps to `to`, a release: one event per frame.
    fn drag(
        button: egui::PointerButton,
        modifiers: egui::Modifiers,
        from: egui::Pos2,
        to: egui::Pos2,
    ) -> Vec<Vec<egui::Event>> {
        let mut frames = vec![
            vec![egui::Event::PointerMoved(from)],
            vec![egui::Event::PointerButton { pos: from, button, pressed: true, modifiers }],
        ];
        for k in 1..=8 {
            frames.push(vec![egui::Event::PointerMoved(from + (to - from) * (k as f32 / 8.0))]);
        }
        frames.push(vec![egui::Event::PointerButton { pos: to, button, pressed: false, modifiers }]);
        frames
    }

    /// A wheel turn of `dy` points (positive: away from the user).
    fn wheel(dy: f32) -> egui::Event {
        egui::Event::MouseWheel {
            unit: egui::MouseWheelUnit::Point,
            delta: egui::vec2(0.0, dy),
            phase: egui::TouchPhase::Move,
            modifiers: Default::default(),
        }
    }

    fn key(key: egui::Key, pressed: bool) -> egui::Event {
        egui::Event::Key { key, physical_key: Some(key), pressed, repeat: false, modifiers: Default::default() }
    }

    fn close(a: Vec3, b: Vec3) -> bool {
        (a - b).length() < 1e-4
    }

    #[test]
    fn left_drag_orbits_the_camera_about_its_target() {
        let mut c = controls(sun());
        let before = c.clone();
        let outs = drive(
            &mut c,
            drag(egui::PointerButton::Primary, Default::default(), egui::pos2(100.0, 90.0), egui::pos2(160.0, 90.0)),
            false,
        );
        assert!(outs.iter().any(|o| o.changed));
        // 60 points to the right turns the camera by −0.008 rad per point (egui's drag
        // threshold may swallow the first few points).
        let turned = before.orbit.yaw - c.orbit.yaw;
        assert!((0.3..=0.481).contains(&turned), "yaw turned by {turned}");
        assert_eq!(c.orbit.pitch, before.orbit.pitch);
        assert!(close(c.orbit.target, before.orbit.target) && c.orbit.distance == before.orbit.distance);
        assert!(!close(c.orbit.position(), before.orbit.position()));
        assert_eq!(c.light(), before.light(), "orbiting must not move the light");
        // Dragging up tilts it.
        let mut c = controls(sun());
        drive(
            &mut c,
            drag(egui::PointerButton::Primary, Default::default(), egui::pos2(100.0, 120.0), egui::pos2(100.0, 60.0)),
            false,
        );
        assert!(c.orbit.pitch < before.orbit.pitch, "pitch {} → {}", before.orbit.pitch, c.orbit.pitch);
    }

    #[test]
    fn shift_or_middle_drag_pans_without_turning() {
        for (button, modifiers) in [
            (egui::PointerButton::Primary, egui::Modifiers::SHIFT),
            (egui::PointerButton::Middle, egui::Modifiers::NONE),
        ] {
            let mut c = controls(sun());
            let before = c.clone();
            drive(&mut c, drag(button, modifiers, egui::pos2(100.0, 90.0), egui::pos2(160.0, 90.0)), false);
            assert_eq!(
                (c.orbit.yaw, c.orbit.pitch, c.orbit.distance),
                (before.orbit.yaw, before.orbit.pitch, before.orbit.distance)
            );
            let moved = c.orbit.target - before.orbit.target;
            // Dragging the scene right moves the camera left.
            assert!(moved.dot(before.orbit.right()) < -0.1, "{button:?}: target moved by {moved}");
            assert!(moved.y.abs() < 1e-4, "{button:?}: a horizontal drag moved the target vertically: {moved}");
        }
    }

    #[test]
    fn right_or_ctrl_drag_turns_the_sun_and_leaves_the_camera() {
        for (button, modifiers) in [
            (egui::PointerButton::Secondary, egui::Modifiers::NONE),
            (egui::PointerButton::Primary, egui::Modifiers::CTRL),
        ] {
            let mut c = controls(sun());
            let before = c.clone();
            drive(&mut c, drag(button, modifiers, egui::pos2(100.0, 90.0), egui::pos2(160.0, 60.0)), false);
            assert_eq!(c.orbit, before.orbit, "{button:?}: the camera moved");
            let (Light::Directional { direction: d0, .. }, Light::Directional { direction: d1, .. }) =
                (before.light(), c.light())
            else {
                unreachable!("colonnade has a sun")
            };
            assert!((d1.length() - 1.0).abs() < 1e-4);
            assert!(d0.dot(*d1) < 0.99, "{button:?}: the sun did not turn: {d0} → {d1}");
        }
    }

    #[test]
    fn right_drag_aims_a_spot_and_shift_right_drag_moves_it() {
        let spot = crepuscular_scene::builtin::builtin("stained-glass").unwrap().lights[0].light.clone();
        let parts = |l: &Light| match l {
            Light::Spot { position, direction, .. } => (*position, *direction),
            _ => unreachable!("stained-glass has a spot light"),
        };
        let mut c = controls(spot.clone());
        drive(
            &mut c,
            drag(egui::PointerButton::Secondary, Default::default(), egui::pos2(100.0, 90.0), egui::pos2(160.0, 90.0)),
            false,
        );
        let ((p0, d0), (p1, d1)) = (parts(&spot), parts(c.light()));
        assert!(close(p0, p1) && d0.dot(d1) < 0.99, "aim: {p0} {d0} → {p1} {d1}");
        let mut c = controls(spot.clone());
        drive(
            &mut c,
            drag(
                egui::PointerButton::Secondary,
                egui::Modifiers::SHIFT,
                egui::pos2(100.0, 90.0),
                egui::pos2(160.0, 90.0),
            ),
            false,
        );
        let (p1, d1) = parts(c.light());
        assert!(close(d0, d1) && (p1 - p0).dot(c.orbit.right()) > 0.05, "move: {p0} {d0} → {p1} {d1}");
        // A point light has no aim: a right drag moves it.
        let point = crepuscular_scene::builtin::builtin("cage").unwrap().lights[0].light.clone();
        let mut c = controls(point.clone());
        drive(
            &mut c,
            drag(egui::PointerButton::Secondary, Default::default(), egui::pos2(100.0, 90.0), egui::pos2(100.0, 40.0)),
            false,
        );
        let (Light::Point { position: a, .. }, Light::Point { position: b, .. }) = (&point, c.light()) else {
            unreachable!("cage has a point light")
        };
        assert!((b - a).y > 0.05, "dragging up moves a point light up: {a} → {b}");
    }

    #[test]
    fn the_wheel_dollies_towards_the_target() {
        let mut c = controls(sun());
        let before = c.clone();
        let mut frames = vec![vec![egui::Event::PointerMoved(egui::pos2(160.0, 90.0)), wheel(120.0)]];
        frames.extend((0..30).map(|_| vec![]));
        drive(&mut c, frames, false);
        assert!(c.orbit.distance < before.orbit.distance * 0.95, "{} → {}", before.orbit.distance, c.orbit.distance);
        assert!(close(c.orbit.target, before.orbit.target) && c.orbit.yaw == before.orbit.yaw);
    }

    #[test]
    fn the_rest_of_a_wheel_turn_does_not_move_a_camera_just_reset() {
        let mut c = controls(sun());
        c.settle_scroll = true; // as Controls::of leaves it
        let before = c.orbit;
        let mut frames = vec![vec![egui::Event::PointerMoved(egui::pos2(160.0, 90.0)), wheel(120.0)]];
        frames.extend((0..30).map(|_| vec![]));
        drive(&mut c, frames.clone(), false);
        assert_eq!(c.orbit, before, "a smooth-scroll tail moved the camera");
        // Once it has run out, the wheel works again.
        drive(&mut c, frames, false);
        assert!(c.orbit.distance < before.distance * 0.95);
    }

    #[test]
    fn wasd_flies_and_f12_asks_for_a_screenshot_unless_a_text_field_has_focus() {
        let mut c = controls(sun());
        let before = c.clone();
        let outs = drive(
            &mut c,
            vec![
                vec![key(egui::Key::W, true)],
                vec![],
                vec![],
                vec![key(egui::Key::W, false)],
                vec![key(egui::Key::F12, true)],
            ],
            false,
        );
        assert!(outs[..3].iter().all(|o| o.keys_down && o.changed), "{outs:?}");
        assert!(!outs[4].keys_down && outs[4].screenshot, "{outs:?}");
        let moved = c.orbit.target - before.orbit.target;
        // 3 frames of 1/30 s at 0.6 × distance per second, along the view direction.
        let expected = 3.0 / 30.0 * 0.6 * before.orbit.distance;
        assert!((moved.length() - expected).abs() < 1e-3 * expected, "moved {moved}, expected {expected}");
        assert!(moved.normalize().dot(before.orbit.forward()) > 0.9999);
        assert_eq!(c.orbit.distance, before.orbit.distance);
        // Q lowers, E raises.
        let mut c = controls(sun());
        drive(&mut c, vec![vec![key(egui::Key::Q, true)], vec![key(egui::Key::Q, false)]], false);
        assert!(c.orbit.target.y < before.orbit.target.y);
        // Typing into a settings field does not fly the camera or take screenshots.
        let mut c = controls(sun());
        let outs = drive(&mut c, vec![vec![], vec![key(egui::Key::W, true)], vec![key(egui::Key::P, true)]], true);
        assert_eq!(c.orbit, before.orbit);
        assert!(outs.iter().all(|o| !o.screenshot && !o.keys_down), "{outs:?}");
    }

    #[test]
    fn rotating_a_direction_keeps_it_unit_and_off_vertical() {
        let d = rotate_direction(Vec3::new(1.0, -0.2, 0.0), 0.3, 2.0);
        assert!((d.length() - 1.0).abs() < 1e-4 && d.y.abs() <= 0.995);
    }

    #[test]
    fn lights_are_added_selected_steered_and_removed() {
        let mut c = Controls::of(&crepuscular_scene::builtin::builtin("atrium").unwrap());
        assert_eq!((c.lights.len(), c.selected), (3, 0));
        // A right drag steers the selected light only: select the second (a spot) and drag.
        c.selected = 1;
        let before = c.clone();
        c.drag_light(egui::vec2(40.0, 0.0), false);
        assert_eq!(c.lights[0], before.lights[0], "the sun must not move");
        assert_eq!(c.lights[2], before.lights[2], "the other spot must not move");
        assert_ne!(c.lights[1], before.lights[1], "the selected spot must turn");
        // Adding selects the new light; removing drops the selected one; the last one stays.
        assert!(c.add_light(Light::Point { position: Vec3::Y, color: Vec3::ONE, intensity: 10.0 }));
        assert_eq!((c.lights.len(), c.selected), (4, 3));
        assert!(matches!(c.light(), Light::Point { .. }));
        c.selected = 0;
        assert!(c.remove_light());
        assert_eq!(c.lights.len(), 3);
        assert!(matches!(c.lights[0].light, Light::Spot { .. }), "the sun was removed");
        while c.lights.len() > 1 {
            assert!(c.remove_light());
        }
        assert!(!c.remove_light(), "a frame keeps at least one light");
        assert_eq!(c.lights.len(), 1);
        while c.lights.len() < crepuscular::MAX_LIGHTS {
            assert!(c.add_light(Light::Point { position: Vec3::Y, color: Vec3::ONE, intensity: 1.0 }));
        }
        assert!(!c.add_light(Light::Point { position: Vec3::Y, color: Vec3::ONE, intensity: 1.0 }));
    }
}
