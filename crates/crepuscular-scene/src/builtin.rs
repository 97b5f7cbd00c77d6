//! Built-in procedural scenes. Each is deterministic (a seeded hash generator, no external
//! randomness), renders at 960 × 540 with a 2048² shadow map by default, and is lit and fogged
//! so that a tone-mapped image at exposure 1 is well exposed: surfaces around 0.05–1 in
//! radiance, shafts clearly visible without washing the image out. The cameras look towards
//! the light, which is partly hidden, because that is where single scattering shows best
//! (forward-scattering Henyey–Greenstein phase functions, g = 0.3–0.55).
//!
//! | name | light | scale | what it shows |
//! | --- | --- | --- | --- |
//! | `colonnade` | directional, sun 14° high | 30 m hall | shafts between nine columns into a roofed hall, towards the camera |
//! | `forest` | directional, sun 23° high | 45 × 40 m | 56 trees, 13 440 leaves (26 880 triangles): a complex shadow map, shafts through a canopy |
//! | `stained-glass` | spot with a projected 256² texture | 12 × 8 × 16 m room | a coloured slab of light through a window into a dusty room |
//! | `cage` | point (cube shadow map) | 3.2 m lantern | beams radiating out of a lattice lantern onto the ground and a wall |
//! | `terrain` | directional, sun 10° high | 180 × 180 m, 128² grid | shafts fanning from behind a peak of a notched ridge |
//! | `night-street` | six street lamps (spots), a lantern (point) and a moon: eight lights | 12 × 70 m street | cones of lamplight and moonlit shafts through the alleys in haze |
//! | `atrium` | a sun through five skylights and two spots | 20 × 12 × 10 m hall | daylight shafts from the roof crossed by two stage spots on a statue |

use crate::mesh::{self, Transform};
use crate::scene::{Geometry, RenderSettings, Scene, Vertex};
use crepuscular::{Camera, Light, Medium, Phase, RgbTexture, ShadowSettings};
use glam::Vec3;
use std::sync::Arc;

/// The scene rendered when none is named.
pub const DEFAULT_SCENE: &str = "colonnade";

const SCENES: &[(&str, &str)] = &[
    (
        "colonnade",
        "a roofed hall behind a row of columns in low sun; shafts stream between the columns towards the camera",
    ),
    ("forest", "trunks under a canopy of thousands of leaves, low sun through the gaps; a complex shadow map"),
    ("stained-glass", "a dusty room lit by a spot light through a window with a projected stained-glass texture"),
    ("cage", "a point light inside a lattice lantern, beams radiating outward (cube shadow map)"),
    ("terrain", "a procedural 128×128 heightfield; low sun behind a notched ridge, shafts fanning from a peak"),
    (
        "night-street",
        "a street at night in haze: six street lamps (spots), a lantern (point), a low moon through the alleys",
    ),
    ("atrium", "a hall by day: sun shafts through five skylights, two stage spots crossing them on a statue"),
];

/// Names and one-line descriptions of the built-in scenes, in a stable order.
pub fn builtin_names() -> &'static [(&'static str, &'static str)] {
    SCENES
}

/// The built-in scenes with exactly one light, in [`builtin_names`]' order (the per-technique
/// quality tests' scenes; the several-light ones have tests of their own).
pub fn one_light_names() -> Vec<&'static str> {
    SCENES.iter().map(|(n, _)| *n).filter(|n| builtin(n).is_some_and(|s| s.lights.len() == 1)).collect()
}

/// Builds the built-in scene `name`, or `None` if there is no such scene.
pub fn builtin(name: &str) -> Option<Scene> {
    let desc = SCENES.iter().find(|(n, _)| *n == name)?.1;
    let mut scene = match name {
        "colonnade" => colonnade(),
        "forest" => forest(),
        "stained-glass" => stained_glass(),
        "cage" => cage(),
        "terrain" => terrain(),
        "night-street" => night_street(),
        "atrium" => atrium(),
        _ => return None,
    };
    scene.name = name.to_string();
    scene.description = desc.to_string();
    Some(scene)
}

// ---------------------------------------------------------------------------------------------
// Helpers.

/// A small deterministic generator (SplitMix64).
struct Rng(u64);

impl Rng {
    fn new(seed: u64) -> Self {
        Self(seed)
    }
    fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        hash64(self.0)
    }
    /// Uniform in [0, 1).
    fn f32(&mut self) -> f32 {
        (self.next_u64() >> 40) as f32 / (1u64 << 24) as f32
    }
    /// Uniform in [lo, hi).
    fn range(&mut self, lo: f32, hi: f32) -> f32 {
        lo + (hi - lo) * self.f32()
    }
    /// Uniform in the unit ball.
    fn in_ball(&mut self) -> Vec3 {
        loop {
            let p = Vec3::new(self.range(-1.0, 1.0), self.range(-1.0, 1.0), self.range(-1.0, 1.0));
            if p.length_squared() <= 1.0 {
                return p;
            }
        }
    }
    /// Uniform on the unit sphere.
    fn on_sphere(&mut self) -> Vec3 {
        loop {
            let p = self.in_ball();
            let l = p.length();
            if l > 1e-3 {
                return p / l;
            }
        }
    }
}

fn hash64(mut z: u64) -> u64 {
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// Hash of an integer lattice point to [0, 1).
fn lattice(seed: u64, i: i32, j: i32) -> f32 {
    let h = hash64(seed ^ hash64((i as u32 as u64) << 32 | j as u32 as u64));
    (h >> 40) as f32 / (1u64 << 24) as f32
}

/// Smooth 2D value noise in [0, 1).
fn value_noise(seed: u64, x: f32, y: f32) -> f32 {
    let (xi, yi) = (x.floor(), y.floor());
    let (fx, fy) = (x - xi, y - yi);
    let s = |t: f32| t * t * t * (t * (t * 6.0 - 15.0) + 10.0);
    let (u, v) = (s(fx), s(fy));
    let (i, j) = (xi as i32, yi as i32);
    let a = lattice(seed, i, j);
    let b = lattice(seed, i + 1, j);
    let c = lattice(seed, i, j + 1);
    let d = lattice(seed, i + 1, j + 1);
    let top = a + (b - a) * u;
    let bottom = c + (d - c) * u;
    top + (bottom - top) * v
}

/// Fractal sum of `octaves` value-noise octaves, roughly in [0, 1).
fn fbm(seed: u64, x: f32, y: f32, octaves: u32) -> f32 {
    let (mut sum, mut amp, mut freq, mut norm) = (0.0, 0.5, 1.0, 0.0);
    for o in 0..octaves {
        sum += amp * value_noise(seed.wrapping_add(o as u64 * 7919), x * freq, y * freq);
        norm += amp;
        amp *= 0.5;
        freq *= 2.03;
    }
    sum / norm
}

fn render(shadow_bias: f32, ambient: Vec3) -> RenderSettings {
    RenderSettings {
        width: 960,
        height: 540,
        shadow: ShadowSettings { size: 2048, bias: shadow_bias, ..ShadowSettings::default() },
        ambient,
        exposure: 1.0,
        ..RenderSettings::default()
    }
}

fn boxed(g: &mut Geometry, center: Vec3, size: Vec3, albedo: Vec3) {
    g.append(&mesh::cuboid(&Transform::at_scaled(center, size), albedo));
}

fn boxed_rot(g: &mut Geometry, center: Vec3, size: Vec3, rot: Vec3, albedo: Vec3) {
    g.append(&mesh::cuboid(&Transform::at_scaled(center, size).rotated(rot), albedo));
}

fn ground(g: &mut Geometry, size: f32, albedo: Vec3) {
    g.append(&mesh::plane(&Transform::at_scaled(Vec3::ZERO, Vec3::new(size, 1.0, size)), albedo));
}

// ---------------------------------------------------------------------------------------------
// Scenes.

/// A stoa: a hall whose front is a row of nine columns under an architrave, closed by a roof,
/// side walls and a back wall. The camera stands inside looking out through the colonnade at a
/// low sun just beside a column; shafts stream between the columns into the shadowed hall
/// towards the camera, and the columns' shadows stripe the floor and the fog. Outside, a row
/// of broken columns and a few fallen blocks.
fn colonnade() -> Scene {
    let mut g = Geometry::default();
    let stone = Vec3::new(0.66, 0.6, 0.52);
    let dark_stone = Vec3::new(0.5, 0.46, 0.4);
    ground(&mut g, 200.0, Vec3::new(0.5, 0.45, 0.38));
    // Hall: x in [-hx, hx], z in [0, depth]; floor at `top`.
    let (hx, depth) = (14.5f32, 13.0f32);
    let top = 0.7;
    boxed(&mut g, Vec3::new(0.0, 0.2, depth * 0.5 - 0.6), Vec3::new(2.0 * hx + 2.0, 0.4, depth + 3.2), dark_stone);
    boxed(&mut g, Vec3::new(0.0, 0.55, depth * 0.5 - 0.3), Vec3::new(2.0 * hx + 1.0, 0.3, depth + 2.0), stone);
    let column_h = 7.5;
    for i in 0..9 {
        let x = -12.0 + 3.0 * i as f32;
        boxed(&mut g, Vec3::new(x, top + 0.15, 0.0), Vec3::new(1.3, 0.3, 1.3), stone);
        g.append(&mesh::cylinder(
            &Transform::at_scaled(Vec3::new(x, top + 0.3 + column_h * 0.5, 0.0), Vec3::new(1.0, column_h, 1.0)),
            stone,
        ));
        boxed(&mut g, Vec3::new(x, top + 0.3 + column_h + 0.2, 0.0), Vec3::new(1.35, 0.4, 1.35), stone);
    }
    let beam_y = top + 0.3 + column_h + 0.4; // 8.9: underside of the architrave
    boxed(&mut g, Vec3::new(0.0, beam_y + 0.5, 0.0), Vec3::new(2.0 * hx + 1.0, 1.0, 1.6), stone);
    boxed(&mut g, Vec3::new(0.0, beam_y + 1.2, 0.0), Vec3::new(2.0 * hx + 2.0, 0.4, 2.2), dark_stone);
    // Roof over the hall, side walls and back wall.
    let roof_y = beam_y + 1.0;
    boxed(&mut g, Vec3::new(0.0, roof_y + 0.3, depth * 0.5), Vec3::new(2.0 * hx + 2.0, 0.6, depth + 1.0), dark_stone);
    for s in [-1.0f32, 1.0] {
        boxed(&mut g, Vec3::new(s * hx, (top + roof_y) * 0.5, depth * 0.5), Vec3::new(0.8, roof_y - top, depth), stone);
    }
    boxed(&mut g, Vec3::new(0.0, (top + roof_y) * 0.5, depth), Vec3::new(2.0 * hx, roof_y - top, 0.8), stone);
    // Broken columns outside.
    let mut rng = Rng::new(0xC010_77AD);
    for i in 0..8 {
        let x = -13.5 + 3.8 * i as f32 + rng.range(-0.4, 0.4);
        let h = rng.range(1.5, 6.5);
        g.append(&mesh::cylinder(
            &Transform::at_scaled(Vec3::new(x, h * 0.5, -12.0), Vec3::new(0.9, h, 0.9)),
            dark_stone,
        ));
    }
    // Fallen drums and blocks inside and outside.
    g.append(&mesh::cylinder(
        &Transform::at_scaled(Vec3::new(-5.0, top + 0.5, 6.0), Vec3::new(1.0, 1.8, 1.0))
            .rotated(Vec3::new(0.0, 35.0, 90.0)),
        stone,
    ));
    boxed_rot(&mut g, Vec3::new(5.5, top + 0.45, 4.0), Vec3::new(1.6, 0.9, 1.1), Vec3::new(0.0, 22.0, 0.0), dark_stone);
    boxed_rot(&mut g, Vec3::new(-7.0, 0.45, -6.0), Vec3::new(1.4, 0.9, 1.0), Vec3::new(0.0, -15.0, 0.0), stone);

    Scene {
        name: String::new(),
        description: String::new(),
        camera: Camera {
            position: Vec3::new(7.0, 2.2, 9.5),
            look_at: Vec3::new(-3.0, 4.6, 0.0),
            up: Vec3::Y,
            fov_y_degrees: 60.0,
            near: 0.1,
            far: 200.0,
        },
        medium: Medium {
            scattering: Vec3::splat(0.03),
            absorption: Vec3::splat(0.015),
            phase: Phase::HenyeyGreenstein { g: 0.5 },
        },
        // Sun outside the colonnade, about 16° high and a little to the left, behind a column
        // as seen from the camera: travelling towards +z (the camera), down and to the right.
        lights: vec![
            Light::Directional {
                direction: Vec3::new(0.505, -0.244, 0.827).normalize(),
                color: Vec3::new(1.0, 0.86, 0.66),
                intensity: 4.0,
            }
            .into(),
        ],
        geometry: g,
        render: render(0.03, Vec3::new(0.025, 0.03, 0.04)),
    }
}

/// Number of trees in `forest`.
const FOREST_TREES_X: usize = 8;
const FOREST_TREES_Z: usize = 7;
const LEAVES_PER_TREE: usize = 240;

/// Trunks on a jittered grid, each under an ellipsoidal canopy of randomly oriented leaf quads.
fn forest() -> Scene {
    let mut g = Geometry::default();
    let mut rng = Rng::new(0xF0E5_7001);
    ground(&mut g, 160.0, Vec3::new(0.24, 0.27, 0.14));
    let bark = Vec3::new(0.28, 0.2, 0.14);
    let camera = Vec3::new(0.0, 1.7, 16.0);
    let cell = 5.6;
    for iz in 0..FOREST_TREES_Z {
        for ix in 0..FOREST_TREES_X {
            let x = -22.0 + cell * (ix as f32 + rng.range(0.15, 0.85));
            let z = -30.0 + cell * (iz as f32 + rng.range(0.15, 0.85));
            let p = Vec3::new(x, 0.0, z);
            // Keep a clearing around the camera.
            let too_close = (p - Vec3::new(camera.x, 0.0, camera.z)).length() < 4.0;
            let h = rng.range(7.0, 11.0);
            let r = rng.range(0.18, 0.34);
            let lean = Vec3::new(rng.range(-3.0, 3.0), rng.range(0.0, 360.0), rng.range(-3.0, 3.0));
            let crown = Vec3::new(x, h - rng.range(0.5, 1.5), z);
            let radii = Vec3::new(rng.range(2.3, 3.3), rng.range(1.6, 2.4), rng.range(2.3, 3.3));
            if too_close {
                continue;
            }
            g.append(&mesh::cylinder_segments(
                &Transform::at_scaled(Vec3::new(x, h * 0.5, z), Vec3::new(2.0 * r, h, 2.0 * r)).rotated(lean),
                bark,
                10,
            ));
            // A few branches towards the crown.
            for _ in 0..3 {
                let dir = Vec3::new(rng.range(-1.0, 1.0), rng.range(0.6, 1.2), rng.range(-1.0, 1.0)).normalize();
                let start = Vec3::new(x, h * rng.range(0.45, 0.65), z);
                let len = rng.range(1.8, 2.8);
                let mid = start + dir * (len * 0.5);
                // Cylinder axis is +Y: tilt it towards `dir`.
                let yaw = dir.x.atan2(dir.z).to_degrees();
                let pitch = dir.y.acos().to_degrees();
                g.append(&mesh::cylinder_segments(
                    &Transform::at_scaled(mid, Vec3::new(0.14, len, 0.14)).rotated(Vec3::new(pitch, yaw, 0.0)),
                    bark,
                    6,
                ));
            }
            let tint = rng.range(0.8, 1.2);
            for _ in 0..LEAVES_PER_TREE {
                let c = crown + rng.in_ball() * radii;
                let n = rng.on_sphere();
                let t = n.any_orthonormal_vector();
                let b = n.cross(t);
                let s = rng.range(0.16, 0.28);
                let spin = rng.range(0.0, std::f32::consts::TAU);
                let (u, v) = (t * spin.cos() + b * spin.sin(), b * spin.cos() - t * spin.sin());
                let albedo = Vec3::new(0.16, 0.3, 0.07) * tint * rng.range(0.8, 1.2);
                g.append(&mesh::quad(
                    [c - u * s - v * s, c + u * s - v * s, c + u * s + v * s, c - u * s + v * s],
                    albedo,
                ));
            }
        }
    }
    // A few fallen logs and rocks on the floor.
    for _ in 0..10 {
        let p = Vec3::new(rng.range(-20.0, 20.0), 0.0, rng.range(-28.0, 10.0));
        if (p - Vec3::new(camera.x, 0.0, camera.z)).length() < 4.0 {
            continue;
        }
        let s = rng.range(0.5, 1.2);
        g.append(&mesh::sphere_segments(
            &Transform::at_scaled(p + Vec3::Y * 0.15 * s, Vec3::new(1.4 * s, 0.8 * s, 1.1 * s)).rotated(Vec3::new(
                0.0,
                rng.range(0.0, 180.0),
                0.0,
            )),
            Vec3::new(0.35, 0.34, 0.3),
            12,
            8,
        ));
    }

    Scene {
        name: String::new(),
        description: String::new(),
        camera: Camera {
            position: camera,
            look_at: Vec3::new(-2.5, 5.0, -10.0),
            up: Vec3::Y,
            fov_y_degrees: 60.0,
            near: 0.1,
            far: 150.0,
        },
        medium: Medium {
            scattering: Vec3::new(0.045, 0.05, 0.055),
            absorption: Vec3::splat(0.01),
            phase: Phase::HenyeyGreenstein { g: 0.55 },
        },
        lights: vec![
            Light::Directional {
                direction: Vec3::new(0.3, -0.45, 1.0).normalize(),
                color: Vec3::new(1.0, 0.9, 0.72),
                intensity: 4.0,
            }
            .into(),
        ],
        geometry: g,
        render: render(0.04, Vec3::new(0.025, 0.03, 0.025)),
    }
}

/// Side of the generated stained-glass texture, texels.
pub const STAINED_GLASS_TEXTURE_SIZE: u32 = 256;

/// The procedural stained-glass texture of the `stained-glass` scene: a rose window of coloured
/// panes in rings and sectors inside a square grid of panes, with dark lead lines, linear RGB.
pub fn stained_glass_texture(size: u32) -> RgbTexture {
    let size = size.max(8);
    let palette: [Vec3; 7] = [
        Vec3::new(0.85, 0.06, 0.04), // ruby
        Vec3::new(0.06, 0.16, 0.9),  // cobalt
        Vec3::new(0.08, 0.7, 0.14),  // emerald
        Vec3::new(1.0, 0.58, 0.06),  // amber
        Vec3::new(0.5, 0.08, 0.8),   // violet
        Vec3::new(0.92, 0.9, 0.75),  // clear
        Vec3::new(1.0, 0.85, 0.2),   // gold
    ];
    let lead = Vec3::splat(0.015);
    let line = 1.3 / size as f32; // half-width of a lead line in uv
    let rings = [0.0f32, 0.1, 0.25, 0.4, 0.47];
    let sectors = [1u32, 8, 12, 24];
    let mut texels = Vec::with_capacity((size * size) as usize);
    for j in 0..size {
        for i in 0..size {
            let u = (i as f32 + 0.5) / size as f32;
            let v = (j as f32 + 0.5) / size as f32;
            let (dx, dy) = (u - 0.5, v - 0.5);
            let r = (dx * dx + dy * dy).sqrt();
            let (cell, edge): (u64, f32) = if r < rings[4] {
                let k = rings.windows(2).position(|w| r >= w[0] && r < w[1]).unwrap_or(0);
                let n = sectors[k];
                let a = dy.atan2(dx) + std::f32::consts::PI; // [0, 2π]
                let sector_w = std::f32::consts::TAU / n as f32;
                // Alternate rings are offset by half a sector.
                let a = a + if k % 2 == 1 { 0.5 * sector_w } else { 0.0 };
                let s = ((a / sector_w).floor() as i64).rem_euclid(n as i64) as u64;
                let frac = (a / sector_w).fract();
                let ang_edge = if n > 1 { frac.min(1.0 - frac) * sector_w * r } else { f32::MAX };
                let ring_edge = (r - rings[k]).abs().min((rings[k + 1] - r).abs());
                // Symmetric colours: sector s and its mirror share a colour.
                let sym = s.min((n as u64 - s) % n as u64);
                (k as u64 * 64 + sym, ang_edge.min(ring_edge))
            } else {
                let n = 6.0;
                let (gx, gy) = (u * n, v * n);
                let (fx, fy) = (gx.fract(), gy.fract());
                let e = fx.min(1.0 - fx).min(fy.min(1.0 - fy)) / n;
                let (cx, cy) = (gx.floor() as i64, gy.floor() as i64);
                // Mirror-symmetric colours.
                let (sx, sy) = (cx.min(5 - cx), cy.min(5 - cy));
                (1000 + (sx * 7 + sy) as u64, e)
            };
            let border = u.min(1.0 - u).min(v.min(1.0 - v));
            let c = if edge < line || border < 2.0 * line {
                lead
            } else {
                let h = hash64(cell.wrapping_mul(0x2545_F491_4F6C_DD1D) ^ 0x57A1);
                let base = palette[(h % palette.len() as u64) as usize];
                // A little mottling inside each pane.
                let m = 0.85 + 0.15 * value_noise(cell, u * 40.0, v * 40.0);
                base * m
            };
            texels.push([c.x, c.y, c.z, 1.0]);
        }
    }
    RgbTexture { width: size, height: size, texels }
}

/// A closed room 12 × 8 × 16 m with a window (with a mullion and a transom) in its left wall.
/// A spot light outside shines through the window, projecting a stained-glass texture into
/// the dusty air and onto the floor; pews and a plinth with a sphere stand in the room.
fn stained_glass() -> Scene {
    let mut g = Geometry::default();
    let wall = Vec3::new(0.6, 0.57, 0.52);
    let floor = Vec3::new(0.45, 0.42, 0.38);
    let wood = Vec3::new(0.32, 0.2, 0.12);
    let (hx, hy, hz, t) = (6.0f32, 8.0f32, 8.0f32, 0.4f32);
    // Floor and ceiling.
    boxed(&mut g, Vec3::new(0.0, -t * 0.5, 0.0), Vec3::new(2.0 * hx + 2.0 * t, t, 2.0 * hz + 2.0 * t), floor);
    boxed(&mut g, Vec3::new(0.0, hy + t * 0.5, 0.0), Vec3::new(2.0 * hx + 2.0 * t, t, 2.0 * hz + 2.0 * t), wall);
    // Right, back, front walls.
    boxed(&mut g, Vec3::new(hx + t * 0.5, hy * 0.5, 0.0), Vec3::new(t, hy, 2.0 * hz + 2.0 * t), wall);
    boxed(&mut g, Vec3::new(0.0, hy * 0.5, -hz - t * 0.5), Vec3::new(2.0 * hx, hy, t), wall);
    boxed(&mut g, Vec3::new(0.0, hy * 0.5, hz + t * 0.5), Vec3::new(2.0 * hx, hy, t), wall);
    // Left wall with a window: y in [w0, w1], z in [-wz, wz].
    let (w0, w1, wz) = (3.0f32, 7.5f32, 1.75f32);
    let x = -hx - t * 0.5;
    let full_z = 2.0 * hz + 2.0 * t;
    boxed(&mut g, Vec3::new(x, w0 * 0.5, 0.0), Vec3::new(t, w0, full_z), wall);
    boxed(&mut g, Vec3::new(x, (w1 + hy) * 0.5, 0.0), Vec3::new(t, hy - w1, full_z), wall);
    let side = hz + t - wz;
    for s in [-1.0f32, 1.0] {
        boxed(&mut g, Vec3::new(x, (w0 + w1) * 0.5, s * (wz + side * 0.5)), Vec3::new(t, w1 - w0, side), wall);
    }
    // Mullion and transom.
    boxed(&mut g, Vec3::new(x, (w0 + w1) * 0.5, 0.0), Vec3::new(t * 0.6, w1 - w0, 0.1), wall * 0.6);
    boxed(&mut g, Vec3::new(x, w0 + 0.62 * (w1 - w0), 0.0), Vec3::new(t * 0.6, 0.1, 2.0 * wz), wall * 0.6);
    // Pews on the right half, facing -z.
    for i in 0..3 {
        let z = -6.5 + 2.0 * i as f32;
        boxed(&mut g, Vec3::new(3.0, 0.45, z), Vec3::new(4.0, 0.1, 0.6), wood);
        boxed(&mut g, Vec3::new(3.0, 0.8, z + 0.3), Vec3::new(4.0, 0.8, 0.08), wood);
        for sx in [1.1f32, 4.9] {
            boxed(&mut g, Vec3::new(sx, 0.45, z), Vec3::new(0.08, 0.9, 0.6), wood);
        }
    }
    // Plinth with a sphere near the back.
    boxed(&mut g, Vec3::new(-2.0, 0.6, -4.5), Vec3::new(1.0, 1.2, 1.0), wall);
    g.append(&mesh::sphere(
        &Transform::at_scaled(Vec3::new(-2.0, 1.7, -4.5), Vec3::splat(1.0)),
        Vec3::new(0.7, 0.7, 0.68),
    ));

    // High outside the window: a steep, flat slab of light lands on the floor at x ≈ -5..-1.
    let position = Vec3::new(-9.0, 12.0, 0.0);
    let target = Vec3::new(0.0, 0.0, 0.0);
    Scene {
        name: String::new(),
        description: String::new(),
        camera: Camera {
            position: Vec3::new(4.0, 1.5, 5.0),
            look_at: Vec3::new(-4.0, 4.2, -0.5),
            up: Vec3::Y,
            fov_y_degrees: 65.0,
            near: 0.05,
            far: 60.0,
        },
        medium: Medium {
            scattering: Vec3::splat(0.06),
            absorption: Vec3::splat(0.005),
            phase: Phase::HenyeyGreenstein { g: 0.5 },
        },
        lights: vec![
            Light::Spot {
                position,
                direction: (target - position).normalize(),
                outer_angle_degrees: 16.0,
                inner_angle_degrees: 13.0,
                color: Vec3::new(1.0, 0.95, 0.88),
                intensity: 8000.0,
                texture: Some(Arc::new(stained_glass_texture(STAINED_GLASS_TEXTURE_SIZE))),
            }
            .into(),
        ],
        geometry: g,
        render: render(0.02, Vec3::new(0.12, 0.12, 0.13)),
    }
}

/// A lantern: a lattice cage of square bars on a pedestal with a point light inside; pillars
/// and a back wall around it catch the beams.
fn cage() -> Scene {
    let mut g = Geometry::default();
    ground(&mut g, 100.0, Vec3::new(0.45, 0.43, 0.4));
    let iron = Vec3::new(0.2, 0.19, 0.18);
    let stone = Vec3::new(0.55, 0.52, 0.48);
    // Pedestal.
    boxed(&mut g, Vec3::new(0.0, 0.5, 0.0), Vec3::new(3.8, 1.0, 3.8), stone);
    // Cage: x, z in [-h, h], y in [y0, y0 + 2h].
    let h = 1.6f32;
    let y0 = 1.0f32;
    let yc = y0 + h;
    let n = 7; // bars per direction per face
    let bar = 0.16f32;
    let depth = 0.1f32;
    let pos = |k: usize| -h + 2.0 * h * k as f32 / (n - 1) as f32;
    for k in 0..n {
        let s = pos(k);
        for side in [-1.0f32, 1.0] {
            // Faces x = ±h: vertical bars (along y) at z = s, horizontal bars (along z) at y = yc + s.
            boxed(&mut g, Vec3::new(side * h, yc, s), Vec3::new(depth, 2.0 * h, bar), iron);
            boxed(&mut g, Vec3::new(side * h, yc + s, 0.0), Vec3::new(depth, bar, 2.0 * h), iron);
            // Faces z = ±h.
            boxed(&mut g, Vec3::new(s, yc, side * h), Vec3::new(bar, 2.0 * h, depth), iron);
            boxed(&mut g, Vec3::new(0.0, yc + s, side * h), Vec3::new(2.0 * h, bar, depth), iron);
        }
        // Top face y = y0 + 2h.
        boxed(&mut g, Vec3::new(s, y0 + 2.0 * h, 0.0), Vec3::new(bar, depth, 2.0 * h), iron);
        boxed(&mut g, Vec3::new(0.0, y0 + 2.0 * h, s), Vec3::new(2.0 * h, depth, bar), iron);
    }
    // Finials on the top corners.
    for sx in [-1.0f32, 1.0] {
        for sz in [-1.0f32, 1.0] {
            g.append(&mesh::sphere_segments(
                &Transform::at_scaled(Vec3::new(sx * h, y0 + 2.0 * h + 0.12, sz * h), Vec3::splat(0.3)),
                iron,
                12,
                8,
            ));
        }
    }
    // Pillars on a circle and a back wall.
    for i in 0..6 {
        let a = std::f32::consts::TAU * (i as f32 + 0.5) / 6.0;
        let p = Vec3::new(8.0 * a.cos(), 3.0, 8.0 * a.sin() - 1.0);
        if p.z > 4.0 {
            continue; // keep the view open
        }
        g.append(&mesh::cylinder(&Transform::at_scaled(p, Vec3::new(0.9, 6.0, 0.9)), stone));
    }
    boxed(&mut g, Vec3::new(0.0, 5.0, -12.0), Vec3::new(40.0, 10.0, 0.6), stone);

    Scene {
        name: String::new(),
        description: String::new(),
        camera: Camera {
            position: Vec3::new(7.3, 3.0, 10.0),
            look_at: Vec3::new(-0.3, 2.6, 0.0),
            up: Vec3::Y,
            fov_y_degrees: 60.0,
            near: 0.1,
            far: 120.0,
        },
        medium: Medium {
            scattering: Vec3::splat(0.08),
            absorption: Vec3::splat(0.01),
            phase: Phase::HenyeyGreenstein { g: 0.3 },
        },
        lights: vec![
            Light::Point {
                position: Vec3::new(0.12, yc + 0.2, -0.1),
                color: Vec3::new(1.0, 0.78, 0.5),
                intensity: 80.0,
            }
            .into(),
        ],
        geometry: g,
        render: render(0.02, Vec3::new(0.02, 0.022, 0.03)),
    }
}

/// Vertices per side of the `terrain` heightfield.
const TERRAIN_N: usize = 128;

/// Height of the `terrain` heightfield at (x, z), metres.
fn terrain_height(x: f32, z: f32) -> f32 {
    // Rolling hills.
    let hills = 10.0 * fbm(0x7E44, x / 34.0, z / 34.0, 5) - 4.0;
    // A ridge across the view, with peaks and notches.
    let zr = -45.0 + 7.0 * (x / 23.0).sin() + 4.0 * (x / 9.0).cos();
    let across = (z - zr) / 11.0;
    let ridged = 1.0 - (2.0 * fbm(0x41D6, x / 16.0, 0.37, 4) - 1.0).abs();
    let ridge = 24.0 * (-across * across).exp() * (0.35 + 0.65 * ridged * ridged);
    // Lower ground near the camera.
    let valley = 4.0 * (-((z - 40.0) / 25.0).powi(2)).exp() * (-(x / 30.0).powi(2)).exp();
    hills + ridge - valley
}

/// A 128 × 128 heightfield, 180 × 180 m, with smooth normals: rolling hills and a notched
/// ridge with the low sun just behind one of its peaks.
fn terrain() -> Scene {
    let n = TERRAIN_N;
    let (x0, x1, z0, z1) = (-90.0f32, 90.0f32, -125.0f32, 55.0f32);
    let step = Vec3::new((x1 - x0) / (n - 1) as f32, 0.0, (z1 - z0) / (n - 1) as f32);
    let mut g = Geometry { vertices: Vec::with_capacity(n * n), indices: Vec::with_capacity((n - 1) * (n - 1) * 6) };
    let grass = Vec3::new(0.22, 0.26, 0.12);
    let rock = Vec3::new(0.42, 0.38, 0.33);
    for j in 0..n {
        for i in 0..n {
            let x = x0 + step.x * i as f32;
            let z = z0 + step.z * j as f32;
            let y = terrain_height(x, z);
            let e = 0.5;
            let dx = (terrain_height(x + e, z) - terrain_height(x - e, z)) / (2.0 * e);
            let dz = (terrain_height(x, z + e) - terrain_height(x, z - e)) / (2.0 * e);
            let normal = Vec3::new(-dx, 1.0, -dz).normalize();
            let rockiness = ((1.0 - normal.y) * 4.0 + (y - 10.0) / 15.0).clamp(0.0, 1.0);
            let albedo = grass.lerp(rock, rockiness);
            g.vertices.push(Vertex { position: [x, y, z], normal: normal.to_array(), albedo: albedo.to_array() });
        }
    }
    for j in 0..n - 1 {
        for i in 0..n - 1 {
            let a = (j * n + i) as u32;
            let b = a + 1;
            let c = a + n as u32;
            let d = c + 1;
            // Counter-clockwise seen from above (+Y).
            g.indices.extend_from_slice(&[a, c, b, b, c, d]);
        }
    }
    let eye = Vec3::new(0.0, terrain_height(0.0, 45.0).max(0.0) + 8.0, 45.0);
    Scene {
        name: String::new(),
        description: String::new(),
        camera: Camera {
            position: eye,
            look_at: Vec3::new(-10.0, 6.0, -40.0),
            up: Vec3::Y,
            fov_y_degrees: 55.0,
            near: 0.2,
            far: 400.0,
        },
        medium: Medium {
            scattering: Vec3::new(0.008, 0.009, 0.011),
            absorption: Vec3::splat(0.004),
            phase: Phase::HenyeyGreenstein { g: 0.5 },
        },
        lights: vec![
            Light::Directional {
                direction: Vec3::new(0.5, -0.2, 1.0).normalize(),
                color: Vec3::new(1.0, 0.76, 0.52),
                intensity: 4.5,
            }
            .into(),
        ],
        geometry: g,
        render: render(0.15, Vec3::new(0.05, 0.055, 0.07)),
    }
}

/// A street between two rows of houses with alleys between them, at night in haze: six street
/// lamps (spots on posts, aimed down and inwards) light cones on the cobbles, a lantern (a
/// point light) hangs under an awning on the right, and a low moon behind the left row sends
/// shafts through the alleys across the street. Eight lights, thirteen shadow-map layers of
/// 1024². The lights are in the order `bench --preset lights` adds them (`night-street:lights=N`):
/// the four nearest lamps, the lantern, the moon, the two far lamps.
fn night_street() -> Scene {
    let mut g = Geometry::default();
    ground(&mut g, 160.0, Vec3::new(0.32, 0.3, 0.28));
    let wall = Vec3::new(0.5, 0.46, 0.42);
    let dark = Vec3::new(0.3, 0.28, 0.27);
    let iron = Vec3::new(0.12, 0.12, 0.13);
    let mut rng = Rng::new(0x5EE7_11A7);
    // Houses: blocks 6–9 m long with 1.6 m alleys, 7–13 m high, both sides of a 12 m street.
    for side in [-1.0f32, 1.0] {
        let mut z = 12.0f32;
        while z > -70.0 {
            let len = rng.range(6.0, 9.0);
            let h = rng.range(7.0, 13.0);
            let c = Vec3::new(side * 11.0, h * 0.5, z - len * 0.5);
            boxed(&mut g, c, Vec3::new(10.0, h, len), if rng.f32() < 0.5 { wall } else { dark });
            // A cornice and a doorstep on the street face.
            boxed(&mut g, Vec3::new(side * 5.8, h - 0.4, z - len * 0.5), Vec3::new(0.5, 0.3, len), dark);
            boxed(&mut g, Vec3::new(side * 5.8, 0.1, z - len * 0.5), Vec3::new(0.6, 0.2, 1.4), dark);
            z -= len + 1.6;
        }
    }
    // Street lamps: posts with an arm and a head; the spot hangs just under the head.
    let mut lights = Vec::new();
    for (i, z) in [-6.0f32, -15.0, -24.0, -33.0, -42.0, -51.0].into_iter().enumerate() {
        let side = if i % 2 == 0 { 1.0f32 } else { -1.0 };
        let x = side * 4.6;
        g.append(&mesh::cylinder(&Transform::at_scaled(Vec3::new(x, 2.6, z), Vec3::new(0.16, 5.2, 0.16)), iron));
        boxed(&mut g, Vec3::new(x - side * 0.45, 5.2, z), Vec3::new(0.9, 0.08, 0.08), iron);
        boxed(&mut g, Vec3::new(x - side * 0.9, 5.15, z), Vec3::new(0.5, 0.18, 0.5), iron);
        lights.push(crate::scene::SceneLight::new(Light::Spot {
            position: Vec3::new(x - side * 0.9, 4.98, z),
            direction: Vec3::new(-side * 0.35, -1.0, 0.1).normalize(),
            outer_angle_degrees: 38.0,
            inner_angle_degrees: 28.0,
            color: Vec3::new(1.0, 0.74, 0.45),
            intensity: 140.0,
            texture: None,
        }));
    }
    let far_lamps = lights.split_off(4);
    // The lantern under an awning by a door on the right.
    boxed(&mut g, Vec3::new(5.3, 3.3, -11.5), Vec3::new(1.4, 0.1, 2.4), dark);
    boxed(&mut g, Vec3::new(5.3, 3.05, -11.5), Vec3::new(0.04, 0.4, 0.04), iron);
    lights.push(crate::scene::SceneLight::new(Light::Point {
        position: Vec3::new(5.3, 2.7, -11.5),
        color: Vec3::new(1.0, 0.58, 0.3),
        intensity: 30.0,
    }));
    // Things in the street: a cart, barrels, benches.
    boxed_rot(&mut g, Vec3::new(-2.5, 0.7, -21.0), Vec3::new(1.6, 1.0, 3.0), Vec3::new(0.0, 12.0, 0.0), dark);
    for k in 0..5 {
        let p = Vec3::new(3.6 + 0.5 * (k % 2) as f32, 0.5, -31.0 - 1.1 * k as f32);
        g.append(&mesh::cylinder(&Transform::at_scaled(p, Vec3::new(0.8, 1.0, 0.8)), wall));
    }
    for z in [-3.0f32, -24.0] {
        boxed(&mut g, Vec3::new(-4.8, 0.45, z), Vec3::new(0.5, 0.1, 2.0), dark);
    }
    // The moon, low behind the left row, travelling towards the camera and across the street.
    lights.push(crate::scene::SceneLight::new(Light::Directional {
        direction: Vec3::new(0.62, -0.3, 0.72).normalize(),
        color: Vec3::new(0.55, 0.66, 1.0),
        intensity: 1.2,
    }));
    lights.extend(far_lamps);
    let mut r = render(0.03, Vec3::new(0.006, 0.008, 0.014));
    r.shadow.size = 1024;
    r.exposure = 1.8;
    Scene {
        name: String::new(),
        description: String::new(),
        camera: Camera {
            position: Vec3::new(0.6, 1.7, 8.0),
            look_at: Vec3::new(-0.8, 3.6, -30.0),
            up: Vec3::Y,
            fov_y_degrees: 60.0,
            near: 0.1,
            far: 150.0,
        },
        medium: Medium {
            scattering: Vec3::new(0.045, 0.05, 0.055),
            absorption: Vec3::splat(0.01),
            phase: Phase::HenyeyGreenstein { g: 0.35 },
        },
        lights,
        geometry: g,
        render: r,
    }
}

/// A hall by day: the sun shines through five skylight slits in the roof, slanting shafts
/// towards the camera, and two stage spots high on the side walls cross them on a statue in
/// the middle. Three lights.
fn atrium() -> Scene {
    let mut g = Geometry::default();
    ground(&mut g, 120.0, Vec3::new(0.5, 0.47, 0.42));
    let stone = Vec3::new(0.62, 0.58, 0.52);
    let dark = Vec3::new(0.42, 0.4, 0.37);
    let (hx, hz, top) = (10.0f32, 8.0f32, 10.0f32);
    // Walls (the front one behind the camera has a door so the hall is not sealed).
    for s in [-1.0f32, 1.0] {
        boxed(&mut g, Vec3::new(s * hx, top * 0.5, 0.0), Vec3::new(0.6, top, 2.0 * hz), stone);
    }
    boxed(&mut g, Vec3::new(0.0, top * 0.5, -hz), Vec3::new(2.0 * hx, top, 0.6), stone);
    boxed(&mut g, Vec3::new(-6.0, top * 0.5, hz), Vec3::new(8.0, top, 0.6), stone);
    boxed(&mut g, Vec3::new(6.0, top * 0.5, hz), Vec3::new(8.0, top, 0.6), stone);
    boxed(&mut g, Vec3::new(0.0, top - 2.0, hz), Vec3::new(4.0, 4.0, 0.6), stone);
    // Roof: planks along x with five 1.2 m slits.
    let mut z = -hz;
    for k in 0..6 {
        let len = if k == 5 { hz - z } else { 1.8 };
        boxed(&mut g, Vec3::new(0.0, top + 0.15, z + len * 0.5), Vec3::new(2.0 * hx + 0.6, 0.3, len), dark);
        z += len + 1.2;
    }
    // A gallery ledge on each side wall, with the spots on it.
    for s in [-1.0f32, 1.0] {
        boxed(&mut g, Vec3::new(s * (hx - 1.0), 6.0, -2.0), Vec3::new(1.6, 0.3, 10.0), dark);
    }
    // The statue: a pedestal and a figure of a cylinder and a sphere; columns round the hall.
    boxed(&mut g, Vec3::new(0.0, 0.6, -2.0), Vec3::new(2.0, 1.2, 2.0), stone);
    g.append(&mesh::cylinder(&Transform::at_scaled(Vec3::new(0.0, 2.3, -2.0), Vec3::new(0.8, 2.2, 0.8)), stone));
    g.append(&mesh::sphere(&Transform::at_scaled(Vec3::new(0.0, 3.8, -2.0), Vec3::splat(0.9)), stone));
    for (x, zc) in [(-6.0f32, -5.0f32), (6.0, -5.0), (-6.0, 2.0), (6.0, 2.0)] {
        g.append(&mesh::cylinder(&Transform::at_scaled(Vec3::new(x, top * 0.5, zc), Vec3::new(0.8, top, 0.8)), stone));
    }
    let target = Vec3::new(0.0, 2.5, -2.0);
    let spot = |p: Vec3| {
        crate::scene::SceneLight::new(Light::Spot {
            position: p,
            direction: (target - p).normalize(),
            outer_angle_degrees: 14.0,
            inner_angle_degrees: 10.0,
            color: Vec3::new(1.0, 0.92, 0.82),
            intensity: 700.0,
            texture: None,
        })
    };
    Scene {
        name: String::new(),
        description: String::new(),
        camera: Camera {
            position: Vec3::new(2.5, 1.7, 7.0),
            look_at: Vec3::new(-0.5, 5.0, -6.0),
            up: Vec3::Y,
            fov_y_degrees: 65.0,
            near: 0.1,
            far: 120.0,
        },
        medium: Medium {
            scattering: Vec3::splat(0.035),
            absorption: Vec3::splat(0.01),
            phase: Phase::HenyeyGreenstein { g: 0.5 },
        },
        lights: vec![
            crate::scene::SceneLight::new(Light::Directional {
                direction: Vec3::new(0.2, -0.72, 0.66).normalize(),
                color: Vec3::new(1.0, 0.9, 0.75),
                intensity: 4.0,
            }),
            spot(Vec3::new(-8.6, 6.6, 1.0)),
            spot(Vec3::new(8.6, 6.6, 1.0)),
        ],
        geometry: g,
        render: render(0.03, Vec3::new(0.03, 0.032, 0.038)),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_builtin_builds() {
        for (name, _) in builtin_names() {
            let s = builtin(name).expect(name);
            assert!(s.geometry.triangle_count() > 0, "{name}");
            assert!(s.geometry.indices.iter().all(|&i| (i as usize) < s.geometry.vertices.len()));
            assert!(s.geometry.vertices.iter().all(|v| v.position.iter().chain(&v.normal).all(|c| c.is_finite())));
        }
        assert!(builtin("nope").is_none());
        assert!(builtin(DEFAULT_SCENE).is_some());
    }

    #[test]
    fn deterministic() {
        let a = builtin("forest").unwrap();
        let b = builtin("forest").unwrap();
        assert_eq!(a.geometry, b.geometry);
    }
}
