//! What `prefiltered` asks of the host renderer when it rasterizes the rectified shadow map
//! itself (Klehm et al. 2014, §4.2): the scene's depth drawn with one projective matrix per
//! region, depth-clamped so that occluders between the light and the camera frustum still cast
//! their shadows ("Additionally, using depth clamping … ensures that objects shadowing the
//! camera frustum, but lying outside of it, are rendered in the shadow map as well").

use glam::Mat4;

/// A request to draw the scene's depth into a rectified shadow map of `width × height` texels.
///
/// Conventions (the same as any wgpu depth pass): for each region, `view_proj` maps a world point
/// to clip space; NDC x ∈ [−1, 1] spans the region's columns `columns[0]..columns[1]` (a
/// viewport), NDC y = +1 is texture row 0, NDC y = −1 the last row; the stored value is the
/// smallest NDC depth z/w over the triangles covering the texel centre, *clamped* to [0, 1]
/// instead of clipped (a triangle with z/w < 0 writes 0, one with z/w > 1 writes 1), and 1.0
/// where nothing is drawn. Clip w is positive in front of the camera (w is the distance along
/// the rectification's x axis).
#[derive(Clone, Debug, PartialEq)]
pub struct RectifiedRaster {
    /// Texels per row (columns, along the view rays).
    pub width: u32,
    /// Rows (epipolar slices).
    pub height: u32,
    /// The regions, left to right; their column ranges tile `0..width`.
    pub regions: Vec<RasterRegion>,
}

/// One region of a [`RectifiedRaster`]: a viewport of columns and its own matrix.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RasterRegion {
    /// World → clip for this region.
    pub view_proj: Mat4,
    /// First column and one past the last column of the region.
    pub columns: [u32; 2],
}
