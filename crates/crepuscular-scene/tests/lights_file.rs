//! Scene files with several lights: `[[lights]]` tables (any mix of kinds, each with its own
//! `scattering`), the old `[light]` table read as one light, and errors naming the light.

use crepuscular::Light;
use crepuscular_scene::file::{SceneError, parse_scene_str};
use glam::Vec3;
use std::path::Path;

fn parse(text: &str) -> Result<crepuscular_scene::Scene, SceneError> {
    parse_scene_str(text, "lights.toml", Path::new("."))
}

/// (key, value, message) of an invalid scene file.
fn invalid(text: &str) -> (String, String, String) {
    match parse(text) {
        Err(SceneError::Invalid { key, value, message, .. }) => (key, value, message),
        other => panic!("expected an invalid-value error, got {other:?}"),
    }
}

#[test]
fn lights_tables_give_every_light_in_order() {
    let s = parse(
        r#"
[[lights]]
kind = "directional"
direction = [0.0, -1.0, 0.0]
intensity = 2.0

[[lights]]
kind = "spot"
position = [0.0, 4.0, 0.0]
direction = [0.0, -1.0, 0.0]
outer_angle_degrees = 30.0
scattering = 0.5

[[lights]]
kind = "point"
position = [1.0, 2.0, 3.0]
intensity = 40.0
scattering = 0.0
"#,
    )
    .unwrap();
    assert_eq!(s.lights.len(), 3);
    assert!(matches!(s.lights[0].light, Light::Directional { intensity, .. } if intensity == 2.0));
    assert!(matches!(s.lights[1].light, Light::Spot { outer_angle_degrees, .. } if outer_angle_degrees == 30.0));
    assert!(matches!(s.lights[2].light, Light::Point { position, .. } if position == Vec3::new(1.0, 2.0, 3.0)));
    assert_eq!(s.lights.iter().map(|l| l.scattering).collect::<Vec<_>>(), vec![1.0, 0.5, 0.0]);
    // The frame packs their shadow maps: one layer, one layer, six cube faces.
    let d = s.frame_desc().unwrap();
    assert_eq!(
        d.lights.iter().map(|l| (l.shadow_layer, l.shadow.layers)).collect::<Vec<_>>(),
        vec![(0, 1), (1, 1), (2, 6)]
    );
    assert_eq!(d.lights.iter().map(|l| l.scattering).collect::<Vec<_>>(), vec![1.0, 0.5, 0.0]);
}

#[test]
fn the_old_light_table_is_one_light() {
    let s = parse("[light]\nkind = \"point\"\nposition = [0.0, 3.0, 0.0]\nintensity = 60.0\n").unwrap();
    assert_eq!(s.lights.len(), 1);
    assert!(matches!(s.lights[0].light, Light::Point { intensity, .. } if intensity == 60.0));
    assert_eq!(s.lights[0].scattering, 1.0);
    // No light at all: the default sun, as before.
    let s = parse("").unwrap();
    assert!(matches!(s.lights[..], [ref l] if matches!(l.light, Light::Directional { .. })));
}

#[test]
fn bad_light_lists_name_the_light_and_key() {
    let (k, _, m) =
        invalid("[light]\nkind = \"point\"\nposition = [0.0, 3.0, 0.0]\n[[lights]]\nkind = \"directional\"\n");
    assert_eq!(k, "lights");
    assert!(m.contains("either"), "{m}");
    let (k, v, _) = invalid("lights = []\n");
    assert_eq!((k.as_str(), v.as_str()), ("lights", "[]"));
    let (k, _, m) = invalid("[[lights]]\nkind = \"directional\"\n[[lights]]\nkind = \"point\"\n");
    assert_eq!(k, "lights[1].position");
    assert!(m.contains("required for a point light"), "{m}");
    let (k, v, _) = invalid("[[lights]]\nkind = \"directional\"\nscattering = -1.0\n");
    assert_eq!((k.as_str(), v.as_str()), ("lights[0].scattering", "-1"));
    let (k, _, m) = invalid(
        "[[lights]]\nkind = \"spot\"\nposition = [0.0, 1.0, 0.0]\ndirection = [0.0, -1.0, 0.0]\nouter_angle_degrees = 10.0\ninner_angle_degrees = 20.0\n",
    );
    assert_eq!(k, "lights[0].inner_angle_degrees");
    assert!(m.contains("lights[0].outer_angle_degrees"), "{m}");
    let many = "[[lights]]\nkind = \"directional\"\n".repeat(crepuscular::MAX_LIGHTS + 1);
    let (k, _, m) = invalid(&many);
    assert_eq!(k, format!("lights[{}]", crepuscular::MAX_LIGHTS));
    assert!(m.contains("at most"), "{m}");
}
