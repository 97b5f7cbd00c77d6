//! TOML scene files.
//!
//! A scene file describes one [`Scene`]: camera, medium, its lights, objects and render
//! settings. Every key is optional unless marked *required*; unknown keys are errors. Numbers
//! may be written as integers or floats. Paths (meshes, textures) are relative to the scene
//! file's directory; absolute paths, `..` components and symbolic links leading out of that
//! directory are rejected. A complete example with every key:
//!
//! ```toml
//! name = "portico"                       # default: the file stem
//! description = "Columns in low sun"     # one line; default ""
//!
//! [camera]
//! position = [0.0, 2.0, 18.0]            # eye, metres; default [0, 1, 5]
//! look_at = [0.0, 5.0, 0.0]              # metres, ≠ position; default [0, 0, 0]
//! up = [0.0, 1.0, 0.0]                   # not parallel to the view direction; default [0, 1, 0]
//! fov_y_degrees = 60.0                   # vertical field of view, degrees, in (0, 180); default 60
//! near = 0.1                             # near plane, metres, > 0; default 0.1
//! far = 200.0                            # far plane, metres, > near; default 200
//!
//! [medium]
//! scattering = [0.04, 0.04, 0.04]        # σs, 1/m, RGB ≥ 0 (one number = grey); default 0.02
//! absorption = 0.005                     # σa, 1/m, RGB ≥ 0 (one number = grey); default 0.005
//! phase = { kind = "henyey-greenstein", g = 0.6 }   # g in (−1, 1); default g = 0.7
//! # phase = { kind = "isotropic" }
//! # phase = { kind = "rayleigh" }
//! # phase = { kind = "hoffman-preetham", g = 0.76, rayleigh_fraction = [0.216, 0.391, 0.612] }
//!
//! [[lights]]                             # one table per light, 1 to 16 of them, any mix of kinds;
//!                                        # or a single [light] table (the same keys) for one light;
//!                                        # neither: one default sun
//! kind = "spot"                          # "directional" | "spot" | "point"; default "directional"
//! position = [-10.0, 9.0, 0.0]           # spot, point: metres (required)
//! direction = [1.0, -0.95, 0.0]          # directional, spot: where the light travels, from the
//!                                        # light into the scene; normalised on load; required
//!                                        # for spot, default [0.2, -0.45, 1.0] for directional
//! outer_angle_degrees = 24.0             # spot: half-angle where the cone reaches 0, (0, 89];
//!                                        # default 30
//! inner_angle_degrees = 19.0             # spot: full-strength half-angle, in [0, outer];
//!                                        # default 0.8 × outer
//! color = [1.0, 0.95, 0.9]               # linear RGB ≥ 0 (one number = grey); default [1, 1, 1]
//! intensity = 3000.0                     # ≥ 0. directional: irradiance scale E (default 1);
//!                                        # spot, point: intensity I per steradian (default 50)
//! texture = "gobo.png"                   # spot only: projected image, PNG (sRGB) or EXR (linear),
//!                                        # at most 8192 × 8192; default none
//! scattering = 1.0                       # scale of this light's in-scattering, ≥ 0: 0 opts it out
//!                                        # of the effect (it still lights surfaces); default 1
//!
//! [[lights]]                             # a second light: a sun
//! kind = "directional"
//! direction = [0.3, -0.4, -1.0]
//! intensity = 2.0
//!
//! # Directional light (a low sun: E ≈ 3–5):
//! #   [[lights]] kind = "directional", direction = [0.0, -0.3, -1.0], intensity = 4.0
//! # Point light (I ≈ target irradiance × distance²):
//! #   [[lights]] kind = "point", position = [0.0, 3.0, 0.0], intensity = 60.0
//!
//! [[objects]]
//! kind = "plane"                         # "plane" | "box" | "sphere" | "cylinder" | "mesh" (required)
//! scale = [60.0, 1.0, 60.0]              # per axis, or one number; non-zero; default 1
//! albedo = [0.6, 0.55, 0.5]              # linear RGB in [0, 1] (one number = grey); default 0.7
//!
//! [[objects]]
//! kind = "mesh"
//! path = "column.obj"                    # mesh only (required): .gltf, .glb or .obj
//! translate = [2.0, 0.0, 0.0]            # metres; default [0, 0, 0]
//! rotate_degrees = [0.0, 45.0, 0.0]      # about X, then Y, then Z, degrees; default [0, 0, 0]
//! scale = 1.5                            # applied first; default 1
//! # no albedo: a mesh takes its material's colour (glTF base colour, OBJ diffuse), else 0.7
//!
//! [render]
//! width = 960                            # pixels, 1 to 16384; default 960
//! height = 540                           # pixels, 1 to 16384; default 540
//! shadow_map_size = 2048                 # texels per side, 1 to 16384; default 2048
//! shadow_bias = 0.02                     # metres along the light's depth axis, ≥ 0; default 0.02
//! shadow_filter = "bilinear"             # volume lookups: "nearest" | "bilinear" (2×2 PCF); default "bilinear"
//! shadow_normal_offset_texels = 1.5      # surface-lookup offset, shadow-map texels, ≥ 0; default 1.5
//! ambient = [0.03, 0.03, 0.03]           # radiance added to surfaces (× albedo), ≥ 0; default 0.03
//! exposure = 1.0                         # multiplier before the tone curve, > 0; default 1
//!
//! [render.brute-force]                   # any other table under [render]: settings of the technique
//! steps = 32                             # of that name, passed on unparsed (read by the technique)
//! ```
//!
//! Primitive shapes before their transform: `plane` is a 1 × 1 square in XZ facing +Y, `box` a
//! unit cube, `sphere` a sphere of radius 0.5, `cylinder` radius 0.5 and height 1 along Y, all
//! centred at the origin (see [`crate::mesh`]).
//!
//! Every error is a [`SceneError`] whose message is one line naming the file, the key and the
//! offending value, e.g.
//! ``scenes/x.toml: medium.scattering[0] = -1: coefficients must be ≥ 0 and finite`` or, for
//! TOML syntax, type and unknown-key errors, with the line and column,
//! ``scenes/x.toml:3:1: medium.scatterin: unknown field `scatterin`, expected one of `scattering`, ...``.

use crate::mesh::{self, Transform};
use crate::scene::SceneLight;
use crate::scene::{Geometry, RenderSettings, Scene};
use crepuscular::{Camera, Light, Medium, Phase, RgbTexture};
use glam::Vec3;
use serde::Deserialize;
use serde::de::{self, Deserializer, MapAccess, SeqAccess, Visitor};
use std::collections::BTreeMap;
use std::fmt;
use std::path::{Component, Path, PathBuf};
use std::sync::Arc;

/// Direction of travel of the default directional light (before normalisation): a low sun
/// ahead of the default camera, which looks down −z, so that shafts come towards it. Used when
/// a file has no `[light]` table or a directional light without `direction`.
pub const DEFAULT_SUN_DIRECTION: [f32; 3] = [0.2, -0.45, 1.0];

/// Largest accepted image width or height (output and shadow map), pixels.
pub const MAX_IMAGE_SIZE: u32 = 16384;
/// Largest accepted spot-light texture width or height, texels.
pub const MAX_TEXTURE_SIZE: u32 = 8192;
/// Largest accepted scene-file size, bytes.
pub const MAX_SCENE_FILE_BYTES: u64 = 16 * 1024 * 1024;

/// An error loading a scene, a mesh or a texture. Its `Display` is always one line naming the
/// file and, where there is one, the key path and the offending value.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum SceneError {
    /// A file could not be read (missing, unreadable, not UTF-8, too large).
    #[error("{file}: {message}")]
    Io {
        /// The file.
        file: String,
        /// What went wrong.
        message: String,
    },
    /// TOML syntax error, wrong type, unknown or missing key. `line` and `column` are 1-based;
    /// 0 when unknown. `key` is the dotted key path (may be empty).
    #[error("{}", syntax_line(.file, *.line, *.column, .key, .message))]
    Syntax {
        /// The scene file.
        file: String,
        /// 1-based line, 0 when unknown.
        line: usize,
        /// 1-based column (characters), 0 when unknown.
        column: usize,
        /// Dotted key path, e.g. `medium.scattering[0]`.
        key: String,
        /// What went wrong.
        message: String,
    },
    /// A value that parsed but is out of range or inconsistent.
    #[error("{file}: {key} = {value}: {message}")]
    Invalid {
        /// The scene file.
        file: String,
        /// Dotted key path, e.g. `medium.scattering[0]`.
        key: String,
        /// The offending value as written (TOML-like).
        value: String,
        /// What is wrong and what is expected.
        message: String,
    },
    /// A mesh file failed to import.
    #[error("{file}: {message}")]
    Mesh {
        /// The mesh file.
        file: String,
        /// What went wrong.
        message: String,
    },
}

fn syntax_line(file: &str, line: usize, column: usize, key: &str, message: &str) -> String {
    let mut s = String::from(file);
    if line > 0 {
        s.push_str(&format!(":{line}:{column}"));
    }
    s.push_str(": ");
    if !key.is_empty() {
        s.push_str(key);
        s.push_str(": ");
    }
    s.push_str(message);
    s
}

/// Collapses whitespace runs containing newlines into single spaces.
fn one_line(s: &str) -> String {
    let mut out = String::with_capacity(s.len());
    let mut pending_space = false;
    for part in s.split(['\n', '\r']) {
        let t = part.trim_end();
        if t.trim().is_empty() {
            continue;
        }
        if pending_space {
            out.push(' ');
            out.push_str(t.trim_start());
        } else {
            out.push_str(t);
        }
        pending_space = true;
    }
    out
}

/// Reads and parses a scene file. Relative paths inside it resolve against its directory.
pub fn load_scene_file(path: &Path) -> Result<Scene, SceneError> {
    let label = path.display().to_string();
    let io = |message: String| SceneError::Io { file: label.clone(), message: one_line(&message) };
    let meta = std::fs::metadata(path).map_err(|e| io(format!("cannot read: {e}")))?;
    if !meta.is_file() {
        return Err(io("not a file".into()));
    }
    if meta.len() > MAX_SCENE_FILE_BYTES {
        return Err(io(format!("{} bytes, more than the limit of {MAX_SCENE_FILE_BYTES}", meta.len())));
    }
    let bytes = std::fs::read(path).map_err(|e| io(format!("cannot read: {e}")))?;
    let text = String::from_utf8(bytes).map_err(|e| io(format!("not UTF-8 text: {e}")))?;
    let base = path.parent().map(Path::to_path_buf).unwrap_or_default();
    parse_scene_str(&text, &label, &base)
}

/// Parses scene-file text. `file_label` names the file in errors (and gives the default scene
/// name: its stem); `base_dir` is where relative mesh and texture paths resolve. Loads the
/// meshes and textures the scene names.
pub fn parse_scene_str(text: &str, file_label: &str, base_dir: &Path) -> Result<Scene, SceneError> {
    let raw = parse_raw(text, file_label)?;
    let ctx = Ctx { file: file_label.to_string(), base_dir: base_dir.to_path_buf() };
    build(&ctx, raw)
}

// ---------------------------------------------------------------------------------------------
// Raw (as written) structures.

/// RGB written as `[r, g, b]` or as one number meaning grey.
#[derive(Clone, Copy, Debug)]
struct Rgb([f32; 3]);

impl<'de> Deserialize<'de> for Rgb {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct V;
        impl<'de> Visitor<'de> for V {
            type Value = Rgb;
            fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
                f.write_str("a number or an array of 3 numbers")
            }
            fn visit_f64<E: de::Error>(self, v: f64) -> Result<Rgb, E> {
                Ok(Rgb([v as f32; 3]))
            }
            fn visit_i64<E: de::Error>(self, v: i64) -> Result<Rgb, E> {
                Ok(Rgb([v as f32; 3]))
            }
            fn visit_u64<E: de::Error>(self, v: u64) -> Result<Rgb, E> {
                Ok(Rgb([v as f32; 3]))
            }
            fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<Rgb, A::Error> {
                let mut out = [0.0f32; 3];
                for (i, o) in out.iter_mut().enumerate() {
                    *o = seq.next_element()?.ok_or_else(|| de::Error::invalid_length(i, &self))?;
                }
                if seq.next_element::<de::IgnoredAny>()?.is_some() {
                    return Err(de::Error::invalid_length(4, &self));
                }
                Ok(Rgb(out))
            }
        }
        d.deserialize_any(V)
    }
}

#[derive(Deserialize, Default)]
#[serde(deny_unknown_fields)]
struct RawScene {
    name: Option<String>,
    description: Option<String>,
    camera: Option<RawCamera>,
    medium: Option<RawMedium>,
    light: Option<RawLight>,
    lights: Option<Vec<RawLight>>,
    #[serde(default)]
    objects: Vec<RawObject>,
    render: Option<RawRender>,
}

#[derive(Deserialize, Default)]
#[serde(deny_unknown_fields)]
struct RawCamera {
    position: Option<[f32; 3]>,
    look_at: Option<[f32; 3]>,
    up: Option<[f32; 3]>,
    fov_y_degrees: Option<f32>,
    near: Option<f32>,
    far: Option<f32>,
}

#[derive(Deserialize, Default)]
#[serde(deny_unknown_fields)]
struct RawMedium {
    scattering: Option<Rgb>,
    absorption: Option<Rgb>,
    phase: Option<RawPhase>,
}

#[derive(Deserialize, Clone, Copy, PartialEq, Debug)]
#[serde(rename_all = "kebab-case")]
enum PhaseKind {
    Isotropic,
    HenyeyGreenstein,
    Rayleigh,
    HoffmanPreetham,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawPhase {
    kind: PhaseKind,
    g: Option<f32>,
    rayleigh_fraction: Option<Rgb>,
}

#[derive(Deserialize, Clone, Copy, PartialEq, Debug, Default)]
#[serde(rename_all = "kebab-case")]
enum LightKind {
    #[default]
    Directional,
    Spot,
    Point,
}

#[derive(Deserialize, Default)]
#[serde(deny_unknown_fields)]
struct RawLight {
    #[serde(default)]
    kind: LightKind,
    direction: Option<[f32; 3]>,
    position: Option<[f32; 3]>,
    outer_angle_degrees: Option<f32>,
    inner_angle_degrees: Option<f32>,
    color: Option<Rgb>,
    intensity: Option<f32>,
    texture: Option<String>,
    scattering: Option<f32>,
}

#[derive(Deserialize, Clone, Copy, PartialEq, Debug)]
#[serde(rename_all = "kebab-case")]
enum ObjectKind {
    Plane,
    Box,
    Sphere,
    Cylinder,
    Mesh,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawObject {
    kind: ObjectKind,
    path: Option<String>,
    translate: Option<[f32; 3]>,
    rotate_degrees: Option<[f32; 3]>,
    scale: Option<Rgb>,
    albedo: Option<Rgb>,
}

/// `[render]`: known keys plus technique sub-tables kept unparsed.
#[derive(Default)]
struct RawRender {
    width: Option<u32>,
    height: Option<u32>,
    shadow_map_size: Option<u32>,
    shadow_bias: Option<f32>,
    shadow_filter: Option<String>,
    shadow_normal_offset_texels: Option<f32>,
    ambient: Option<Rgb>,
    exposure: Option<f32>,
    techniques: BTreeMap<String, toml::Table>,
}

const RENDER_KEYS: &[&str] = &[
    "width",
    "height",
    "shadow_map_size",
    "shadow_bias",
    "shadow_filter",
    "shadow_normal_offset_texels",
    "ambient",
    "exposure",
];

/// A technique table under `[render]`; any other value there is an unknown key. Reading it
/// through a seed (rather than failing after the value) keeps the key in the error's path.
struct TechniqueTable<'k> {
    key: &'k str,
}

impl<'de> de::DeserializeSeed<'de> for TechniqueTable<'_> {
    type Value = toml::Table;
    fn deserialize<D: Deserializer<'de>>(self, d: D) -> Result<toml::Table, D::Error> {
        match toml::Value::deserialize(d)? {
            toml::Value::Table(t) => Ok(t),
            _ => {
                let known = RENDER_KEYS.iter().map(|k| format!("`{k}`")).collect::<Vec<_>>();
                Err(de::Error::custom(format!(
                    "unknown field `{}`, expected one of {} or a technique table such as [render.brute-force]",
                    self.key,
                    known.join(", ")
                )))
            }
        }
    }
}

impl<'de> Deserialize<'de> for RawRender {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct V;
        impl<'de> Visitor<'de> for V {
            type Value = RawRender;
            fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
                f.write_str("a [render] table")
            }
            fn visit_map<A: MapAccess<'de>>(self, mut map: A) -> Result<RawRender, A::Error> {
                let mut r = RawRender::default();
                while let Some(key) = map.next_key::<String>()? {
                    match key.as_str() {
                        "width" => r.width = Some(map.next_value()?),
                        "height" => r.height = Some(map.next_value()?),
                        "shadow_map_size" => r.shadow_map_size = Some(map.next_value()?),
                        "shadow_bias" => r.shadow_bias = Some(map.next_value()?),
                        "shadow_filter" => r.shadow_filter = Some(map.next_value()?),
                        "shadow_normal_offset_texels" => r.shadow_normal_offset_texels = Some(map.next_value()?),
                        "ambient" => r.ambient = Some(map.next_value()?),
                        "exposure" => r.exposure = Some(map.next_value()?),
                        _ => {
                            let t = map.next_value_seed(TechniqueTable { key: &key })?;
                            r.techniques.insert(key, t);
                        }
                    }
                }
                Ok(r)
            }
        }
        d.deserialize_map(V)
    }
}

// ---------------------------------------------------------------------------------------------
// Parsing with key paths and locations.

fn parse_raw(text: &str, file: &str) -> Result<RawScene, SceneError> {
    let de = match toml::Deserializer::parse(text) {
        Ok(de) => de,
        Err(e) => {
            let (line, column) = e.span().map(|s| line_col(text, s.start)).unwrap_or((0, 0));
            let key = if line > 0 { guess_key(text, line) } else { String::new() };
            return Err(SceneError::Syntax {
                file: file.to_string(),
                line,
                column,
                key,
                message: one_line(e.message()),
            });
        }
    };
    serde_path_to_error::deserialize::<_, RawScene>(de).map_err(|e| {
        let path = e.path().to_string();
        let inner = e.inner();
        let (line, column) = inner.span().map(|s| line_col(text, s.start)).unwrap_or((0, 0));
        let key = if path == "." || path.is_empty() {
            if line > 0 { guess_key(text, line) } else { String::new() }
        } else {
            path
        };
        SceneError::Syntax { file: file.to_string(), line, column, key, message: friendly(&one_line(inner.message())) }
    })
}

/// Rewrites serde's Rust-flavoured type names into the words a scene-file author uses.
fn friendly(message: &str) -> String {
    let mut m = message
        .replace("expected f32", "expected a number")
        .replace("expected u32", "expected a whole number ≥ 0")
        .replace("expected a string", "expected a quoted string");
    if let Some(i) = m.find("expected struct Raw") {
        m.truncate(i);
        m.push_str("expected a table");
    }
    m
}

/// 1-based line and column (in characters) of a byte offset.
fn line_col(text: &str, offset: usize) -> (usize, usize) {
    let mut offset = offset.min(text.len());
    while !text.is_char_boundary(offset) {
        offset -= 1;
    }
    let before = &text[..offset];
    let line = before.matches('\n').count() + 1;
    let line_start = before.rfind('\n').map(|i| i + 1).unwrap_or(0);
    (line, text[line_start..offset].chars().count() + 1)
}

/// Best-effort dotted key path of the key written on a 1-based line, from the table headers
/// above it (used where the TOML parser gives no key: syntax errors).
fn guess_key(text: &str, line: usize) -> String {
    let mut table = String::new();
    let mut array_counts: BTreeMap<String, usize> = BTreeMap::new();
    let simple_key = |s: &str| {
        let s = s.trim();
        (!s.is_empty() && s.chars().all(|c| c.is_ascii_alphanumeric() || "_-.\"' ".contains(c)))
            .then(|| s.replace([' ', '"', '\''], ""))
    };
    for (i, l) in text.lines().enumerate() {
        let t = l.trim();
        let is_target = i + 1 == line;
        if let Some(inner) = t.strip_prefix("[[").and_then(|r| r.split("]]").next()) {
            if let Some(k) = simple_key(inner) {
                let n = array_counts.entry(k.clone()).or_insert(0);
                table = format!("{k}[{n}]");
                *n += 1;
                if is_target {
                    return table;
                }
                continue;
            }
        } else if let Some(inner) = t.strip_prefix('[').and_then(|r| r.split(']').next())
            && let Some(k) = simple_key(inner)
        {
            // A sub-table of an array of tables refers to its last element.
            let mut path = k.clone();
            for (arr, n) in &array_counts {
                if let Some(rest) = k.strip_prefix(&format!("{arr}.")) {
                    path = format!("{arr}[{}].{rest}", n.saturating_sub(1));
                }
            }
            table = path;
            if is_target {
                return table;
            }
            continue;
        }
        if is_target {
            let key = t.split('=').next().and_then(|k| if t.contains('=') { simple_key(k) } else { None });
            return match (table.is_empty(), key) {
                (_, None) => table,
                (true, Some(k)) => k,
                (false, Some(k)) => format!("{table}.{k}"),
            };
        }
    }
    table
}

// ---------------------------------------------------------------------------------------------
// Validation and building.

struct Ctx {
    file: String,
    base_dir: PathBuf,
}

fn fmt_num(v: f32) -> String {
    if v.is_nan() {
        "nan".into()
    } else if v.is_infinite() {
        if v > 0.0 { "inf".into() } else { "-inf".into() }
    } else {
        format!("{v}")
    }
}

fn fmt_vec(v: [f32; 3]) -> String {
    format!("[{}, {}, {}]", fmt_num(v[0]), fmt_num(v[1]), fmt_num(v[2]))
}

impl Ctx {
    fn err(&self, key: impl Into<String>, value: impl Into<String>, message: impl Into<String>) -> SceneError {
        SceneError::Invalid {
            file: self.file.clone(),
            key: one_line(&key.into()),
            value: one_line(&value.into()),
            message: one_line(&message.into()),
        }
    }

    fn finite(&self, key: &str, v: f32) -> Result<f32, SceneError> {
        if v.is_finite() { Ok(v) } else { Err(self.err(key, fmt_num(v), "must be a finite number")) }
    }

    fn finite3(&self, key: &str, v: [f32; 3]) -> Result<Vec3, SceneError> {
        for (i, c) in v.iter().enumerate() {
            self.finite(&format!("{key}[{i}]"), *c)?;
        }
        Ok(Vec3::from(v))
    }

    /// Finite, each component in [lo, hi].
    fn ranged3(&self, key: &str, v: [f32; 3], lo: f32, hi: f32, what: &str) -> Result<Vec3, SceneError> {
        self.finite3(key, v)?;
        for (i, c) in v.iter().enumerate() {
            if *c < lo || *c > hi {
                return Err(self.err(format!("{key}[{i}]"), fmt_num(*c), what));
            }
        }
        Ok(Vec3::from(v))
    }

    fn direction(&self, key: &str, v: [f32; 3]) -> Result<Vec3, SceneError> {
        let d = self.finite3(key, v)?;
        let l = d.length();
        if !(l.is_finite() && l > 1e-12) {
            return Err(self.err(key, fmt_vec(v), "direction must have non-zero length"));
        }
        Ok(d / l)
    }

    /// A path relative to the scene file's directory, inside it (no absolute paths, no `..`),
    /// naming an existing file.
    fn path(&self, key: &str, value: &str) -> Result<PathBuf, SceneError> {
        let shown = format!("{value:?}");
        if value.trim().is_empty() {
            return Err(self.err(key, shown, "path must not be empty"));
        }
        let p = Path::new(value);
        let absolute = p.is_absolute()
            || p.components().any(|c| matches!(c, Component::RootDir | Component::Prefix(_)))
            || value.starts_with(['/', '\\'])
            || value.contains(':');
        if absolute {
            return Err(self.err(key, shown, "absolute paths are not allowed; give a path relative to the scene file"));
        }
        if value.split(['/', '\\']).any(|c| c == "..") || p.components().any(|c| matches!(c, Component::ParentDir)) {
            return Err(self.err(
                key,
                shown,
                "paths must not contain `..`; keep files in the scene file's directory or below",
            ));
        }
        let full = self.base_dir.join(p);
        if !full.is_file() {
            return Err(self.err(key, shown, format!("file not found (looked for {})", full.display())));
        }
        // A symbolic link must not lead out of the scene file's directory either.
        let dir = if self.base_dir.as_os_str().is_empty() { Path::new(".") } else { self.base_dir.as_path() };
        let base = dir.canonicalize().unwrap_or_else(|_| dir.to_path_buf());
        match full.canonicalize() {
            Ok(real) if real.starts_with(&base) => Ok(full),
            Ok(real) => Err(self.err(
                key,
                shown,
                format!("resolves to {}, outside the scene file's directory (a symbolic link?)", real.display()),
            )),
            Err(e) => Err(self.err(key, shown, format!("cannot resolve the path: {e}"))),
        }
    }
}

fn build(ctx: &Ctx, raw: RawScene) -> Result<Scene, SceneError> {
    let stem = Path::new(&ctx.file).file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
    let name = raw.name.unwrap_or(stem);
    let description = raw.description.map(|d| one_line(&d)).unwrap_or_default();
    let camera = build_camera(ctx, raw.camera.unwrap_or_default())?;
    let medium = build_medium(ctx, raw.medium.unwrap_or_default())?;
    let lights = match (raw.light, raw.lights) {
        (Some(_), Some(_)) => {
            return Err(ctx.err(
                "lights",
                "[light] and [[lights]]",
                "give either one [light] table or [[lights]] tables",
            ));
        }
        (Some(l), None) => vec![build_light(ctx, "light", l)?],
        (None, None) => vec![build_light(ctx, "light", RawLight::default())?],
        (None, Some(list)) if list.is_empty() => {
            return Err(ctx.err("lights", "[]", "a scene needs at least one light"));
        }
        (None, Some(list)) => list
            .into_iter()
            .enumerate()
            .map(|(i, l)| build_light(ctx, &format!("lights[{i}]"), l))
            .collect::<Result<Vec<_>, _>>()?,
    };
    if lights.len() > crepuscular::MAX_LIGHTS {
        return Err(ctx.err(
            format!("lights[{}]", crepuscular::MAX_LIGHTS),
            format!("{} lights", lights.len()),
            format!("at most {} lights per scene", crepuscular::MAX_LIGHTS),
        ));
    }
    let render = build_render(ctx, raw.render.unwrap_or_default())?;
    let mut geometry = Geometry::default();
    for (i, o) in raw.objects.iter().enumerate() {
        geometry.append(&build_object(ctx, &format!("objects[{i}]"), o)?);
    }
    Ok(Scene { name, description, camera, medium, lights, geometry, render })
}

fn build_camera(ctx: &Ctx, c: RawCamera) -> Result<Camera, SceneError> {
    let d = Camera::default();
    let position = c.position.map(|v| ctx.finite3("camera.position", v)).transpose()?.unwrap_or(d.position);
    let look_at = c.look_at.map(|v| ctx.finite3("camera.look_at", v)).transpose()?.unwrap_or(d.look_at);
    let up = c.up.map(|v| ctx.direction("camera.up", v)).transpose()?.unwrap_or(d.up);
    let fov = ctx.finite("camera.fov_y_degrees", c.fov_y_degrees.unwrap_or(d.fov_y_degrees))?;
    let near = ctx.finite("camera.near", c.near.unwrap_or(d.near))?;
    let far = ctx.finite("camera.far", c.far.unwrap_or(d.far))?;
    let camera = Camera { position, look_at, up, fov_y_degrees: fov, near, far };
    // The library's own checks (field of view, 0 < near < far, a look-at point away from the
    // eye), with the file named.
    camera.validate().map_err(|e| match e {
        crepuscular::Error::Invalid { key, value, reason } => ctx.err(key, value, reason),
        other => ctx.err("camera", "", other.to_string()),
    })?;
    // A file's up vector must not lie along the view (the library would replace it silently).
    if (look_at - position).normalize().cross(up).length() < 1e-4 {
        return Err(ctx.err("camera.up", fmt_vec(up.to_array()), "must not be parallel to the view direction"));
    }
    Ok(camera)
}

fn build_medium(ctx: &Ctx, m: RawMedium) -> Result<Medium, SceneError> {
    let d = Medium::default();
    let coef = "coefficients must be ≥ 0 and finite";
    let scattering = match m.scattering {
        Some(v) => ctx.ranged3("medium.scattering", v.0, 0.0, f32::MAX, coef)?,
        None => d.scattering,
    };
    let absorption = match m.absorption {
        Some(v) => ctx.ranged3("medium.absorption", v.0, 0.0, f32::MAX, coef)?,
        None => d.absorption,
    };
    let phase = match m.phase {
        None => d.phase,
        Some(p) => {
            let check_g = |g: f32| -> Result<f32, SceneError> {
                if g.is_finite() && g > -1.0 && g < 1.0 {
                    Ok(g)
                } else {
                    Err(ctx.err("medium.phase.g", fmt_num(g), "asymmetry g must be in (-1, 1)"))
                }
            };
            let kind_name = match p.kind {
                PhaseKind::Isotropic => "isotropic",
                PhaseKind::HenyeyGreenstein => "henyey-greenstein",
                PhaseKind::Rayleigh => "rayleigh",
                PhaseKind::HoffmanPreetham => "hoffman-preetham",
            };
            if let (Some(g), PhaseKind::Isotropic | PhaseKind::Rayleigh) = (p.g, p.kind) {
                return Err(ctx.err(
                    "medium.phase.g",
                    fmt_num(g),
                    format!("not used by the {kind_name} phase function"),
                ));
            }
            if let Some(f) = p.rayleigh_fraction
                && p.kind != PhaseKind::HoffmanPreetham
            {
                return Err(ctx.err(
                    "medium.phase.rayleigh_fraction",
                    fmt_vec(f.0),
                    format!("only used by hoffman-preetham, not {kind_name}"),
                ));
            }
            match p.kind {
                PhaseKind::Isotropic => Phase::Isotropic,
                PhaseKind::Rayleigh => Phase::Rayleigh,
                PhaseKind::HenyeyGreenstein => Phase::HenyeyGreenstein { g: check_g(p.g.unwrap_or(0.7))? },
                PhaseKind::HoffmanPreetham => {
                    // The library's defaults, through its own serde implementation.
                    let mut t = toml::Table::new();
                    t.insert("kind".into(), toml::Value::String("hoffman-preetham".into()));
                    let (g_default, f_default) = match toml::Value::Table(t).try_into::<Phase>() {
                        Ok(Phase::HoffmanPreetham { g, rayleigh_fraction }) => (g, rayleigh_fraction),
                        _ => (0.76, Vec3::new(5.8 / 26.8, 13.5 / 34.5, 33.1 / 54.1)),
                    };
                    let g = check_g(p.g.unwrap_or(g_default))?;
                    let rayleigh_fraction = match p.rayleigh_fraction {
                        Some(f) => {
                            ctx.ranged3("medium.phase.rayleigh_fraction", f.0, 0.0, 1.0, "fractions must be in [0, 1]")?
                        }
                        None => f_default,
                    };
                    Phase::HoffmanPreetham { g, rayleigh_fraction }
                }
            }
        }
    };
    Ok(Medium { scattering, absorption, phase })
}

/// One light table (`key` is `light` or `lights[i]`, the prefix of every error's key).
fn build_light(ctx: &Ctx, key: &str, l: RawLight) -> Result<SceneLight, SceneError> {
    let k = |name: &str| format!("{key}.{name}");
    let scattering = l.scattering.unwrap_or(1.0);
    if !(scattering.is_finite() && scattering >= 0.0) {
        return Err(ctx.err(k("scattering"), fmt_num(scattering), "must be finite and ≥ 0"));
    }
    Ok(SceneLight { light: build_light_kind(ctx, key, l)?, scattering })
}

fn build_light_kind(ctx: &Ctx, key: &str, l: RawLight) -> Result<Light, SceneError> {
    let k = |name: &str| format!("{key}.{name}");
    let kind = match l.kind {
        LightKind::Directional => "directional",
        LightKind::Spot => "spot",
        LightKind::Point => "point",
    };
    let not_used = |name: &str, value: String| Err(ctx.err(k(name), value, format!("not used by a {kind} light")));
    let color = match l.color {
        Some(c) => ctx.ranged3(&k("color"), c.0, 0.0, f32::MAX, "colour components must be ≥ 0 and finite")?,
        None => Vec3::ONE,
    };
    let default_intensity = if l.kind == LightKind::Directional { 1.0 } else { 50.0 };
    let intensity = l.intensity.unwrap_or(default_intensity);
    if !(intensity.is_finite() && intensity >= 0.0) {
        return Err(ctx.err(k("intensity"), fmt_num(intensity), "must be finite and ≥ 0"));
    }
    let required = |name: &str| ctx.err(k(name), "(missing)", format!("required for a {kind} light"));
    let position = l.position.map(|p| ctx.finite3(&k("position"), p)).transpose()?;
    let direction = l.direction.map(|d| ctx.direction(&k("direction"), d)).transpose()?;
    if l.kind != LightKind::Spot {
        if let Some(v) = l.outer_angle_degrees {
            return not_used("outer_angle_degrees", fmt_num(v));
        }
        if let Some(v) = l.inner_angle_degrees {
            return not_used("inner_angle_degrees", fmt_num(v));
        }
        if let Some(t) = &l.texture {
            return not_used("texture", format!("{t:?}"));
        }
    }
    match l.kind {
        LightKind::Directional => {
            if let Some(p) = position {
                return not_used("position", fmt_vec(p.to_array()));
            }
            let direction = direction.unwrap_or_else(|| Vec3::from(DEFAULT_SUN_DIRECTION).normalize());
            Ok(Light::Directional { direction, color, intensity })
        }
        LightKind::Point => {
            if let Some(d) = l.direction {
                return not_used("direction", fmt_vec(d));
            }
            let position = position.ok_or_else(|| required("position"))?;
            Ok(Light::Point { position, color, intensity })
        }
        LightKind::Spot => {
            let position = position.ok_or_else(|| required("position"))?;
            let direction = direction.ok_or_else(|| required("direction"))?;
            let outer = l.outer_angle_degrees.unwrap_or(30.0);
            if !(outer > 0.0 && outer <= 89.0) {
                return Err(ctx.err(k("outer_angle_degrees"), fmt_num(outer), "must be in (0, 89] degrees"));
            }
            let inner = l.inner_angle_degrees.unwrap_or(0.8 * outer);
            if !(0.0..=89.0).contains(&inner) {
                return Err(ctx.err(k("inner_angle_degrees"), fmt_num(inner), "must be in [0, 89] degrees"));
            }
            if inner > outer {
                return Err(ctx.err(
                    k("inner_angle_degrees"),
                    fmt_num(inner),
                    format!("must be ≤ {key}.outer_angle_degrees ({})", fmt_num(outer)),
                ));
            }
            let texture = match &l.texture {
                None => None,
                Some(t) => {
                    let full = ctx.path(&k("texture"), t)?;
                    let tex = load_texture(&full).map_err(|m| ctx.err(k("texture"), format!("{t:?}"), m))?;
                    Some(Arc::new(tex))
                }
            };
            Ok(Light::Spot {
                position,
                direction,
                outer_angle_degrees: outer,
                inner_angle_degrees: inner,
                color,
                intensity,
                texture,
            })
        }
    }
}

fn build_render(ctx: &Ctx, r: RawRender) -> Result<RenderSettings, SceneError> {
    let mut s = RenderSettings::default();
    let size = |key: &str, v: Option<u32>, default: u32| -> Result<u32, SceneError> {
        let v = v.unwrap_or(default);
        if v == 0 || v > MAX_IMAGE_SIZE {
            return Err(ctx.err(key, v.to_string(), format!("must be between 1 and {MAX_IMAGE_SIZE}")));
        }
        Ok(v)
    };
    s.width = size("render.width", r.width, s.width)?;
    s.height = size("render.height", r.height, s.height)?;
    s.shadow.size = size("render.shadow_map_size", r.shadow_map_size, s.shadow.size)?;
    if let Some(b) = r.shadow_bias {
        if !(b.is_finite() && b >= 0.0) {
            return Err(ctx.err("render.shadow_bias", fmt_num(b), "must be finite and ≥ 0"));
        }
        s.shadow.bias = b;
    }
    if let Some(f) = &r.shadow_filter {
        s.shadow.filter = crepuscular::ShadowFilter::parse(f)
            .map_err(|_| ctx.err("render.shadow_filter", format!("{f:?}"), "must be \"nearest\" or \"bilinear\""))?;
    }
    if let Some(b) = r.shadow_normal_offset_texels {
        if !(b.is_finite() && b >= 0.0) {
            return Err(ctx.err("render.shadow_normal_offset_texels", fmt_num(b), "must be finite and ≥ 0"));
        }
        s.shadow.normal_offset_texels = b;
    }
    if let Some(a) = r.ambient {
        s.ambient = ctx.ranged3("render.ambient", a.0, 0.0, f32::MAX, "must be finite and ≥ 0")?;
    }
    if let Some(e) = r.exposure {
        if !(e.is_finite() && e > 0.0) {
            return Err(ctx.err("render.exposure", fmt_num(e), "must be finite and > 0"));
        }
        s.exposure = e;
    }
    for (name, table) in &r.techniques {
        check_table_finite(ctx, &format!("render.{name}"), table)?;
    }
    s.techniques = r.techniques;
    Ok(s)
}

/// Rejects NaN and infinities anywhere inside a technique table.
fn check_table_finite(ctx: &Ctx, key: &str, t: &toml::Table) -> Result<(), SceneError> {
    fn check(ctx: &Ctx, key: &str, v: &toml::Value) -> Result<(), SceneError> {
        match v {
            toml::Value::Float(f) if !f.is_finite() => Err(ctx.err(key, fmt_num(*f as f32), "must be a finite number")),
            toml::Value::Array(a) => a.iter().enumerate().try_for_each(|(i, v)| check(ctx, &format!("{key}[{i}]"), v)),
            toml::Value::Table(t) => t.iter().try_for_each(|(k, v)| check(ctx, &format!("{key}.{k}"), v)),
            _ => Ok(()),
        }
    }
    t.iter().try_for_each(|(k, v)| check(ctx, &format!("{key}.{k}"), v))
}

fn build_object(ctx: &Ctx, key: &str, o: &RawObject) -> Result<Geometry, SceneError> {
    let translate = o.translate.map(|v| ctx.finite3(&format!("{key}.translate"), v)).transpose()?.unwrap_or(Vec3::ZERO);
    let rotate =
        o.rotate_degrees.map(|v| ctx.finite3(&format!("{key}.rotate_degrees"), v)).transpose()?.unwrap_or(Vec3::ZERO);
    let scale = match o.scale {
        None => Vec3::ONE,
        Some(s) => {
            let v = ctx.finite3(&format!("{key}.scale"), s.0)?;
            for (i, c) in s.0.iter().enumerate() {
                if *c == 0.0 {
                    return Err(ctx.err(format!("{key}.scale[{i}]"), fmt_num(*c), "scale must be non-zero"));
                }
            }
            v
        }
    };
    let albedo = o
        .albedo
        .map(|a| ctx.ranged3(&format!("{key}.albedo"), a.0, 0.0, 1.0, "albedo must be in [0, 1]"))
        .transpose()?;
    let t = Transform { translate, rotate_degrees: rotate, scale };
    if let Some(p) = &o.path
        && o.kind != ObjectKind::Mesh
    {
        return Err(ctx.err(format!("{key}.path"), format!("{p:?}"), "only `kind = \"mesh\"` objects take a path"));
    }
    let a = albedo.unwrap_or(mesh::DEFAULT_ALBEDO);
    Ok(match o.kind {
        ObjectKind::Plane => mesh::plane(&t, a),
        ObjectKind::Box => mesh::cuboid(&t, a),
        ObjectKind::Sphere => mesh::sphere(&t, a),
        ObjectKind::Cylinder => mesh::cylinder(&t, a),
        ObjectKind::Mesh => {
            let pkey = format!("{key}.path");
            let Some(p) = &o.path else {
                return Err(ctx.err(pkey, "(missing)", "required for `kind = \"mesh\"`"));
            };
            let full = ctx.path(&pkey, p)?;
            mesh::load_mesh(&full, &t, albedo).map_err(|e| ctx.err(&pkey, format!("{p:?}"), e.to_string()))?
        }
    })
}

/// sRGB transfer function → linear.
fn srgb_to_linear(c: f32) -> f32 {
    if c <= 0.04045 { c / 12.92 } else { ((c + 0.055) / 1.055).powf(2.4) }
}

/// Loads a spot-light texture: PNG (or any 8/16-bit image) is taken as sRGB and converted to
/// linear; float images (EXR) are taken as linear. At most [`MAX_TEXTURE_SIZE`] per side.
/// Returns a one-line message on failure.
pub fn load_texture(path: &Path) -> Result<RgbTexture, String> {
    let (w, h) =
        image::image_dimensions(path).map_err(|e| format!("cannot read image: {}", one_line(&e.to_string())))?;
    if w == 0 || h == 0 || w > MAX_TEXTURE_SIZE || h > MAX_TEXTURE_SIZE {
        return Err(format!("image is {w}×{h}; sides must be between 1 and {MAX_TEXTURE_SIZE}"));
    }
    let img = image::open(path).map_err(|e| format!("cannot decode image: {}", one_line(&e.to_string())))?;
    let linear_source = matches!(img, image::DynamicImage::ImageRgb32F(_) | image::DynamicImage::ImageRgba32F(_));
    let rgba = img.to_rgba32f();
    let (width, height) = rgba.dimensions();
    let texels = rgba
        .pixels()
        .map(|p| {
            let f = |c: f32| {
                let c = if c.is_finite() { c.max(0.0) } else { 0.0 };
                if linear_source { c } else { srgb_to_linear(c) }
            };
            [f(p[0]), f(p[1]), f(p[2]), p[3]]
        })
        .collect();
    Ok(RgbTexture { width, height, texels })
}
