//! Built-in scenes, scene files (good and bad) and mesh import.

use crepuscular::{Light, Phase};
use crepuscular_scene::builtin::{DEFAULT_SCENE, builtin, builtin_names};
use crepuscular_scene::file::{SceneError, load_scene_file, parse_scene_str};
use crepuscular_scene::mesh::{self, Transform, load_mesh};
use glam::Vec3;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};

/// A fresh, empty directory under the system temp dir.
fn temp_dir(tag: &str) -> PathBuf {
    static N: AtomicUsize = AtomicUsize::new(0);
    let dir = std::env::temp_dir().join(format!(
        "crepuscular-scene-test-{}-{}-{tag}",
        std::process::id(),
        N.fetch_add(1, Ordering::Relaxed)
    ));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

fn write(dir: &Path, name: &str, contents: impl AsRef<[u8]>) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, contents).unwrap();
    p
}

const CUBE_OBJ: &str = "\
# a unit cube, quads
v -0.5 -0.5 -0.5
v 0.5 -0.5 -0.5
v 0.5 0.5 -0.5
v -0.5 0.5 -0.5
v -0.5 -0.5 0.5
v 0.5 -0.5 0.5
v 0.5 0.5 0.5
v -0.5 0.5 0.5
f 1 4 3 2
f 5 6 7 8
f 1 2 6 5
f 4 8 7 3
f 1 5 8 4
f 2 3 7 6
";

fn write_png(dir: &Path, name: &str) -> PathBuf {
    let mut img = image::RgbImage::new(4, 2);
    for (x, _, p) in img.enumerate_pixels_mut() {
        *p = if x < 2 { image::Rgb([255, 128, 0]) } else { image::Rgb([0, 0, 255]) };
    }
    let p = dir.join(name);
    img.save(&p).unwrap();
    p
}

// ---------------------------------------------------------------------------------------------
// Built-in scenes.

#[test]
fn every_builtin_loads_with_geometry() {
    assert!(builtin_names().len() >= 5);
    assert!(builtin_names().iter().any(|(n, _)| *n == DEFAULT_SCENE));
    for (name, desc) in builtin_names() {
        let s = builtin(name).unwrap_or_else(|| panic!("builtin {name} missing"));
        assert_eq!(&s.name, name);
        assert_eq!(&s.description, desc);
        assert!(!desc.contains('\n'));
        assert!(s.geometry.triangle_count() > 0, "{name} has no triangles");
        assert_eq!(s.geometry.indices.len() % 3, 0);
        let nv = s.geometry.vertices.len();
        assert!(s.geometry.indices.iter().all(|&i| (i as usize) < nv), "{name}: index out of range");
        for v in &s.geometry.vertices {
            assert!(v.position.iter().all(|c| c.is_finite()), "{name}: non-finite position");
            let n = Vec3::from(v.normal);
            assert!((n.length() - 1.0).abs() < 1e-3, "{name}: normal {n} not unit");
            assert!(v.albedo.iter().all(|&c| (0.0..=1.0).contains(&c)), "{name}: albedo {:?}", v.albedo);
        }
        assert_eq!((s.render.width, s.render.height), (960, 540), "{name}");
        // 2048² maps, except where a scene's lights need more layers than one point light's
        // cube (6): night-street's eight lights take 13 layers, at 1024² (52 MiB, not 208).
        let layers: u32 = s.frame_desc().unwrap().lights.iter().map(|l| l.shadow.layers).sum();
        let size = if layers > 6 { 1024 } else { 2048 };
        assert_eq!(s.render.shadow.size, size, "{name} ({layers} shadow-map layers)");
        let c = &s.camera;
        assert!(c.near > 0.0 && c.far > c.near && (c.look_at - c.position).length() > 0.0);
        assert!(s.medium.scattering.min_element() > 0.0);
        // The camera must not sit inside geometry bounds' exterior in a silly way: it sees
        // something, i.e. the geometry is within the far plane.
        let b = s.geometry.bounds();
        assert!((b.center() - c.position).length() < c.far + b.radius(), "{name}");
    }
    assert!(builtin("no-such-scene").is_none());
}

#[test]
fn builtin_lights_are_the_advertised_kinds() {
    let kind = |n: &str| builtin(n).unwrap().lights[0].light.kind_name();
    assert_eq!(kind("colonnade"), "directional");
    assert_eq!(kind("forest"), "directional");
    assert_eq!(kind("terrain"), "directional");
    assert_eq!(kind("cage"), "point");
    assert_eq!(kind("stained-glass"), "spot");
    match builtin("stained-glass").unwrap().lights[0].light.clone() {
        Light::Spot { texture: Some(t), .. } => {
            assert_eq!((t.width, t.height), (256, 256));
            assert_eq!(t.texels.len(), 256 * 256);
            // Coloured panes and dark lead lines.
            let lum = |p: &[f32; 4]| 0.2126 * p[0] + 0.7152 * p[1] + 0.0722 * p[2];
            assert!(t.texels.iter().any(|p| lum(p) < 0.03));
            assert!(t.texels.iter().any(|p| p[0] > 0.6 && p[2] < 0.2));
            assert!(t.texels.iter().any(|p| p[2] > 0.6 && p[0] < 0.2));
        }
        _ => panic!("stained-glass needs a textured spot light"),
    }
    for (name, _) in builtin_names() {
        if let Light::Directional { direction, .. } = builtin(name).unwrap().lights[0].light.clone() {
            assert!((direction.length() - 1.0).abs() < 1e-5);
            assert!(direction.y < 0.0, "{name}: the sun must shine downwards");
        }
    }
}

#[test]
fn forest_has_thousands_of_leaves() {
    let s = builtin("forest").unwrap();
    let leaves = s
        .geometry
        .indices
        .chunks_exact(3)
        .filter(|t| {
            let a = s.geometry.vertices[t[0] as usize].albedo;
            a[1] > 1.5 * a[0] && a[1] > 2.0 * a[2]
        })
        .count();
    assert!(leaves >= 2000, "only {leaves} leaf triangles");
}

#[test]
fn terrain_is_a_128_grid() {
    let s = builtin("terrain").unwrap();
    assert_eq!(s.geometry.vertices.len(), 128 * 128);
    assert_eq!(s.geometry.triangle_count(), 127 * 127 * 2);
}

#[test]
fn builtins_are_deterministic() {
    for (name, _) in builtin_names() {
        assert_eq!(builtin(name).unwrap().geometry, builtin(name).unwrap().geometry, "{name}");
    }
}

// ---------------------------------------------------------------------------------------------
// Good scene files.

/// The example scene in file.rs's module documentation (also the README's).
fn documented_example() -> String {
    let src = include_str!("../src/file.rs");
    let mut out = String::new();
    let mut inside = false;
    for line in src.lines() {
        let Some(doc) = line.strip_prefix("//!") else {
            continue;
        };
        let doc = doc.strip_prefix(' ').unwrap_or(doc);
        if doc.starts_with("```toml") {
            inside = true;
        } else if inside && doc.starts_with("```") {
            break;
        } else if inside {
            out.push_str(doc);
            out.push('\n');
        }
    }
    assert!(out.contains("[camera]"), "example not found in file.rs docs");
    out
}

#[test]
fn documented_example_parses_with_all_keys() {
    let dir = temp_dir("example");
    write(&dir, "column.obj", CUBE_OBJ);
    write_png(&dir, "gobo.png");
    let path = write(&dir, "portico.toml", documented_example());
    let s = load_scene_file(&path).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(s.name, "portico");
    assert_eq!(s.description, "Columns in low sun");
    assert_eq!(s.camera.position, Vec3::new(0.0, 2.0, 18.0));
    assert_eq!(s.camera.look_at, Vec3::new(0.0, 5.0, 0.0));
    assert_eq!(s.camera.fov_y_degrees, 60.0);
    assert_eq!((s.camera.near, s.camera.far), (0.1, 200.0));
    assert_eq!(s.medium.scattering, Vec3::splat(0.04));
    assert_eq!(s.medium.absorption, Vec3::splat(0.005));
    assert_eq!(s.medium.phase, Phase::HenyeyGreenstein { g: 0.6 });
    match &s.lights[0].light {
        Light::Spot { position, direction, outer_angle_degrees, inner_angle_degrees, color, intensity, texture } => {
            assert_eq!(*position, Vec3::new(-10.0, 9.0, 0.0));
            assert!((direction.length() - 1.0).abs() < 1e-6);
            assert!((*direction - Vec3::new(1.0, -0.95, 0.0).normalize()).length() < 1e-6);
            assert_eq!((*outer_angle_degrees, *inner_angle_degrees), (24.0, 19.0));
            assert_eq!(*color, Vec3::new(1.0, 0.95, 0.9));
            assert_eq!(*intensity, 3000.0);
            let t = texture.as_ref().expect("texture");
            assert_eq!((t.width, t.height), (4, 2));
            // sRGB → linear: 255 → 1, 128 → 0.2158, 0 → 0.
            let p = t.texels[0];
            assert!((p[0] - 1.0).abs() < 1e-6 && (p[1] - 0.2158).abs() < 1e-3 && p[2] == 0.0, "{p:?}");
        }
        other => panic!("expected a spot light, got {other:?}"),
    }
    // Plane (2 triangles) + cube mesh (12 triangles).
    assert_eq!(s.geometry.triangle_count(), 2 + 12);
    // The mesh is scaled 1.5, rotated and translated by 2 in x: its bounds.
    let mesh_xs: Vec<f32> = s.geometry.vertices[4..].iter().map(|v| v.position[0]).collect();
    let max_x = mesh_xs.iter().cloned().fold(f32::MIN, f32::max);
    assert!((max_x - (2.0 + 1.5 * 0.5 * 2f32.sqrt())).abs() < 1e-4, "{max_x}");
    // The plane is 60 × 60 with the given albedo.
    assert_eq!(s.geometry.vertices[0].albedo, [0.6, 0.55, 0.5]);
    assert!((s.geometry.bounds().min.x + 30.0).abs() < 1e-4);
    // Mesh without albedo: default grey (the OBJ has no material).
    assert_eq!(s.geometry.vertices[4].albedo, [0.7; 3]);
    let r = &s.render;
    assert_eq!((r.width, r.height, r.shadow.size), (960, 540, 2048));
    assert_eq!((r.shadow.bias, r.shadow.normal_offset_texels), (0.02, 1.5));
    assert_eq!(r.shadow.filter, crepuscular::ShadowFilter::Bilinear);
    assert_eq!(r.ambient, Vec3::splat(0.03));
    assert_eq!(r.exposure, 1.0);
    let bf = r.techniques.get("brute-force").expect("technique table kept");
    assert_eq!(bf.get("steps").and_then(|v| v.as_integer()), Some(32));
    assert_eq!(r.techniques.len(), 1);
}

#[test]
fn minimal_file_takes_defaults() {
    let dir = temp_dir("minimal");
    let path = write(&dir, "tiny.toml", "[light]\ndirection = [0, -1, -1]\n");
    let s = load_scene_file(&path).unwrap();
    assert_eq!(s.name, "tiny");
    assert_eq!(s.camera, crepuscular::Camera::default());
    assert_eq!(s.medium, crepuscular::Medium::default());
    assert_eq!(s.render, crepuscular_scene::RenderSettings::default());
    match s.lights[0].light.clone() {
        Light::Directional { direction, color, intensity } => {
            assert!((direction - Vec3::new(0.0, -1.0, -1.0).normalize()).length() < 1e-6);
            assert_eq!((color, intensity), (Vec3::ONE, 1.0));
        }
        other => panic!("{other:?}"),
    }
    assert_eq!(s.geometry.triangle_count(), 0);
    // No [light] at all: the default sun.
    let s = parse_scene_str("", "empty.toml", Path::new(".")).unwrap();
    assert!(
        matches!(s.lights[0].light, Light::Directional { direction, .. } if direction.z > 0.0 && direction.y < 0.0)
    );
    assert_eq!(s.name, "empty");
}

#[test]
fn other_lights_phases_and_objects() {
    let text = r#"
[medium]
scattering = 0.05
phase = { kind = "hoffman-preetham" }
[light]
kind = "point"
position = [0, 3, 0]
[[objects]]
kind = "sphere"
translate = [0, 1, 0]
albedo = 0.5
[[objects]]
kind = "cylinder"
scale = [1, 4, 1]
rotate_degrees = [0, 0, 90]
[[objects]]
kind = "box"
[[objects]]
kind = "plane"
scale = 10
"#;
    let s = parse_scene_str(text, "inline.toml", Path::new(".")).unwrap();
    assert!(matches!(s.lights[0].light, Light::Point { intensity, .. } if intensity == 50.0));
    assert!(matches!(s.medium.phase, Phase::HoffmanPreetham { g, .. } if (g - 0.76).abs() < 1e-6));
    let spot = parse_scene_str(
        "[light]\nkind = \"spot\"\nposition = [0, 5, 0]\ndirection = [0, -1, 0]\nouter_angle_degrees = 40\n[medium]\nphase = { kind = \"rayleigh\" }",
        "s.toml",
        Path::new("."),
    )
    .unwrap();
    match spot.lights[0].light.clone() {
        Light::Spot { outer_angle_degrees, inner_angle_degrees, intensity, texture, .. } => {
            assert_eq!(outer_angle_degrees, 40.0);
            assert!((inner_angle_degrees - 32.0).abs() < 1e-5);
            assert_eq!(intensity, 50.0);
            assert!(texture.is_none());
        }
        other => panic!("{other:?}"),
    }
    assert_eq!(spot.medium.phase, Phase::Rayleigh);
    let iso = parse_scene_str("[medium]\nphase = { kind = \"isotropic\" }", "i.toml", Path::new(".")).unwrap();
    assert_eq!(iso.medium.phase, Phase::Isotropic);
}

// ---------------------------------------------------------------------------------------------
// Bad scene files: an error, one line, naming the file and the key.

fn check_bad(dir: &Path, file: &str, text: &str, key: &str, also: &[&str]) -> String {
    let path = write(dir, file, text);
    let err = match load_scene_file(&path) {
        Ok(_) => panic!("{file}: expected an error for:\n{text}"),
        Err(e) => e,
    };
    let msg = err.to_string();
    assert!(!msg.contains('\n') && !msg.contains('\r'), "{file}: not one line: {msg:?}");
    assert!(msg.contains(file), "{file}: message does not name the file: {msg}");
    assert!(msg.contains(key), "{file}: message does not name the key {key}: {msg}");
    for a in also {
        assert!(msg.contains(a), "{file}: message lacks {a:?}: {msg}");
    }
    println!("{msg}");
    msg
}

#[test]
fn bad_files_fail_with_one_line_naming_file_and_key() {
    let dir = temp_dir("bad");
    write(&dir, "ok.obj", CUBE_OBJ);
    // Syntax error: location and (guessed) key.
    let m =
        check_bad(&dir, "syntax.toml", "[camera]\nfov_y_degrees = 60\nposition = [0, 1, \n", "camera.position", &[]);
    assert!(m.contains("syntax.toml:3:"), "{m}");
    check_bad(&dir, "syntax2.toml", "[render]\nwidth = = 3\n", "render.width", &["syntax2.toml:2:"]);
    check_bad(&dir, "unclosed.toml", "name = \"x\n", "name", &[]);
    // Unknown keys, everywhere.
    check_bad(
        &dir,
        "unknown.toml",
        "[medium]\nscatterin = 0.1\n",
        "medium.scatterin",
        &["unknown field", "unknown.toml:2:"],
    );
    check_bad(&dir, "unknown_top.toml", "nmae = \"x\"\n", "nmae", &["unknown field"]);
    check_bad(&dir, "unknown_light.toml", "[light]\ndirection = [0,-1,0]\ncolour = [1,1,1]\n", "light.colour", &[]);
    check_bad(
        &dir,
        "unknown_obj.toml",
        "[[objects]]\nkind = \"box\"\n[[objects]]\nkind = \"box\"\nsize = 2\n",
        "objects[1].size",
        &[],
    );
    check_bad(
        &dir,
        "unknown_phase.toml",
        "[medium]\nphase = { kind = \"henyey-greenstein\", gg = 0.5 }\n",
        "medium.phase.gg",
        &[],
    );
    check_bad(&dir, "unknown_render.toml", "[render]\nwdth = 10\n", "wdth", &["render"]);
    check_bad(&dir, "unknown_kind.toml", "[[objects]]\nkind = \"torus\"\n", "objects[0].kind", &["torus"]);
    check_bad(&dir, "unknown_phase_kind.toml", "[medium]\nphase = { kind = \"mie\" }\n", "medium.phase.kind", &["mie"]);
    // Wrong types.
    check_bad(&dir, "type.toml", "[camera]\nfov_y_degrees = \"wide\"\n", "camera.fov_y_degrees", &["type.toml:2:"]);
    check_bad(&dir, "type2.toml", "[camera]\nposition = [1, 2]\n", "camera.position", &[]);
    check_bad(&dir, "type3.toml", "[render]\nwidth = -5\n", "render.width", &[]);
    check_bad(&dir, "type4.toml", "[medium]\nscattering = [0.1, \"a\", 0.1]\n", "medium.scattering", &[]);
    check_bad(&dir, "type5.toml", "camera = 3\n", "camera", &[]);
    // Values out of range.
    check_bad(&dir, "neg.toml", "[medium]\nscattering = [-1, 0.1, 0.1]\n", "medium.scattering[0]", &["= -1", "≥ 0"]);
    check_bad(&dir, "neg2.toml", "[medium]\nabsorption = -0.5\n", "medium.absorption[0]", &["-0.5"]);
    check_bad(&dir, "nan.toml", "[medium]\nscattering = [0.1, nan, 0.1]\n", "medium.scattering[1]", &["nan"]);
    check_bad(&dir, "nan2.toml", "[camera]\nnear = nan\n", "camera.near", &["nan"]);
    check_bad(&dir, "inf.toml", "[camera]\nposition = [0, inf, 0]\n", "camera.position[1]", &["inf"]);
    check_bad(&dir, "nan3.toml", "[render]\nexposure = nan\n", "render.exposure", &[]);
    check_bad(&dir, "nan4.toml", "[render.brute-force]\nsteps = nan\n", "render.brute-force.steps", &["nan"]);
    check_bad(
        &dir,
        "nan5.toml",
        "[[objects]]\nkind = \"box\"\ntranslate = [0, nan, 0]\n",
        "objects[0].translate[1]",
        &[],
    );
    check_bad(
        &dir,
        "g.toml",
        "[medium]\nphase = { kind = \"henyey-greenstein\", g = 1.0 }\n",
        "medium.phase.g",
        &["= 1"],
    );
    check_bad(&dir, "g2.toml", "[medium]\nphase = { kind = \"isotropic\", g = 0.5 }\n", "medium.phase.g", &[]);
    check_bad(&dir, "zero.toml", "[render]\nwidth = 0\n", "render.width", &["= 0"]);
    check_bad(&dir, "huge.toml", "[render]\nheight = 100000\n", "render.height", &["100000"]);
    check_bad(&dir, "zero_shadow.toml", "[render]\nshadow_map_size = 0\n", "render.shadow_map_size", &[]);
    check_bad(
        &dir,
        "filter.toml",
        "[render]\nshadow_filter = \"pcf\"\n",
        "render.shadow_filter",
        &["\"pcf\"", "bilinear"],
    );
    check_bad(&dir, "filter2.toml", "[render]\nshadow_filter = 2\n", "render.shadow_filter", &[]);
    check_bad(&dir, "near.toml", "[camera]\nnear = 0\n", "camera.near", &[]);
    check_bad(&dir, "far.toml", "[camera]\nnear = 5\nfar = 2\n", "camera.far", &[]);
    check_bad(&dir, "fov.toml", "[camera]\nfov_y_degrees = 180\n", "camera.fov_y_degrees", &["180"]);
    check_bad(&dir, "lookat.toml", "[camera]\nposition = [1, 2, 3]\nlook_at = [1, 2, 3]\n", "camera.look_at", &[]);
    check_bad(&dir, "up.toml", "[camera]\nposition = [0, 5, 0]\nlook_at = [0, 0, 0]\n", "camera.up", &[]);
    check_bad(&dir, "dir.toml", "[light]\ndirection = [0, 0, 0]\n", "light.direction", &["[0, 0, 0]"]);
    check_bad(&dir, "nodir.toml", "[light]\nkind = \"spot\"\nposition = [0, 1, 0]\n", "light.direction", &["required"]);
    check_bad(&dir, "intensity.toml", "[light]\ndirection = [0,-1,0]\nintensity = -2\n", "light.intensity", &["-2"]);
    let spot = "[light]\nkind = \"spot\"\nposition = [0, 5, 0]\ndirection = [0, -1, 0]\n";
    check_bad(&dir, "outer.toml", &format!("{spot}outer_angle_degrees = 95\n"), "light.outer_angle_degrees", &["95"]);
    check_bad(&dir, "outer0.toml", &format!("{spot}outer_angle_degrees = 0\n"), "light.outer_angle_degrees", &[]);
    check_bad(
        &dir,
        "inner.toml",
        &format!("{spot}outer_angle_degrees = 20\ninner_angle_degrees = 30\n"),
        "light.inner_angle_degrees",
        &["30"],
    );
    check_bad(
        &dir,
        "pointdir.toml",
        "[light]\nkind = \"point\"\nposition = [0,1,0]\ndirection = [0,1,0]\n",
        "light.direction",
        &[],
    );
    check_bad(
        &dir,
        "albedo.toml",
        "[[objects]]\nkind = \"box\"\nalbedo = [1.5, 0, 0]\n",
        "objects[0].albedo[0]",
        &["1.5"],
    );
    check_bad(&dir, "scale.toml", "[[objects]]\nkind = \"box\"\nscale = [1, 0, 1]\n", "objects[0].scale[1]", &[]);
    // Files: missing, escaping, absolute.
    check_bad(
        &dir,
        "missing.toml",
        "[[objects]]\nkind = \"mesh\"\npath = \"nope.obj\"\n",
        "objects[0].path",
        &["nope.obj", "not found"],
    );
    check_bad(&dir, "nopath.toml", "[[objects]]\nkind = \"mesh\"\n", "objects[0].path", &["required"]);
    check_bad(
        &dir,
        "dotdot.toml",
        "[[objects]]\nkind = \"mesh\"\npath = \"../ok.obj\"\n",
        "objects[0].path",
        &["..", "../ok.obj"],
    );
    check_bad(
        &dir,
        "dotdot2.toml",
        "[[objects]]\nkind = \"mesh\"\npath = \"sub/../../ok.obj\"\n",
        "objects[0].path",
        &[],
    );
    check_bad(
        &dir,
        "dotdot3.toml",
        "[[objects]]\nkind = \"mesh\"\npath = \"sub\\\\..\\\\ok.obj\"\n",
        "objects[0].path",
        &[],
    );
    let abs = dir.join("ok.obj").display().to_string().replace('\\', "/");
    check_bad(
        &dir,
        "absolute.toml",
        &format!("[[objects]]\nkind = \"mesh\"\npath = \"{abs}\"\n"),
        "objects[0].path",
        &["absolute"],
    );
    check_bad(
        &dir,
        "absolute2.toml",
        "[[objects]]\nkind = \"mesh\"\npath = \"C:/x.obj\"\n",
        "objects[0].path",
        &["absolute"],
    );
    check_bad(&dir, "texdotdot.toml", &format!("{spot}texture = \"../gobo.png\"\n"), "light.texture", &[]);
    check_bad(&dir, "texmissing.toml", &format!("{spot}texture = \"gobo.png\"\n"), "light.texture", &["not found"]);
    write(&dir, "notimage.png", "this is not a png");
    check_bad(&dir, "texbad.toml", &format!("{spot}texture = \"notimage.png\"\n"), "light.texture", &[]);
    check_bad(&dir, "pathonbox.toml", "[[objects]]\nkind = \"box\"\npath = \"ok.obj\"\n", "objects[0].path", &[]);
    // A mesh that fails to import names the scene file, the key and the mesh file.
    write(&dir, "broken.obj", "v 0 0 0\nv 1 0 0\nf 1 2 7\n");
    check_bad(
        &dir,
        "broken_mesh.toml",
        "[[objects]]\nkind = \"mesh\"\npath = \"broken.obj\"\n",
        "objects[0].path",
        &["broken.obj"],
    );
}

#[cfg(unix)]
#[test]
fn symlinks_out_of_the_scene_directory_are_rejected() {
    let outside = temp_dir("outside");
    let target = write(&outside, "secret.obj", CUBE_OBJ);
    let dir = temp_dir("symlink");
    std::os::unix::fs::symlink(&target, dir.join("link.obj")).unwrap();
    check_bad(
        &dir,
        "symlink.toml",
        "[[objects]]\nkind = \"mesh\"\npath = \"link.obj\"\n",
        "objects[0].path",
        &["outside"],
    );
    // A link inside the directory is fine.
    write(&dir, "real.obj", CUBE_OBJ);
    std::os::unix::fs::symlink(dir.join("real.obj"), dir.join("inside.obj")).unwrap();
    let p = write(&dir, "ok.toml", "[[objects]]\nkind = \"mesh\"\npath = \"inside.obj\"\n");
    assert_eq!(load_scene_file(&p).unwrap().geometry.triangle_count(), 12);
}

#[test]
fn unreadable_scene_file_is_an_error() {
    let dir = temp_dir("unreadable");
    let e = load_scene_file(&dir.join("absent.toml")).unwrap_err();
    assert!(matches!(e, SceneError::Io { .. }));
    assert!(e.to_string().contains("absent.toml"));
    let p = write(&dir, "binary.toml", [0xffu8, 0xfe, 0x00, 0x41]);
    let e = load_scene_file(&p).unwrap_err().to_string();
    assert!(e.contains("binary.toml") && !e.contains('\n'), "{e}");
    assert!(load_scene_file(&dir).is_err());
}

#[test]
fn parse_errors_carry_line_and_column() {
    let e = parse_scene_str("\n\n[medium]\n  scatterin = 0.1\n", "x/y.toml", Path::new(".")).unwrap_err();
    match &e {
        SceneError::Syntax { file, line, column, key, .. } => {
            assert_eq!(file, "x/y.toml");
            assert_eq!(*line, 4);
            assert_eq!(*column, 3);
            assert_eq!(key, "medium.scatterin");
        }
        other => panic!("{other:?}"),
    }
    assert!(e.to_string().starts_with("x/y.toml:4:3: medium.scatterin: unknown field `scatterin`"), "{e}");
    let e = parse_scene_str("[medium]\nscattering = [-1, 0, 0]\n", "scenes/x.toml", Path::new(".")).unwrap_err();
    assert_eq!(e.to_string(), "scenes/x.toml: medium.scattering[0] = -1: coefficients must be ≥ 0 and finite");
}

// ---------------------------------------------------------------------------------------------
// Mesh import.

#[test]
fn obj_imports_with_the_right_triangle_count() {
    let dir = temp_dir("obj");
    let p = write(&dir, "cube.obj", CUBE_OBJ);
    let g = load_mesh(&p, &Transform::default(), None).unwrap();
    assert_eq!(g.triangle_count(), 12);
    // Flat normals are unit and point outward.
    for t in g.indices.chunks_exact(3) {
        let v = &g.vertices[t[0] as usize];
        let n = Vec3::from(v.normal);
        assert!((n.length() - 1.0).abs() < 1e-5);
        let c = (0..3).map(|k| Vec3::from(g.vertices[t[k] as usize].position)).sum::<Vec3>() / 3.0;
        assert!(n.dot(c) > 0.0, "normal {n} at {c} points inward");
    }
    // Transform and albedo.
    let t = Transform { translate: Vec3::new(10.0, 0.0, 0.0), rotate_degrees: Vec3::ZERO, scale: Vec3::splat(2.0) };
    let g = load_mesh(&p, &t, Some(Vec3::new(0.2, 0.3, 0.4))).unwrap();
    let b = g.bounds();
    assert!(
        (b.min - Vec3::new(9.0, -1.0, -1.0)).length() < 1e-5 && (b.max - Vec3::new(11.0, 1.0, 1.0)).length() < 1e-5
    );
    assert!(g.vertices.iter().all(|v| v.albedo == [0.2, 0.3, 0.4]));

    // With normals, a material, and a zero-area triangle that is dropped.
    write(&dir, "m.mtl", "newmtl red\nKd 0.8 0.1 0.1\n");
    let p = write(
        &dir,
        "n.obj",
        "mtllib m.mtl\nusemtl red\nv 0 0 0\nv 1 0 0\nv 0 0 1\nv 2 0 0\nvn 0 1 0\nf 1//1 3//1 2//1\nf 1//1 2//1 4//1\n",
    );
    let g = load_mesh(&p, &Transform::default(), None).unwrap();
    assert_eq!(g.triangle_count(), 1);
    assert_eq!(g.vertices[g.indices[0] as usize].normal, [0.0, 1.0, 0.0]);
    assert_eq!(g.vertices[g.indices[0] as usize].albedo, [0.8, 0.1, 0.1]);
    // A material library outside the mesh's directory is ignored (default albedo), not read.
    let sub = dir.join("sub");
    std::fs::create_dir_all(&sub).unwrap();
    let p = write(&sub, "escape.obj", "mtllib ../m.mtl\nusemtl red\nv 0 0 0\nv 1 0 0\nv 0 0 1\nf 1 3 2\n");
    let g = load_mesh(&p, &Transform::default(), None).unwrap();
    assert_eq!(g.triangle_count(), 1);
    assert_eq!(g.vertices[0].albedo, [0.7; 3]);
}

#[test]
fn bad_obj_files_error_instead_of_panicking() {
    let dir = temp_dir("badobj");
    let cases: &[(&str, &str)] = &[
        ("oob.obj", "v 0 0 0\nv 1 0 0\nf 1 2 3\n"),
        ("truncated.obj", &CUBE_OBJ[..CUBE_OBJ.len() / 2 + 7]),
        ("garbage.obj", "v 0 0 zero\nf 1 1 1\n"),
        ("nan.obj", "v nan 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n"),
        ("inf.obj", "v 0 0 0\nv 1 0 0\nv 0 inf 0\nf 1 2 3\n"),
        ("neg.obj", "v 0 0 0\nv 1 0 0\nf -1 -2 -5\n"),
    ];
    for (name, text) in cases {
        let p = write(&dir, name, text);
        match load_mesh(&p, &Transform::default(), None) {
            Ok(g) => {
                // A truncated file may still be a valid, smaller mesh; it must be consistent.
                assert!(g.indices.iter().all(|&i| (i as usize) < g.vertices.len()), "{name}");
                assert_ne!(*name, "oob.obj");
                assert_ne!(*name, "nan.obj");
                assert_ne!(*name, "inf.obj");
            }
            Err(e) => {
                let m = e.to_string();
                assert!(m.contains(name) && !m.contains('\n'), "{m}");
            }
        }
    }
    assert!(load_mesh(&dir.join("absent.obj"), &Transform::default(), None).is_err());
    let p = write(&dir, "x.ply", "ply\n");
    assert!(load_mesh(&p, &Transform::default(), None).unwrap_err().to_string().contains("x.ply"));
}

fn base64(data: &[u8]) -> String {
    const A: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut s = String::new();
    for c in data.chunks(3) {
        let b = [c[0], *c.get(1).unwrap_or(&0), *c.get(2).unwrap_or(&0)];
        let n = (b[0] as u32) << 16 | (b[1] as u32) << 8 | b[2] as u32;
        for k in 0..4 {
            if k <= c.len() {
                s.push(A[(n >> (18 - 6 * k) & 63) as usize] as char);
            } else {
                s.push('=');
            }
        }
    }
    s
}

fn f32_bytes(v: &[f32]) -> Vec<u8> {
    v.iter().flat_map(|f| f.to_le_bytes()).collect()
}

/// A glTF with one triangle (no normals, no indices) under a translated parent node.
fn one_triangle_gltf(buffer_len: usize, count: usize) -> String {
    let data = f32_bytes(&[0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0]);
    format!(
        r#"{{
  "asset": {{ "version": "2.0" }},
  "scene": 0,
  "scenes": [ {{ "nodes": [0] }} ],
  "nodes": [ {{ "translation": [0, 0, 5], "children": [1] }}, {{ "mesh": 0, "scale": [2, 2, 2] }} ],
  "meshes": [ {{ "primitives": [ {{ "attributes": {{ "POSITION": 0 }}, "material": 0 }} ] }} ],
  "materials": [ {{ "pbrMetallicRoughness": {{ "baseColorFactor": [0.9, 0.2, 0.1, 1.0] }} }} ],
  "accessors": [ {{ "bufferView": 0, "componentType": 5126, "count": {count}, "type": "VEC3",
                   "min": [0, 0, 0], "max": [1, 1, 0] }} ],
  "bufferViews": [ {{ "buffer": 0, "byteOffset": 0, "byteLength": 36 }} ],
  "buffers": [ {{ "byteLength": {buffer_len}, "uri": "data:application/octet-stream;base64,{}" }} ]
}}"#,
        base64(&data)
    )
}

#[test]
fn gltf_imports_with_the_right_triangle_count() {
    let dir = temp_dir("gltf");
    let p = write(&dir, "tri.gltf", one_triangle_gltf(36, 3));
    let g = load_mesh(&p, &Transform::default(), None).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(g.triangle_count(), 1);
    // Node transforms: scale 2 then translate z by 5.
    let ps: Vec<Vec3> = g.indices.iter().map(|&i| Vec3::from(g.vertices[i as usize].position)).collect();
    assert!(ps.contains(&Vec3::new(2.0, 0.0, 5.0)) && ps.contains(&Vec3::new(0.0, 2.0, 5.0)), "{ps:?}");
    // Flat normal computed: +Z (counter-clockwise in XY).
    assert_eq!(g.vertices[0].normal, [0.0, 0.0, 1.0]);
    // Material base colour as albedo when the object gives none.
    assert_eq!(g.vertices[0].albedo, [0.9, 0.2, 0.1]);
    let g = load_mesh(&p, &Transform::at(Vec3::new(1.0, 0.0, 0.0)), Some(Vec3::splat(0.5))).unwrap();
    assert_eq!(g.vertices[0].albedo, [0.5; 3]);
    assert!(g.vertices.iter().any(|v| v.position == [3.0, 0.0, 5.0]));

    // The same as GLB with indices and normals in the binary chunk.
    let mut bin = f32_bytes(&[0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 1.0, 1.0, 0.0]);
    bin.extend(f32_bytes(&[0.0, 0.0, 1.0].repeat(4)));
    for i in [0u16, 1, 2, 2, 1, 3] {
        bin.extend(i.to_le_bytes());
    }
    while !bin.len().is_multiple_of(4) {
        bin.push(0);
    }
    let json = format!(
        r#"{{"asset":{{"version":"2.0"}},"scenes":[{{"nodes":[0]}}],"nodes":[{{"mesh":0}}],
"meshes":[{{"primitives":[{{"attributes":{{"POSITION":0,"NORMAL":1}},"indices":2}}]}}],
"accessors":[{{"bufferView":0,"componentType":5126,"count":4,"type":"VEC3","min":[0,0,0],"max":[1,1,0]}},
{{"bufferView":1,"componentType":5126,"count":4,"type":"VEC3"}},
{{"bufferView":2,"componentType":5123,"count":6,"type":"SCALAR"}}],
"bufferViews":[{{"buffer":0,"byteOffset":0,"byteLength":48}},{{"buffer":0,"byteOffset":48,"byteLength":48}},
{{"buffer":0,"byteOffset":96,"byteLength":12}}],
"buffers":[{{"byteLength":{}}}]}}"#,
        bin.len()
    );
    let mut json = json.into_bytes();
    while !json.len().is_multiple_of(4) {
        json.push(b' ');
    }
    let total = 12 + 8 + json.len() + 8 + bin.len();
    let mut glb = Vec::new();
    glb.extend(b"glTF");
    glb.extend(2u32.to_le_bytes());
    glb.extend((total as u32).to_le_bytes());
    glb.extend((json.len() as u32).to_le_bytes());
    glb.extend(b"JSON");
    glb.extend(&json);
    glb.extend((bin.len() as u32).to_le_bytes());
    glb.extend(b"BIN\0");
    glb.extend(&bin);
    let p = write(&dir, "quad.glb", &glb);
    let g = load_mesh(&p, &Transform::default(), None).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(g.triangle_count(), 2);
    assert_eq!(g.vertices.len(), 4);
    assert!(g.vertices.iter().all(|v| v.normal == [0.0, 0.0, 1.0] && v.albedo == [0.7; 3]));

    // Truncated GLB files error.
    for cut in [4, 12, 20, 40, glb.len() - 10] {
        let p = write(&dir, "cut.glb", &glb[..cut]);
        let e = load_mesh(&p, &Transform::default(), None).expect_err("truncated glb");
        assert!(e.to_string().contains("cut.glb") && !e.to_string().contains('\n'), "{e}");
    }

    // In a scene file.
    let p = write(&dir, "scene.toml", "[[objects]]\nkind = \"mesh\"\npath = \"tri.gltf\"\n");
    assert_eq!(load_scene_file(&p).unwrap().geometry.triangle_count(), 1);
}

#[test]
fn bad_gltf_files_error_instead_of_panicking() {
    let dir = temp_dir("badgltf");
    let good = one_triangle_gltf(36, 3);
    let cases: Vec<(&str, String)> = vec![
        ("truncated.gltf", good[..good.len() / 2].to_string()),
        ("empty.gltf", String::new()),
        ("short_buffer.gltf", one_triangle_gltf(400, 3)),
        ("count_too_big.gltf", one_triangle_gltf(36, 300)),
        ("count_zero.gltf", one_triangle_gltf(36, 0)),
        ("escape.gltf", good.replace("data:application/octet-stream;base64,", "../secret.bin#")),
        ("absolute.gltf", good.replace("data:application/octet-stream;base64,", "/etc/")),
        ("missing_buffer.gltf", good.replace("data:application/octet-stream;base64,", "nope.bin?")),
        ("bad_node.gltf", good.replace("\"children\": [1]", "\"children\": [7]")),
        ("cycle.gltf", good.replace("{ \"mesh\": 0, \"scale\": [2, 2, 2] }", "{ \"mesh\": 0, \"children\": [0] }")),
        ("escape_encoded.gltf", good.replace("data:application/octet-stream;base64,", "%2e%2e%2Fsecret.bin#")),
        ("escape_encoded2.gltf", good.replace("data:application/octet-stream;base64,", "sub/..%2F..%2Fsecret.bin#")),
        ("file_scheme.gltf", good.replace("data:application/octet-stream;base64,", "file:///etc/")),
        ("nan.gltf", good.replace("\"translation\": [0, 0, 5]", "\"matrix\": [0,0,0,0, 0,0,0,0, 0,0,0,0, 0,0,0,1]")),
    ];
    for (name, text) in &cases {
        let p = write(&dir, name, text);
        let r = load_mesh(&p, &Transform::default(), None);
        match (*name, r) {
            // An accessor with count 0 holds no triangles: empty but fine.
            ("count_zero.gltf", Ok(g)) => assert_eq!(g.triangle_count(), 0),
            // A singular node matrix collapses the triangle: dropped, not an error.
            ("nan.gltf", Ok(g)) => assert_eq!(g.triangle_count(), 0),
            (_, Ok(g)) => panic!("{name}: expected an error, got {} triangles", g.triangle_count()),
            (_, Err(e)) => {
                let m = e.to_string();
                assert!(m.contains(*name) && !m.contains('\n'), "{m}");
            }
        }
    }
}

#[test]
fn gltf_buffers_cannot_leave_the_directory_through_links_or_grow_without_bound() {
    let outside = temp_dir("gltf-outside");
    write(&outside, "secret.bin", f32_bytes(&[0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0]));
    let dir = temp_dir("gltf-link");
    let good = one_triangle_gltf(36, 3);
    #[cfg(unix)]
    {
        std::os::unix::fs::symlink(outside.join("secret.bin"), dir.join("link.bin")).unwrap();
        let linked = good.replace("data:application/octet-stream;base64,", "link.bin#");
        let linked = linked.split('#').next().unwrap().to_string() + "\" }\n  ]\n}";
        let p = write(&dir, "linked.gltf", &linked);
        let m = load_mesh(&p, &Transform::default(), None).expect_err("a link out of the directory").to_string();
        assert!(m.contains("linked.gltf") && m.contains("outside"), "{m}");
    }
    // A data: URI over the limit is refused before it is decoded.
    let huge =
        one_triangle_gltf(36, 3).replace(";base64,", &format!(";base64,{}", "A".repeat(mesh::MAX_DATA_URI_BYTES)));
    let p = write(&dir, "huge.gltf", &huge);
    let m = load_mesh(&p, &Transform::default(), None).expect_err("an oversized data: URI").to_string();
    assert!(m.contains("huge.gltf") && m.contains("limit"), "{m}");
}

#[test]
fn primitives_have_unit_normals_and_expected_sizes() {
    let t = Transform::default();
    let a = Vec3::splat(0.5);
    for (name, g, tris) in [
        ("plane", mesh::plane(&t, a), 2),
        ("cuboid", mesh::cuboid(&t, a), 12),
        ("sphere", mesh::sphere(&t, a), 24 * 16 * 2 - 2 * 24),
        ("cylinder", mesh::cylinder(&t, a), 24 * 4),
    ] {
        assert_eq!(g.triangle_count(), tris, "{name}");
        let b = g.bounds();
        assert!((b.max.x - 0.5).abs() < 1e-5 && (b.min.x + 0.5).abs() < 1e-5, "{name}");
        for tri in g.indices.chunks_exact(3) {
            let p: Vec<Vec3> = tri.iter().map(|&i| Vec3::from(g.vertices[i as usize].position)).collect();
            let face = (p[1] - p[0]).cross(p[2] - p[0]);
            assert!(face.length() > 0.0, "{name}: degenerate triangle");
            let n = Vec3::from(g.vertices[tri[0] as usize].normal);
            assert!((n.length() - 1.0).abs() < 1e-5, "{name}");
            // Winding agrees with the normal (counter-clockwise front faces).
            assert!(face.dot(n) > 0.0, "{name}: winding disagrees with the normal");
        }
    }
    // Rotation order X then Y then Z; mirroring keeps winding consistent.
    let t = Transform { translate: Vec3::ZERO, rotate_degrees: Vec3::new(90.0, 0.0, 0.0), scale: Vec3::ONE };
    let g = mesh::plane(&t, a);
    assert!((Vec3::from(g.vertices[0].normal) - Vec3::Z).length() < 1e-5);
    let t = Transform { translate: Vec3::ZERO, rotate_degrees: Vec3::new(90.0, 90.0, 0.0), scale: Vec3::ONE };
    let g = mesh::plane(&t, a);
    assert!((Vec3::from(g.vertices[0].normal) - Vec3::X).length() < 1e-5, "{:?}", g.vertices[0].normal);
    let t = Transform { translate: Vec3::ZERO, rotate_degrees: Vec3::ZERO, scale: Vec3::new(-1.0, 2.0, 3.0) };
    let g = mesh::cuboid(&t, a);
    for tri in g.indices.chunks_exact(3) {
        let p: Vec<Vec3> = tri.iter().map(|&i| Vec3::from(g.vertices[i as usize].position)).collect();
        let n = Vec3::from(g.vertices[tri[0] as usize].normal);
        assert!((p[1] - p[0]).cross(p[2] - p[0]).dot(n) > 0.0);
        assert!(n.dot((p[0] + p[1] + p[2]) / 3.0) > 0.0, "mirrored cube normal points inward");
    }
}

// ---------------------------------------------------------------------------------------------
// Fuzzing (proptest-driven): mutated scene files and meshes load or fail with one line naming
// the file; they never panic. Seeds: the documented example scene, the cube OBJ, the
// one-triangle glTF. Cases proptest finds are kept in proptest-regressions/ and rerun first.

mod fuzz {
    use super::*;
    use proptest::prelude::*;

    /// Fragments that break TOML, numbers, paths and meshes in interesting ways.
    const TOKENS: &[&str] = &[
        "=",
        "[",
        "]",
        "{",
        "}",
        "\"",
        "\n",
        ",",
        "nan",
        "-inf",
        "inf",
        "1e39",
        "-1",
        "0",
        "-0.0",
        "..",
        "/etc/passwd",
        "../x.obj",
        "[render]",
        "[[objects]]",
        "kind = \"mesh\"",
        "path = \"../../etc/passwd\"",
        "\u{0}",
        "é",
        "true",
        "[1,2]",
        "99999999999999999999",
        "v",
        "f",
        "vn 0 0 0",
        "mtllib ../../x.mtl",
        "f 1 2 99999",
        "f -9 -8 -7",
        "/",
        "\"uri\": \"../secret.bin\"",
        "\"count\": 4294967295",
        "\"byteLength\": 0",
        "null",
        "\"componentType\": 5121",
    ];

    #[derive(Clone, Debug)]
    enum Edit {
        Delete(usize, usize),
        Insert(usize, usize),
        Truncate(usize),
        Flip(usize, u8),
    }

    fn edit() -> impl Strategy<Value = Edit> {
        prop_oneof![
            (any::<usize>(), 1usize..40).prop_map(|(p, n)| Edit::Delete(p, n)),
            (any::<usize>(), 0..TOKENS.len()).prop_map(|(p, t)| Edit::Insert(p, t)),
            any::<usize>().prop_map(Edit::Truncate),
            (any::<usize>(), any::<u8>()).prop_map(|(p, b)| Edit::Flip(p, b)),
        ]
    }

    /// Applies the edits to the bytes of `seed` (byte flips may leave invalid UTF-8).
    fn mutate(seed: &str, edits: &[Edit]) -> Vec<u8> {
        let mut b = seed.as_bytes().to_vec();
        for e in edits {
            let at = |p: usize, b: &Vec<u8>| if b.is_empty() { 0 } else { p % (b.len() + 1) };
            match *e {
                Edit::Delete(p, n) => {
                    let s = at(p, &b);
                    b.drain(s..(s + n).min(b.len()));
                }
                Edit::Insert(p, t) => {
                    let s = at(p, &b);
                    b.splice(s..s, TOKENS[t].bytes());
                }
                Edit::Truncate(p) => {
                    let s = at(p, &b);
                    b.truncate(s);
                }
                Edit::Flip(p, v) => {
                    if !b.is_empty() {
                        let s = p % b.len();
                        b[s] ^= v;
                    }
                }
            }
        }
        b
    }

    fn one_line_naming(message: &str, name: &str) {
        assert!(!message.contains('\n'), "error spans lines: {message}");
        assert!(message.contains(name), "error does not name {name}: {message}");
    }

    proptest! {
        #![proptest_config(ProptestConfig { cases: 300, failure_persistence: None, ..ProptestConfig::default() })]

        #[test]
        fn mutated_scene_files_never_panic(edits in proptest::collection::vec(edit(), 1..6)) {
            let dir = temp_dir("fuzz-scene");
            write(&dir, "column.obj", CUBE_OBJ);
            write_png(&dir, "gobo.png");
            let bytes = mutate(&documented_example(), &edits);
            let p = write(&dir, "fuzz.toml", &bytes);
            if let Err(e) = load_scene_file(&p) {
                one_line_naming(&e.to_string(), "fuzz.toml");
            }
            let _ = std::fs::remove_dir_all(&dir);
        }

        #[test]
        fn mutated_obj_files_never_panic(edits in proptest::collection::vec(edit(), 1..6)) {
            let dir = temp_dir("fuzz-obj");
            let p = write(&dir, "fuzz.obj", mutate(CUBE_OBJ, &edits));
            if let Err(e) = load_mesh(&p, &Transform::default(), None) {
                one_line_naming(&e.to_string(), "fuzz.obj");
            }
            let _ = std::fs::remove_dir_all(&dir);
        }

        #[test]
        fn mutated_gltf_files_never_panic(edits in proptest::collection::vec(edit(), 1..6)) {
            let dir = temp_dir("fuzz-gltf");
            let p = write(&dir, "fuzz.gltf", mutate(&one_triangle_gltf(36, 3), &edits));
            if let Err(e) = load_mesh(&p, &Transform::default(), None) {
                one_line_naming(&e.to_string(), "fuzz.gltf");
            }
            let _ = std::fs::remove_dir_all(&dir);
        }
    }
}
