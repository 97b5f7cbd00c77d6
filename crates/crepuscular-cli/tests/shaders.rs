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

/// Checks the WGSL struct `name` against its Rust twin's member offsets and size.
fn check_struct(module: &naga::Module, name: &str, rust: &[(&str, usize)], size: usize) {
    let (members, span) = struct_members(module, name);
    assert_eq!(members.len(), rust.len(), "{name}: field count");
    for ((wn, wo), (rn, ro)) in members.iter().zip(rust) {
        assert_eq!(wn, rn, "{name}");
        assert_eq!(*wo as usize, *ro, "{name}: offset of {rn}");
    }
    assert_eq!(span as usize, size, "{name}: size");
}

#[test]
fn frame_uniforms_match_the_wgsl_layout() {
    use crepuscular::{LightUniforms, LightsUniforms};
    let module = parse("common", &crepuscular::shaders::compose(crepuscular::techniques::brute_force::MARCH_WGSL));
    check_struct(
        &module,
        "Frame",
        &[
            ("inv_view_proj", offset_of!(FrameUniforms, inv_view_proj)),
            ("inv_projection", offset_of!(FrameUniforms, inv_projection)),
            ("inv_view", offset_of!(FrameUniforms, inv_view)),
            ("view_proj", offset_of!(FrameUniforms, view_proj)),
            ("camera_pos", offset_of!(FrameUniforms, camera_pos)),
            ("camera_fwd", offset_of!(FrameUniforms, camera_fwd)),
            ("sigma_s", offset_of!(FrameUniforms, sigma_s)),
            ("sigma_a", offset_of!(FrameUniforms, sigma_a)),
            ("rayleigh_fraction", offset_of!(FrameUniforms, rayleigh_fraction)),
            ("depth_params", offset_of!(FrameUniforms, depth_params)),
            ("width", offset_of!(FrameUniforms, width)),
            ("height", offset_of!(FrameUniforms, height)),
            ("phase_kind", offset_of!(FrameUniforms, phase_kind)),
            ("_pad", offset_of!(FrameUniforms, _pad)),
        ],
        std::mem::size_of::<FrameUniforms>(),
    );
    check_struct(
        &module,
        "Light",
        &[
            ("shadow_view_proj", offset_of!(LightUniforms, shadow_view_proj)),
            ("position", offset_of!(LightUniforms, position)),
            ("direction", offset_of!(LightUniforms, direction)),
            ("color", offset_of!(LightUniforms, color)),
            ("shadow_near", offset_of!(LightUniforms, shadow_near)),
            ("shadow_far", offset_of!(LightUniforms, shadow_far)),
            ("shadow_bias", offset_of!(LightUniforms, shadow_bias)),
            ("shadow_texel", offset_of!(LightUniforms, shadow_texel)),
            ("kind", offset_of!(LightUniforms, kind)),
            ("shadow_layers", offset_of!(LightUniforms, shadow_layers)),
            ("shadow_size", offset_of!(LightUniforms, shadow_size)),
            ("shadow_orthographic", offset_of!(LightUniforms, shadow_orthographic)),
            ("shadow_first_layer", offset_of!(LightUniforms, shadow_first_layer)),
            ("shadow_clear", offset_of!(LightUniforms, shadow_clear)),
            ("texture_layer", offset_of!(LightUniforms, texture_layer)),
            ("slot", offset_of!(LightUniforms, slot)),
            ("texture_size", offset_of!(LightUniforms, texture_size)),
            ("shadow_filter", offset_of!(LightUniforms, shadow_filter)),
            ("_pad1", offset_of!(LightUniforms, _pad1)),
        ],
        std::mem::size_of::<LightUniforms>(),
    );
    check_struct(
        &module,
        "Lights",
        &[
            ("count", offset_of!(LightsUniforms, count)),
            ("_pad0", offset_of!(LightsUniforms, _pad)),
            ("_pad1", offset_of!(LightsUniforms, _pad) + 4),
            ("_pad2", offset_of!(LightsUniforms, _pad) + 8),
            ("items", offset_of!(LightsUniforms, items)),
        ],
        std::mem::size_of::<LightsUniforms>(),
    );
}

/// Checks a pass's `Params` uniform block against its Rust twin: member names, offsets, size
/// (a multiple of 16 bytes); and that the shader has the entry point `entry`.
pub fn check_params(name: &str, wgsl: &str, entry: &str, rust: &[(&str, usize)], size: usize) {
    let module = parse(name, &crepuscular::shaders::compose(wgsl));
    assert!(module.entry_points.iter().any(|e| e.name == entry), "{name}: no entry point {entry}");
    let (members, span) = struct_members(&module, "Params");
    let named: Vec<_> = members.iter().filter(|(n, _)| !n.starts_with("_pad")).collect();
    assert_eq!(named.len(), rust.len(), "{name}: Params field count: {members:?}");
    for ((wn, wo), (rn, ro)) in named.iter().zip(rust) {
        assert_eq!(wn, rn, "{name}");
        assert_eq!(*wo as usize, *ro, "{name}: offset of {rn}");
    }
    assert_eq!(span as usize, size, "{name}: Params size");
    assert_eq!(size % 16, 0, "{name}: Params size");
}

#[test]
fn pass_params_match_the_wgsl_layout() {
    use crepuscular::techniques::brute_force::{MARCH_WGSL, MarchParams};
    check_params(
        "brute_force/march",
        MARCH_WGSL,
        "march",
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

#[test]
fn interleaved_params_match_the_wgsl_layout_in_every_pass() {
    use crepuscular::techniques::interleaved::{InterleavedParams, SHADERS};
    let rust = [
        ("block", offset_of!(InterleavedParams, block)),
        ("steps", offset_of!(InterleavedParams, steps)),
        ("spot_steps", offset_of!(InterleavedParams, spot_steps)),
        ("spot_denominator", offset_of!(InterleavedParams, spot_denominator)),
        ("jitter", offset_of!(InterleavedParams, jitter)),
        ("frame_index", offset_of!(InterleavedParams, frame_index)),
        ("depth_aware", offset_of!(InterleavedParams, depth_aware)),
        ("depth_tolerance", offset_of!(InterleavedParams, depth_tolerance)),
        ("phase_lut", offset_of!(InterleavedParams, phase_lut)),
        ("phase_lut_size", offset_of!(InterleavedParams, phase_lut_size)),
    ];
    for (name, src) in SHADERS {
        let entry = name.rsplit('/').next().unwrap();
        check_params(name, src, entry, &rust, std::mem::size_of::<InterleavedParams>());
    }
}

#[test]
fn subsampled_params_match_the_wgsl_layout_in_every_pass() {
    use crepuscular::techniques::subsampled::{MARCH_WGSL, MIN_WEIGHT, SubsampledParams, UPSAMPLE_WGSL};
    let rust = [
        ("steps", offset_of!(SubsampledParams, steps)),
        ("jitter", offset_of!(SubsampledParams, jitter)),
        ("frame_index", offset_of!(SubsampledParams, frame_index)),
        ("spot_steps", offset_of!(SubsampledParams, spot_steps)),
        ("spot_denominator", offset_of!(SubsampledParams, spot_denominator)),
        ("grid_width", offset_of!(SubsampledParams, grid_width)),
        ("grid_height", offset_of!(SubsampledParams, grid_height)),
        ("depth_tolerance", offset_of!(SubsampledParams, depth_tolerance)),
        ("edge_remarch", offset_of!(SubsampledParams, edge_remarch)),
        ("cone_aware", offset_of!(SubsampledParams, cone_aware)),
    ];
    for (name, wgsl, entry) in
        [("subsampled/march", MARCH_WGSL, "march"), ("subsampled/upsample", UPSAMPLE_WGSL, "upsample")]
    {
        check_params(name, wgsl, entry, &rust, std::mem::size_of::<SubsampledParams>());
    }
    // The upsampling's threshold is the same constant on both sides.
    let c = format!("const MIN_WEIGHT: f32 = {MIN_WEIGHT:e};");
    assert!(UPSAMPLE_WGSL.contains(&c), "upsample.wgsl lacks `{c}`");
}

#[test]
fn epipolar_params_match_the_wgsl_layout_in_every_pass() {
    use crepuscular::techniques::epipolar::{
        EpipolarLine, EpipolarParams, GEOMETRY_WGSL, MIN_LINE_LENGTH, MIN_WEIGHT, SHADERS, pass_source,
    };
    let rust = [
        ("steps", offset_of!(EpipolarParams, steps)),
        ("jitter", offset_of!(EpipolarParams, jitter)),
        ("frame_index", offset_of!(EpipolarParams, frame_index)),
        ("spot_steps", offset_of!(EpipolarParams, spot_steps)),
        ("spot_denominator", offset_of!(EpipolarParams, spot_denominator)),
        ("slices", offset_of!(EpipolarParams, slices)),
        ("samples", offset_of!(EpipolarParams, samples)),
        ("initial_samples", offset_of!(EpipolarParams, initial_samples)),
        ("length_proportional", offset_of!(EpipolarParams, length_proportional)),
        ("depth_threshold", offset_of!(EpipolarParams, depth_threshold)),
        ("threshold_growth", offset_of!(EpipolarParams, threshold_growth)),
        ("taps", offset_of!(EpipolarParams, taps)),
        ("weighting", offset_of!(EpipolarParams, weighting)),
        ("spatial_scale", offset_of!(EpipolarParams, spatial_scale)),
        ("depth_scale", offset_of!(EpipolarParams, depth_scale)),
        ("outer_lines", offset_of!(EpipolarParams, outer_lines)),
        ("fallback_remarch", offset_of!(EpipolarParams, fallback_remarch)),
        ("degenerate", offset_of!(EpipolarParams, degenerate)),
        ("max_workgroups", offset_of!(EpipolarParams, max_workgroups)),
        ("prefilter_level", offset_of!(EpipolarParams, prefilter_level)),
        ("epipole_radius", offset_of!(EpipolarParams, epipole_radius)),
        ("epipole", offset_of!(EpipolarParams, epipole)),
    ];
    for (name, src, entries) in SHADERS {
        for entry in entries {
            check_params(name, &pass_source(src), entry, &rust, std::mem::size_of::<EpipolarParams>());
        }
    }
    // The line record of the storage buffer, member by member.
    let module = parse("epipolar/lines", &crepuscular::shaders::compose(&pass_source(SHADERS[1].1)));
    let (members, span) = struct_members(&module, "Line");
    let rust = [
        ("end", offset_of!(EpipolarLine, end)),
        ("dir", offset_of!(EpipolarLine, dir)),
        ("length", offset_of!(EpipolarLine, length)),
        ("valid", offset_of!(EpipolarLine, valid)),
        ("initial", offset_of!(EpipolarLine, initial)),
        ("_pad", offset_of!(EpipolarLine, _pad)),
    ];
    assert_eq!(members.len(), rust.len(), "Line field count: {members:?}");
    for ((wn, wo), (rn, ro)) in members.iter().zip(rust) {
        assert_eq!(wn, rn);
        assert_eq!(*wo as usize, ro, "Line: offset of {rn}");
    }
    assert_eq!(span as usize, std::mem::size_of::<EpipolarLine>());
    // The constants are the same on both sides.
    for c in [
        format!("const MIN_WEIGHT: f32 = {MIN_WEIGHT:e};"),
        format!("const MIN_LINE_LENGTH: f32 = {MIN_LINE_LENGTH:e};"),
    ] {
        assert!(GEOMETRY_WGSL.contains(&c), "geometry.wgsl lacks `{c}`");
    }
}

#[test]
fn wgsl_light_and_phase_kinds_are_the_rust_constants() {
    use crepuscular::frame::*;
    let common = crepuscular::shaders::COMMON;
    for (name, value) in [
        ("LIGHT_DIRECTIONAL", LIGHT_DIRECTIONAL),
        ("LIGHT_SPOT", LIGHT_SPOT),
        ("LIGHT_POINT", LIGHT_POINT),
        ("PHASE_ISOTROPIC", PHASE_ISOTROPIC),
        ("PHASE_HENYEY_GREENSTEIN", PHASE_HENYEY_GREENSTEIN),
        ("PHASE_RAYLEIGH", PHASE_RAYLEIGH),
        ("PHASE_HOFFMAN_PREETHAM", PHASE_HOFFMAN_PREETHAM),
        ("CUBE_LAYERS", crepuscular::shadow::CUBE_FACES.len() as u32),
        ("SPOT_FIXED", crepuscular::march::SpotSteps::Fixed.code()),
        ("SPOT_EXACT_CONE", crepuscular::march::SpotSteps::ExactCone.code()),
        ("SPOT_APPENDIX_B_CONSTANT", crepuscular::march::SpotSteps::AppendixBConstant.code()),
        ("SPOT_APPENDIX_B_SMOOTHSTEP", crepuscular::march::SpotSteps::AppendixBSmoothstep.code()),
        ("MARCH_EQUIANGULAR", crepuscular::march::EQUIANGULAR_BIT),
        ("SHADOW_FILTER_NEAREST", crepuscular::ShadowFilter::Nearest.code()),
        ("SHADOW_FILTER_BILINEAR", crepuscular::ShadowFilter::Bilinear.code()),
    ] {
        let decl = format!("const {name}: u32 = {value}u;");
        assert!(common.contains(&decl), "common.wgsl lacks `{decl}`");
    }
    // The lights block: its size, the missing-texture marker, its binding.
    for decl in [
        format!("const MAX_LIGHTS: u32 = {MAX_LIGHTS}u;"),
        format!("items: array<Light, {MAX_LIGHTS}>,"),
        format!("const NO_TEXTURE: u32 = 0x{NO_TEXTURE:x}u;"),
        format!("@group(0) @binding({}) var<uniform> lights: Lights;", crepuscular::techniques::pass::LIGHTS_BINDING),
    ] {
        assert!(common.contains(&decl), "common.wgsl lacks `{decl}`");
    }
}

#[test]
fn temporal_uniforms_match_their_wgsl_layout() {
    use crepuscular::temporal::{MAX_FRAMES, TEMPORAL_WGSL, TemporalUniforms as T};
    let module = parse("temporal", &crepuscular::shaders::compose(TEMPORAL_WGSL));
    assert!(module.entry_points.iter().any(|e| e.name == "resolve"), "temporal: no entry point resolve");
    check_struct(
        &module,
        "Temporal",
        &[
            ("prev_view_proj", offset_of!(T, prev_view_proj)),
            ("prev_camera_pos", offset_of!(T, prev_camera_pos)),
            ("history_weight", offset_of!(T, history_weight)),
            ("clip_sigma", offset_of!(T, clip_sigma)),
            ("depth_tolerance", offset_of!(T, depth_tolerance)),
            ("valid", offset_of!(T, valid)),
            ("clip", offset_of!(T, clip)),
            ("catmull_rom", offset_of!(T, catmull_rom)),
            ("motion", offset_of!(T, motion)),
            ("adaptive", offset_of!(T, adaptive)),
            ("young_frames", offset_of!(T, young_frames)),
            ("lamp_count", offset_of!(T, lamp_count)),
            ("lamp_radius", offset_of!(T, lamp_radius)),
            ("scattering", offset_of!(T, scattering)),
            ("lamps", offset_of!(T, lamps)),
        ],
        std::mem::size_of::<T>(),
    );
    assert!(TEMPORAL_WGSL.contains(&format!("const MAX_FRAMES: f32 = {MAX_FRAMES:.1};")));
}

#[test]
fn prefiltered_params_match_the_wgsl_layout_and_constants() {
    use crepuscular::techniques::prefiltered::{self as pf, PrefilteredParams as P};
    let fields: Vec<(&str, usize)> = vec![
        ("mode", offset_of!(P, mode)),
        ("local", offset_of!(P, local)),
        ("width", offset_of!(P, width)),
        ("height", offset_of!(P, height)),
        ("regions", offset_of!(P, regions)),
        ("bases", offset_of!(P, bases)),
        ("bases_per_thread", offset_of!(P, bases_per_thread)),
        ("flags", offset_of!(P, flags)),
        ("epipole_radius", offset_of!(P, epipole_radius)),
        ("epipole_steps", offset_of!(P, epipole_steps)),
        ("light_steps", offset_of!(P, light_steps)),
        ("spot_steps", offset_of!(P, spot_steps)),
        ("camera", offset_of!(P, camera)),
        ("light", offset_of!(P, light)),
        ("axes", offset_of!(P, axes)),
        ("ranges", offset_of!(P, ranges)),
        ("epipole", offset_of!(P, epipole)),
        ("region_x", offset_of!(P, region_x)),
        ("bands", offset_of!(P, bands)),
        ("channels", offset_of!(P, channels)),
        ("tree_levels", offset_of!(P, tree_levels)),
        ("max_nodes", offset_of!(P, max_nodes)),
    ];
    // Every prefiltered and minmax pass shares the block (prefiltered/geometry.wgsl).
    for (name, src, entry) in
        pf::shaders().into_iter().chain(crepuscular::techniques::minmax::shaders()).collect::<Vec<_>>()
    {
        check_params(name, &src, entry, &fields, std::mem::size_of::<P>());
    }
    let geometry = pf::GEOMETRY_WGSL;
    use pf::rectify::Mode;
    for (name, value) in [
        ("RECT_PROJECTIVE", Mode::Projective.code()),
        ("RECT_EPIPOLAR", Mode::Epipolar.code()),
        ("FLAG_TRANSMITTANCE_WEIGHTS", pf::FLAG_TRANSMITTANCE_WEIGHTS),
        ("FLAG_FULL_CIRCLE", pf::FLAG_FULL_CIRCLE),
        ("FLAG_HOST_RASTER", pf::FLAG_HOST_RASTER),
    ] {
        let decl = format!("const {name}: u32 = {value}u;");
        assert!(geometry.contains(&decl), "prefiltered/geometry.wgsl lacks `{decl}`");
    }
}
