//! The camera of a frame as an engine has it: a view matrix, any invertible perspective
//! projection (standard or reversed-Z, finite or infinite far plane, jittered, off-centre) and
//! the depth convention of its depth buffer (docs/MODEL.md §5). Everything the techniques need
//! — the eye, the view axis, the near and far distances, view rays and view distances from
//! depth — is derived here, once, and mirrored by `pixel_ray` / `view_distance` in common.wgsl.

use crate::error::Error;
use glam::{DVec2, DVec3, Mat4, Vec2, Vec3, Vec4};

/// How the depth buffer stores depth (the projection's NDC z = clip.z / clip.w, in [0, 1]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum DepthConvention {
    /// 0 at the near plane, 1 at the far plane; cleared to 1 (`Mat4::perspective_rh`).
    #[default]
    Standard,
    /// 1 at the near plane, 0 at the far plane (or at infinity); cleared to 0 — the precise
    /// convention most engines (Bevy included) use (`Mat4::perspective_infinite_reverse_rh`).
    Reversed,
}

impl DepthConvention {
    /// The depth-buffer value where nothing was drawn (the clear value).
    pub fn far_value(self) -> f32 {
        match self {
            DepthConvention::Standard => 1.0,
            DepthConvention::Reversed => 0.0,
        }
    }
    /// The depth-buffer value at the near plane.
    pub fn near_value(self) -> f32 {
        1.0 - self.far_value()
    }
    /// The depth test that keeps the nearer surface.
    pub fn compare(self) -> wgpu::CompareFunction {
        match self {
            DepthConvention::Standard => wgpu::CompareFunction::Less,
            DepthConvention::Reversed => wgpu::CompareFunction::Greater,
        }
    }
    /// True when `a` is nearer the eye than `b`.
    pub fn nearer(self, a: f32, b: f32) -> bool {
        match self {
            DepthConvention::Standard => a < b,
            DepthConvention::Reversed => a > b,
        }
    }
}

/// A frame's camera: the engine's matrices and depth convention, with what the techniques
/// derive from them. Build it with [`FrameCamera::new`] (any perspective projection) or
/// [`FrameCamera::look_at`] (the library's own look-at camera, [`crate::Camera`]).
#[derive(Clone, Debug, PartialEq)]
pub struct FrameCamera {
    /// World → view (right-handed; the camera looks down −z in view space).
    pub view: Mat4,
    /// View → clip, as the depth buffer was rendered with it.
    pub projection: Mat4,
    /// The depth buffer's convention.
    pub depth: DepthConvention,
    /// Eye position, world units (derived).
    pub position: Vec3,
    /// Distance of the near plane along the view axis, world units (derived).
    pub near: f32,
    /// Distance along the view axis where rays that hit nothing end — the medium's depth
    /// behind an empty pixel: the projection's far plane, or the `far` given to
    /// [`FrameCamera::new`] for an infinite projection (world units).
    pub far: f32,
    forward: Vec3,
    inv_view: Mat4,
    inv_projection: Mat4,
    /// View depth from NDC depth d: lin = depth_b / (d + depth_a) (derived from the projection).
    depth_a: f32,
    depth_b: f32,
}

impl FrameCamera {
    /// The engine's camera. `projection` must be an invertible perspective projection
    /// (clip.w = −z_view: standard or reversed-Z, finite or infinite far, jittered or
    /// off-centre) whose depth follows `depth`. `far`: where empty pixels' rays end; `None`
    /// takes the projection's far plane, which an infinite projection does not have (an error
    /// then). Errors name what is wrong (a singular or non-perspective matrix, NaN, a far
    /// distance that is not beyond the near plane).
    pub fn new(view: Mat4, projection: Mat4, depth: DepthConvention, far: Option<f32>) -> Result<Self, Error> {
        let name = |m: &Mat4| format!("{:?}", m.to_cols_array());
        if !view.is_finite() || view.determinant().abs() < 1e-12 {
            return Err(Error::invalid("camera.view", name(&view), "must be a finite, invertible matrix"));
        }
        if !projection.is_finite() || projection.determinant().abs() < 1e-30 {
            return Err(Error::invalid("camera.projection", name(&projection), "must be a finite, invertible matrix"));
        }
        // A perspective projection: clip.w = −z_view.
        let w_row = projection.row(3);
        if (w_row - Vec4::new(0.0, 0.0, -1.0, 0.0)).abs().max_element() > 1e-6 {
            return Err(Error::invalid(
                "camera.projection",
                name(&projection),
                "must be a perspective projection (clip w = −z_view); orthographic cameras are not supported",
            ));
        }
        let depth_a = projection.z_axis.z;
        let depth_b = projection.w_axis.z;
        let lin = |d: f32| depth_b / (d + depth_a);
        let near = lin(depth.near_value());
        let projection_far = lin(depth.far_value());
        if !(near.is_finite() && near > 0.0) {
            return Err(Error::invalid(
                "camera.projection",
                name(&projection),
                format!("its near plane ({near}) must be in front of the eye for the {depth:?} depth convention"),
            ));
        }
        let far = match far {
            Some(f) => f,
            None if projection_far.is_finite() && projection_far > near => projection_far,
            None => {
                return Err(Error::invalid(
                    "camera.far",
                    "none",
                    "an infinite projection needs the distance where empty pixels' rays end",
                ));
            }
        };
        if !(far.is_finite() && far > near) {
            return Err(Error::invalid("camera.far", far, format!("must be finite and beyond the near plane {near}")));
        }
        let inv_view = view.inverse();
        let position = inv_view.w_axis.truncate();
        let forward = inv_view.transform_vector3(Vec3::NEG_Z).normalize();
        Ok(Self {
            view,
            projection,
            depth,
            position,
            near,
            far,
            forward,
            inv_view,
            inv_projection: projection.inverse(),
            depth_a,
            depth_b,
        })
    }

    /// The library's look-at camera ([`crate::Camera`]) for an image of `aspect` (width /
    /// height), with a standard [0, 1] depth buffer. Errors: the camera's own checks
    /// ([`crate::Camera::validate`]) and an aspect that is not finite and > 0.
    pub fn look_at(camera: &crate::Camera, aspect: f32) -> Result<Self, Error> {
        camera.validate()?;
        if !(aspect.is_finite() && aspect > 0.0) {
            return Err(Error::invalid("camera aspect (width / height)", aspect, "must be finite and > 0"));
        }
        Self::new(camera.view(), camera.projection(aspect), DepthConvention::Standard, Some(camera.far))
    }

    /// World → clip.
    pub fn view_proj(&self) -> Mat4 {
        self.projection * self.view
    }

    /// Unit view axis (world).
    pub fn forward(&self) -> Vec3 {
        self.forward
    }

    /// View → world.
    pub fn inv_view(&self) -> Mat4 {
        self.inv_view
    }

    /// Clip → view.
    pub fn inv_projection(&self) -> Mat4 {
        self.inv_projection
    }

    /// (a, b) of the view depth lin = b / (d + a) from NDC depth d.
    pub fn depth_params(&self) -> (f32, f32) {
        (self.depth_a, self.depth_b)
    }

    /// Unit world direction of the view ray through NDC (x, y): the near-plane point
    /// unprojected in view space (where the eye is the origin, so the direction keeps f32
    /// precision), rotated to world. Mirrors `ndc_ray` in common.wgsl.
    pub fn ndc_ray(&self, ndc: Vec2) -> Vec3 {
        let h = self.inv_projection * ndc.extend(self.depth.near_value()).extend(1.0);
        let p = h.truncate() / h.w;
        self.inv_view.transform_vector3(p.normalize()).normalize()
    }

    /// [`FrameCamera::ndc_ray`] in f64 (the reference's precision).
    pub fn ndc_ray_f64(&self, ndc: DVec2) -> DVec3 {
        let h = self.inv_projection.as_dmat4() * ndc.extend(self.depth.near_value() as f64).extend(1.0);
        let p = h.truncate() / h.w;
        self.inv_view.as_dmat4().transform_vector3(p.normalize()).normalize()
    }

    /// [`FrameCamera::view_depth`] in f64.
    pub fn view_depth_f64(&self, d: f64) -> f64 {
        let far = self.far as f64;
        if d == self.depth.far_value() as f64 {
            return far;
        }
        let lin = self.depth_b as f64 / (d + self.depth_a as f64);
        if lin.is_finite() && lin > 0.0 { lin.min(far) } else { far }
    }

    /// Distance along the view axis for a depth-buffer value `d`: b / (d + a), and
    /// [`FrameCamera::far`] where nothing was drawn (`d` the convention's far value), beyond
    /// the far distance, or where the projection puts `d` at infinity. Mirrors `view_depth`
    /// in common.wgsl.
    pub fn view_depth(&self, d: f32) -> f32 {
        if d == self.depth.far_value() {
            return self.far;
        }
        let lin = self.depth_b / (d + self.depth_a);
        if lin.is_finite() && lin > 0.0 { lin.min(self.far) } else { self.far }
    }

    /// The depth-buffer value of a point at view-axis distance `lin` (for hosts and tests).
    pub fn depth_of(&self, lin: f32) -> f32 {
        let c = self.projection * Vec4::new(0.0, 0.0, -lin, 1.0);
        c.z / c.w
    }

    /// The eight world-space corners of the frustum slice between view depths `d0` and `d1`
    /// (near face first, corners (−1,−1), (1,−1), (1,1), (−1,1) in NDC): exact for off-centre
    /// and jittered projections.
    pub fn frustum_corners(&self, d0: f32, d1: f32) -> [Vec3; 8] {
        let mut out = [Vec3::ZERO; 8];
        for (k, d) in [d0, d1].into_iter().enumerate() {
            for (j, (sx, sy)) in [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)].into_iter().enumerate() {
                let dir = self.ndc_ray(Vec2::new(sx, sy));
                out[k * 4 + j] = self.position + dir * (d / dir.dot(self.forward).max(1e-6));
            }
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn camera() -> crate::Camera {
        crate::Camera { position: Vec3::new(1.0, 2.0, 3.0), look_at: Vec3::new(0.0, 1.0, -5.0), ..Default::default() }
    }

    /// A look-at camera that cannot make matrices is an error naming the field, not a panic.
    #[test]
    fn bad_look_at_camera_is_an_error() {
        let cases: [(&str, crate::Camera); 6] = [
            ("camera.position", crate::Camera { position: Vec3::new(f32::NAN, 0.0, 0.0), ..camera() }),
            ("camera.look_at", crate::Camera { look_at: camera().position, ..camera() }),
            ("camera.fov_y_degrees", crate::Camera { fov_y_degrees: 180.0, ..camera() }),
            ("camera.near", crate::Camera { near: 0.0, ..camera() }),
            ("camera.far", crate::Camera { far: 0.05, ..camera() }),
            ("camera.up", crate::Camera { up: Vec3::splat(f32::INFINITY), ..camera() }),
        ];
        for (key, cam) in cases {
            let e = FrameCamera::look_at(&cam, 1.5).expect_err(key).to_string();
            assert!(e.contains(key), "{key}: {e}");
        }
        let e = FrameCamera::look_at(&camera(), f32::NAN).expect_err("aspect").to_string();
        assert!(e.contains("aspect"), "{e}");
        // An up vector along the view is replaced, not refused.
        let straight_down = crate::Camera { look_at: camera().position - Vec3::Y, ..camera() };
        assert!(FrameCamera::look_at(&straight_down, 1.5).is_ok());
    }

    #[test]
    fn view_depth_inverts_every_convention() {
        let cam = camera();
        let aspect = 1.5;
        let standard = FrameCamera::look_at(&cam, aspect).unwrap();
        let reversed = FrameCamera::new(
            cam.view(),
            Mat4::perspective_infinite_reverse_rh(cam.fov_y_degrees.to_radians(), aspect, cam.near),
            DepthConvention::Reversed,
            Some(cam.far),
        )
        .unwrap();
        for c in [&standard, &reversed] {
            assert!((c.near - cam.near).abs() < 1e-6, "{:?}: near {}", c.depth, c.near);
            assert_eq!(c.far, cam.far);
            assert!((c.position - cam.position).length() < 1e-5);
            assert!((c.forward() - cam.forward()).length() < 1e-6);
            for z in [0.1f32, 0.5, 3.0, 50.0, 199.0] {
                let lin = c.view_depth(c.depth_of(z));
                assert!((lin - z).abs() / z < 1e-4, "{:?}: {z} → {lin}", c.depth);
            }
            assert_eq!(c.view_depth(c.depth.far_value()), cam.far);
        }
        // The two conventions give the same rays.
        for ndc in [Vec2::ZERO, Vec2::new(-1.0, 1.0), Vec2::new(0.3, -0.7)] {
            assert!((standard.ndc_ray(ndc) - reversed.ndc_ray(ndc)).length() < 1e-6);
        }
    }

    #[test]
    fn bad_projections_are_errors() {
        let cam = camera();
        let v = cam.view();
        let ortho = Mat4::orthographic_rh(-1.0, 1.0, -1.0, 1.0, 0.1, 10.0);
        assert!(FrameCamera::new(v, ortho, DepthConvention::Standard, None).is_err());
        assert!(FrameCamera::new(v, Mat4::ZERO, DepthConvention::Standard, None).is_err());
        let inf = Mat4::perspective_infinite_reverse_rh(1.0, 1.0, 0.1);
        let e = FrameCamera::new(v, inf, DepthConvention::Reversed, None).unwrap_err().to_string();
        assert!(e.contains("camera.far"), "{e}");
        // A reversed projection declared standard: its "near plane" is behind the eye.
        assert!(FrameCamera::new(v, inf, DepthConvention::Standard, Some(100.0)).is_err());
        let mut nan = cam.projection(1.0);
        nan.x_axis.x = f32::NAN;
        assert!(FrameCamera::new(v, nan, DepthConvention::Standard, None).is_err());
    }

    #[test]
    fn frustum_corners_match_the_look_at_camera() {
        let cam = camera();
        let fc = FrameCamera::look_at(&cam, 1.5).unwrap();
        let a = cam.frustum_corners(1.5, 1.0, 20.0);
        let b = fc.frustum_corners(1.0, 20.0);
        for (p, q) in a.iter().zip(&b) {
            assert!((*p - *q).length() < 1e-3, "{p} vs {q}");
        }
    }
}
