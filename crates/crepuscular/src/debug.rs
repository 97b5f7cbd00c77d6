//! The techniques' debug views: pictures of what a technique computed on its way to the
//! in-scattering (its samples, its maps, its cost per pixel), drawn from the state of the last
//! frame a [`Scattering`] rendered on the GPU ([`Scattering::debug_view`]) or from the CPU
//! passes ([`debug_view_cpu`]). Every tool reaches them here: `render --debug`, the viewer's
//! buttons. They read intermediates back, so they stall: tools only, never in an engine's frame.

use crate::error::Error;
use crate::frame::CpuFrame;
use crate::image::Image;
use crate::scattering::Scattering;
use crate::techniques::{AnyGpuTechnique, TechniqueSettings, epipolar, interleaved, minmax, prefiltered};

/// A technique's debug view.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum DebugView {
    /// `epipolar`: Engelhardt & Dachsbacher 2010, Fig. 9 bottom — every valid epipolar line's
    /// texels drawn faint over the final image, the initial ray-march samples in red and the
    /// samples the refinement placed at depth discontinuities in green.
    Classification,
    /// `epipolar`: the radiance texture (one row per epipolar line, one column per sample
    /// along it; culled lines black), scaled up to at least 1024 pixels wide.
    Radiance,
    /// `interleaved`: the interleaving pattern (Tóth & Umenhoffer 2009 §4.1) — each pixel
    /// coloured by its offset k of the M×M block (which of the N/M² terms of eq. 1 it
    /// marches), blended half and half over the final image.
    Pattern,
    /// `prefiltered`: the rectified shadow map (Klehm et al. 2014, §2.2, §4) — one row per
    /// epipolar slice, view rays left to right, grey = normalised occluder depth (white:
    /// unoccluded).
    RectifiedMap,
    /// `prefiltered`: the first filtered-basis layer (bases 0–2 as RGB), the prefix-summed
    /// Fourier bases as stored (§3.3, Appendix A).
    Basis,
    /// `prefiltered`: the prefiltered average visibility of every pixel's ray (Listing 4), the
    /// ray-marched epipole disc (§5) in red.
    Visibility,
    /// `minmax`: the tree nodes each pixel's walk visits (Chen et al. 2011: the cost follows the
    /// changes of visibility along the ray), magma from 0 (black) to the frame's most (pale
    /// yellow), the ray-marched epipole disc in red.
    Nodes,
}

impl DebugView {
    /// Every view, in the order of the enum.
    pub const ALL: [DebugView; 7] = [
        DebugView::Classification,
        DebugView::Radiance,
        DebugView::Pattern,
        DebugView::RectifiedMap,
        DebugView::Basis,
        DebugView::Visibility,
        DebugView::Nodes,
    ];

    /// Name, as on the command line.
    pub fn name(self) -> &'static str {
        match self {
            DebugView::Classification => "classification",
            DebugView::Radiance => "radiance",
            DebugView::Pattern => "pattern",
            DebugView::RectifiedMap => "rectified-map",
            DebugView::Basis => "basis",
            DebugView::Visibility => "visibility",
            DebugView::Nodes => "nodes",
        }
    }

    /// One line on what it shows (the viewer's button labels).
    pub fn label(self) -> &'static str {
        match self {
            DebugView::Classification => "epipolar: sample classification (Fig. 9)",
            DebugView::Radiance => "epipolar: the lines × samples radiance texture",
            DebugView::Pattern => "interleaved: each pixel's offset in the M×M block",
            DebugView::RectifiedMap => "prefiltered: the rectified shadow map (rows = epipolar slices)",
            DebugView::Basis => "prefiltered: filtered-basis layer 0 (bases 0–2 as RGB)",
            DebugView::Visibility => "prefiltered: average visibility per pixel (epipole disc red)",
            DebugView::Nodes => "minmax: tree nodes each pixel's walk visits (epipole disc red)",
        }
    }

    /// The debug views `technique` has (empty: none).
    pub fn of(technique: &TechniqueSettings) -> &'static [DebugView] {
        match technique {
            TechniqueSettings::Epipolar(_) => &[DebugView::Classification, DebugView::Radiance],
            TechniqueSettings::Interleaved(_) => &[DebugView::Pattern],
            TechniqueSettings::Prefiltered(_) => &[DebugView::RectifiedMap, DebugView::Basis, DebugView::Visibility],
            TechniqueSettings::Minmax(_) => &[DebugView::Nodes],
            _ => &[],
        }
    }

    /// "epipolar — classification, radiance; …": every technique's views, for messages and help.
    pub fn list() -> &'static str {
        "debug views: epipolar — classification, radiance; interleaved — pattern; prefiltered — rectified-map, basis, visibility; minmax — nodes"
    }

    /// An error unless `technique` has this view (naming both and listing the views).
    pub fn check(self, technique: &TechniqueSettings) -> Result<(), Error> {
        if DebugView::of(technique).contains(&self) {
            return Ok(());
        }
        Err(Error::invalid(
            "debug view",
            self.name(),
            format!("not a debug view of `{}` ({})", technique.name(), DebugView::list()),
        ))
    }
}

impl std::str::FromStr for DebugView {
    type Err = Error;
    fn from_str(s: &str) -> Result<Self, Error> {
        DebugView::ALL
            .into_iter()
            .find(|v| v.name() == s)
            .ok_or_else(|| Error::invalid("debug view", s, DebugView::list()))
    }
}

/// Magma-like colour ramp for `v` in `[0, 1]`: piecewise-linear through matplotlib's magma
/// sampled at eighths (0, 1/8, …, 1), as 8-bit sRGB. Values outside are clamped; NaN gives the
/// top colour. The nodes view's ramp, and the tools' FLIP error maps'.
pub fn magma_ramp(v: f32) -> [u8; 3] {
    const STOPS: [[f32; 3]; 9] = [
        [0.0, 0.0, 4.0],
        [28.0, 16.0, 68.0],
        [79.0, 18.0, 123.0],
        [129.0, 37.0, 129.0],
        [181.0, 54.0, 122.0],
        [229.0, 80.0, 100.0],
        [251.0, 135.0, 97.0],
        [254.0, 194.0, 135.0],
        [252.0, 253.0, 191.0],
    ];
    let v = if v.is_nan() { 1.0 } else { v.clamp(0.0, 1.0) };
    let x = v * (STOPS.len() - 1) as f32;
    let i = (x.floor() as usize).min(STOPS.len() - 2);
    let f = x - i as f32;
    let (a, b) = (STOPS[i], STOPS[i + 1]);
    [0, 1, 2].map(|c| (a[c] + (b[c] - a[c]) * f).round().clamp(0.0, 255.0) as u8)
}

/// A colour per block offset k of `m2` = M² offsets: a hue wheel, so neighbouring offsets differ.
fn offset_colour(k: u32, m2: u32) -> [f32; 3] {
    let h = (k as f32 + 0.5) / m2.max(1) as f32 * 6.0;
    // Hue → RGB at full saturation: each channel a trapezoid on the wheel, a third apart.
    let c = |n: f32| 1.0 - (((n + h) % 6.0 - 3.0).abs() - 1.0).clamp(0.0, 1.0);
    [c(0.0), c(4.0), c(2.0)]
}

/// `interleaved`'s pattern over `final_radiance` ([`DebugView::Pattern`]): it needs no frame,
/// only the settings and the final image.
pub fn pattern_view(s: &interleaved::InterleavedSettings, final_radiance: &Image) -> Image {
    let m2 = s.block * s.block;
    let mut img = final_radiance.clone();
    for y in 0..img.height {
        for x in 0..img.width {
            let c = offset_colour(interleaved::cpu::block_offset(s, x, y), m2);
            let p = &mut img.pixels[(y * img.width + x) as usize];
            for i in 0..3 {
                p[i] = 0.5 * p[i] + 0.5 * c[i];
            }
        }
    }
    img
}

/// `epipolar`'s views of `debug`.
fn epipolar_view(debug: &epipolar::debug::EpipolarDebug, view: DebugView, final_radiance: &Image) -> Image {
    match view {
        DebugView::Classification => epipolar::debug::classification_view(debug, final_radiance),
        _ => {
            let scale = 1024u32.div_ceil(debug.samples().max(1)).clamp(1, 16);
            epipolar::debug::radiance_view(debug, scale)
        }
    }
}

/// `prefiltered`'s views of its maps.
fn prefiltered_view(
    passes: &prefiltered::cpu::Passes,
    frame: &CpuFrame,
    settings: &prefiltered::PrefilteredSettings,
    view: DebugView,
) -> Image {
    use prefiltered::debug;
    match view {
        DebugView::RectifiedMap => debug::rectified_map_view(passes),
        DebugView::Basis => debug::basis_view(passes, 0),
        _ => {
            let epipole = prefiltered::epipole_pixel(frame.desc, settings.epipole_radius);
            debug::visibility_view(passes, frame.desc, frame.depth, settings.bases, epipole, settings.epipole_radius)
        }
    }
}

/// `minmax`'s nodes view: every pixel's walk over `tree` counted on the CPU.
fn nodes_view(frame: &CpuFrame, settings: &minmax::MinmaxSettings, tree: &[[f32; 2]]) -> Image {
    let desc = frame.desc;
    let rect = prefiltered::Rectification::new(desc, &settings.rectify_options());
    let settings = &settings.for_frame(desc);
    let epipole = prefiltered::epipole_pixel(desc, settings.epipole_radius);
    let nodes = minmax::cpu::traverse(frame, settings, &rect, tree, epipole).2;
    let most = nodes.iter().copied().filter(|&n| n != u32::MAX).max().unwrap_or(1).max(1);
    let mut img = Image::new(desc.width, desc.height);
    for (p, &n) in img.pixels.iter_mut().zip(&nodes) {
        *p = if n == u32::MAX {
            [1.0, 0.0, 0.0, 1.0]
        } else {
            let c = magma_ramp(n as f32 / most as f32);
            [c[0] as f32 / 255.0, c[1] as f32 / 255.0, c[2] as f32 / 255.0, 1.0]
        };
    }
    img
}

/// Draws `view` of `technique` on the CPU backend: runs the technique's CPU passes on `frame`
/// (one light: the views of epipolar, prefiltered and minmax are one light's) and draws the
/// view. `rectified`: the host's rasterized rectified map where the rectification is
/// projective (as for [`crate::techniques::Technique::render_cpu`]); `final_radiance`: the
/// frame's final image (the classification's and the pattern's background). Returns a linear
/// image (tone-map it like the final image).
pub fn debug_view_cpu(
    technique: &TechniqueSettings,
    view: DebugView,
    frame: &CpuFrame,
    rectified: Option<&[f32]>,
    final_radiance: &Image,
) -> Result<Image, Error> {
    view.check(technique)?;
    Ok(match technique {
        TechniqueSettings::Interleaved(s) => pattern_view(s, final_radiance),
        TechniqueSettings::Epipolar(s) => {
            epipolar_view(&epipolar::cpu::render_with_debug(frame, s)?.2, view, final_radiance)
        }
        TechniqueSettings::Prefiltered(s) => {
            prefiltered_view(&prefiltered::cpu::passes(frame, s, rectified)?.0, frame, s, view)
        }
        TechniqueSettings::Minmax(s) => nodes_view(frame, s, &minmax::cpu::passes(frame, s, rectified)?.0.tree),
        _ => unreachable!("checked above"),
    })
}

impl Scattering {
    /// Draws `view` from the last frame this rendered on the GPU, reading its intermediates
    /// back (a stall: for tools). `frame` is that frame on the CPU side: its description (one
    /// light), its depth as the GPU saw it (prefiltered's visibility and minmax's walk end
    /// there), and — for minmax's nodes view only, whose walk is counted on the CPU over the
    /// GPU's tree — its shadow maps. `final_radiance`: the frame's final image. Returns a
    /// linear image (tone-map it like the final image). An error when the technique has no
    /// such view or has not rendered yet.
    pub fn debug_view(&self, view: DebugView, frame: &CpuFrame, final_radiance: &Image) -> Result<Image, Error> {
        let settings = self.settings();
        view.check(&settings)?;
        let gpu = self.gpu();
        Ok(match (self.technique(), &settings) {
            (_, TechniqueSettings::Interleaved(s)) => pattern_view(s, final_radiance),
            (AnyGpuTechnique::Epipolar(t), _) => epipolar_view(&t.read_debug(gpu)?, view, final_radiance),
            (AnyGpuTechnique::Prefiltered(t), TechniqueSettings::Prefiltered(s)) => {
                let rect = t
                    .last_rectification()
                    .ok_or_else(|| Error::invalid("debug view", view.name(), "render a frame first"))?
                    .clone();
                let channels = s.channels(&frame.desc.lights[0].light);
                let passes = prefiltered::debug::passes_from_gpu(rect, channels, t.read_maps(gpu)?);
                prefiltered_view(&passes, frame, s, view)
            }
            (AnyGpuTechnique::Minmax(t), TechniqueSettings::Minmax(s)) => nodes_view(frame, s, &t.read_tree(gpu)?),
            _ => unreachable!("checked above"),
        })
    }
}
