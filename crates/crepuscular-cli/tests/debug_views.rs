//! The techniques' debug views through the library's one interface (`crepuscular::debug`):
//! every view of every technique that has one, on the GPU (`Scattering::debug_view`, from the
//! frame it rendered) and on the CPU (`debug_view_cpu`), each a picture with something in it,
//! the two backends drawing the same picture, and a clear error for a view the technique lacks
//! or a technique that has not rendered.

use crepuscular::debug::{DebugView, debug_view_cpu};
use crepuscular::gpu::test_gpu;
use crepuscular::{CpuFrame, Image, Scattering, TechniqueSettings};
use crepuscular_cli::render::{RenderOptions, debug_view, frame_desc, render};
use crepuscular_cli::view::parse_technique;
use crepuscular_scene::{builtin, host_cpu};

fn small(name: &str) -> crepuscular_scene::Scene {
    let mut s = builtin::builtin(name).expect("built-in scene");
    s.render.width = 64;
    s.render.height = 36;
    s.render.shadow.size = 512;
    s
}

/// (fraction of channel values more than 0.02 apart, whether `img` holds more than one value).
fn agreement(a: &Image, b: &Image) -> (f64, bool) {
    assert_eq!((a.width, a.height), (b.width, b.height));
    let mut off = 0usize;
    for (p, q) in a.pixels.iter().zip(&b.pixels) {
        for c in 0..3 {
            off += ((p[c] - q[c]).abs() > 0.02) as usize;
        }
    }
    let varied = a.pixels.iter().any(|p| p[..3] != a.pixels[0][..3]);
    (off as f64 / (a.pixels.len() * 3) as f64, varied)
}

#[test]
fn every_debug_view_draws_the_same_picture_on_both_backends() {
    let Some(gpu) = test_gpu("every_debug_view_draws_the_same_picture_on_both_backends") else { return };
    let scene = small("stained-glass");
    for name in ["epipolar", "interleaved", "prefiltered", "minmax"] {
        // Small maps keep the CPU's prefix sums short.
        let set =
            if matches!(name, "prefiltered" | "minmax") { vec!["map_size=[256, 128]".to_string()] } else { vec![] };
        let technique = parse_technique(name, &scene, None, &set).unwrap();
        let fin = render(&scene, None, &RenderOptions { technique: technique.clone(), progress: &|_, _| {} })
            .unwrap()
            .final_radiance;
        for &view in DebugView::of(&technique) {
            let cpu = debug_view(&scene, None, &technique, view, &fin).unwrap();
            let on_gpu = debug_view(&scene, Some(&gpu), &technique, view, &fin).unwrap();
            assert!(cpu.all_finite() && on_gpu.all_finite(), "{name} {}", view.name());
            let (off, varied) = agreement(&on_gpu, &cpu);
            eprintln!("{name} {}: {}×{}, {:.3}% of values apart", view.name(), cpu.width, cpu.height, off * 100.0);
            assert!(varied, "{name} {}: a constant picture", view.name());
            // The backends mirror each other pass by pass (each technique's mirror test);
            // a debug view is those passes drawn, so at most a few values differ (a sample
            // classified on the other side of a threshold, a walk one node longer).
            assert!(off < 0.02, "{name} {}: {:.2}% of values differ", view.name(), off * 100.0);
        }
    }
}

#[test]
fn a_view_the_technique_lacks_or_a_frame_not_rendered_is_an_error() {
    let Some(gpu) = test_gpu("a_view_the_technique_lacks_or_a_frame_not_rendered_is_an_error") else { return };
    let scene = small("colonnade");
    let desc = frame_desc(&scene).unwrap();
    let h = host_cpu::render(&scene.geometry, &scene.shading(), &desc);
    let frame = CpuFrame { desc: &desc, depth: &h.depth, shadow_maps: &h.shadow_maps, surface: Some(&h.surface) };
    let fin = Image::new(desc.width, desc.height);
    // A view of another technique: an error naming the view and the technique, both backends.
    let bf = TechniqueSettings::BruteForce(Default::default());
    let e = debug_view_cpu(&bf, DebugView::Pattern, &frame, None, &fin).unwrap_err().to_string();
    assert!(e.contains("pattern") && e.contains("brute-force"), "{e}");
    let sc = Scattering::from_gpu(&gpu, bf).unwrap();
    let e = sc.debug_view(DebugView::Nodes, &frame, &fin).unwrap_err().to_string();
    assert!(e.contains("nodes") && e.contains("brute-force"), "{e}");
    // A technique that has not rendered a frame has nothing to read back.
    for name in ["epipolar", "prefiltered", "minmax"] {
        let technique = parse_technique(name, &scene, None, &[]).unwrap();
        let view = DebugView::of(&technique)[0];
        let sc = Scattering::from_gpu(&gpu, technique).unwrap();
        assert!(sc.debug_view(view, &frame, &fin).is_err(), "{name}: a view before any frame");
    }
    // Names parse back, and a wrong one lists the views.
    for v in DebugView::ALL {
        assert_eq!(v.name().parse::<DebugView>().unwrap(), v);
    }
    let e = "bogus".parse::<DebugView>().unwrap_err().to_string();
    assert!(e.contains("bogus") && e.contains("classification"), "{e}");
}
