//! Debug views of `prefiltered` (ISSUE 4, "Stats and debug views"): the rectified shadow map,
//! one filtered-basis layer and the average-visibility image, from a frame's [`Passes`] (the
//! CPU's, or the GPU's maps read back with [`super::Prefiltered::read_maps`] and put into a
//! [`Passes`] by [`passes_from_gpu`]).

use super::cpu::{Passes, in_epipole_disc, ray_visibility};
use super::rectify::Rectification;
use crate::frame::FrameDesc;
use crate::image::Image;

/// A [`Passes`] from the maps the GPU read back (the in-scattering left empty).
pub fn passes_from_gpu(rect: Rectification, channels: u32, maps: (Vec<f32>, Vec<[f32; 4]>, Vec<f32>)) -> Passes {
    let (depth, basis, cumw) = maps;
    Passes { rect, depth, basis, cumw, channels, image: Image::new(1, 1) }
}

/// The rectified shadow map: one row per epipolar slice, view rays running left to right,
/// brightness = the normalised depth of the first occluder (white: unoccluded).
pub fn rectified_map_view(p: &Passes) -> Image {
    let mut img = Image::new(p.rect.width, p.rect.height);
    for (o, &z) in img.pixels.iter_mut().zip(&p.depth) {
        *o = [z, z, z, 1.0];
    }
    img
}

/// Filtered-basis layer `layer` (bases 4·layer … 4·layer + 2 as red, green, blue), as stored:
/// the normalised weighted running mean mapped to [0, 1] (Appendix A).
pub fn basis_view(p: &Passes, layer: u32) -> Image {
    let (w, h) = (p.rect.width as usize, p.rect.height as usize);
    let layer = (layer as usize).min(p.basis.len() / (w * h).max(1) - 1);
    let mut img = Image::new(p.rect.width, p.rect.height);
    for (i, o) in img.pixels.iter_mut().enumerate() {
        let b = p.basis[layer * w * h + i];
        *o = [b[0], b[1], b[2], 1.0];
    }
    img
}

/// The prefiltered average visibility of every pixel's view ray (Listing 4's `avgVis`; per
/// channel with RGB spot weights);
/// pixels of the epipole disc, which are ray-marched instead, in red.
pub fn visibility_view(
    p: &Passes,
    desc: &FrameDesc,
    depth: &[f32],
    bases: u32,
    epipole: Option<[f32; 2]>,
    radius: u32,
) -> Image {
    let mut img = Image::new(desc.width, desc.height);
    for y in 0..desc.height {
        for x in 0..desc.width {
            let i = (y * desc.width + x) as usize;
            if in_epipole_disc(epipole, radius, x, y) {
                img.pixels[i] = [1.0, 0.0, 0.0, 1.0];
                continue;
            }
            let dir = desc.pixel_ray(x, y);
            let s = desc.view_distance(depth[i], dir);
            let v = ray_visibility(p, bases, desc.camera.position + dir * s, dir);
            img.pixels[i] = [v.x, v.y, v.z, 1.0];
        }
    }
    img
}
