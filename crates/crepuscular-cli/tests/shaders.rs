//! Every WGSL shader validates with naga (no GPU needed), and the Rust uniform structs match
//! naga's layout of their WGSL twins field by field.

use crepuscular::FrameUniforms;
use std::mem::offset_of;

fn parse(name: &str, src: &str) -> naga::Module {
    let module = naga::front::wgsl::parse_str(src).unwrap_or_else(|e| panic!("{name}: {}", e.emit_to_string(src)));
    naga::valid::Validator::new(naga::valid::ValidationFlags::all(), naga::valid::Capabilities::empty())
        .validate(&module)
        .unwrap_or_else(|e| panic!("{name}: {e:?}"));
    module
}

fn all_shaders() -> Vec<(String, String)> {
    let mut v: Vec<(String, String)> =
        crepuscular::shaders::all_library_shaders().into_iter().map(|(n, s)| (n.to_string(), s)).collect();
    v.push(("host/shadow_depth".into(), crepuscular_scene::host::SHADOW_DEPTH_WGSL.into()));
    v.push(("host/surface".into(), crepuscular::shaders::compose(crepuscular_scene::host::SURFACE_WGSL)));
    v
}

#[test]
fn every_shader_validates_with_naga() {
    for (name, src) in all_shaders() {
        parse(&name, &src);
    }
}

fn struct_members(module: &naga::Module, name: &str) -> (Vec<(String, u32)>, u32) {
    for (_, ty) in module.types.iter() {
        if ty.name.as_deref() == Some(name) {
            if let naga::TypeInner::Struct { members, span } = &ty.inner {
                return (members.iter().map(|m| (m.name.clone().unwrap_or_default(), m.offset)).collect(), *span);
            }
        }
    }
    panic!("struct {name} not found");
}

#[test]
fn frame_uniforms_match_the_wgsl_layout() {
    let module = parse("common", &crepuscular::shaders::compose(crepuscular::techniques::brute_force::MARCH_WGSL));
    let (members, span) = struct_members(&module, "Frame");
    let rust = [
        ("inv_view_proj", offset_of!(FrameUniforms, inv_view_proj)),
        ("view_proj", offset_of!(FrameUniforms, view_proj)),
        ("shadow_view_proj", offset_of!(FrameUniforms, shadow_view_proj)),
        ("camera_pos", offset_of!(FrameUniforms, camera_pos)),
        ("camera_fwd", offset_of!(FrameUniforms, camera_fwd)),
        ("light_pos", offset_of!(FrameUniforms, light_pos)),
        ("light_dir", offset_of!(FrameUniforms, light_dir)),
        ("light_color", offset_of!(FrameUniforms, light_color)),
        ("sigma_s", offset_of!(FrameUniforms, sigma_s)),
        ("sigma_a", offset_of!(FrameUniforms, sigma_a)),
        ("rayleigh_fraction", offset_of!(FrameUniforms, rayleigh_fraction)),
        ("shadow_params", offset_of!(FrameUniforms, shadow_params)),
        ("ambient", offset_of!(FrameUniforms, ambient)),
        ("ints", offset_of!(FrameUniforms, ints)),
        ("shadow_ints", offset_of!(FrameUniforms, shadow_ints)),
    ];
    assert_eq!(members.len(), rust.len(), "field count");
    for ((wn, wo), (rn, ro)) in members.iter().zip(rust) {
        assert_eq!(wn, rn);
        assert_eq!(*wo as usize, ro, "offset of {rn}");
    }
    assert_eq!(span as usize, std::mem::size_of::<FrameUniforms>());
}

/// Checks a pass's `Params` uniform block against its Rust twin: member names, offsets, size.
pub fn check_params(wgsl: &str, rust: &[(&str, usize)], size: usize) {
    let module = parse("params", &crepuscular::shaders::compose(wgsl));
    let (members, span) = struct_members(&module, "Params");
    let named: Vec<_> = members.iter().filter(|(n, _)| !n.starts_with("_pad")).collect();
    assert_eq!(named.len(), rust.len(), "Params field count: {members:?}");
    for ((wn, wo), (rn, ro)) in named.iter().zip(rust) {
        assert_eq!(wn, rn);
        assert_eq!(*wo as usize, *ro, "offset of {rn}");
    }
    assert_eq!(span as usize, size);
}

#[test]
fn pass_params_match_the_wgsl_layout() {
    use crepuscular::techniques::brute_force::{MARCH_WGSL, MarchParams};
    check_params(
        MARCH_WGSL,
        &[
            ("steps", offset_of!(MarchParams, steps)),
            ("jitter", offset_of!(MarchParams, jitter)),
            ("frame_index", offset_of!(MarchParams, frame_index)),
            ("spot_steps", offset_of!(MarchParams, spot_steps)),
            ("spot_denominator", offset_of!(MarchParams, spot_denominator)),
        ],
        std::mem::size_of::<MarchParams>(),
    );
}
