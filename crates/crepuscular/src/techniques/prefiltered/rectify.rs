//! The rectification of Klehm, Seidel & Eisemann 2014 (§2.2, §4): a map in which every view ray
//! of an epipolar slice runs along one row from left to right at one constant depth z, so that
//! the average visibility along the ray becomes a prefix sum over the row (§3.1, eq. 7).
//!
//! Two constructions, chosen per frame by [`Rectification::new`]:
//!
//! - **Projective** (§4.2, Fig. 4; directional lights): a light view whose "up" is turned so the
//!   2D bisectrix of the projected camera frustum runs left to right (x), then a perspective
//!   projection *along x* with the camera as centre of projection. In light-view coordinates
//!   (x, y, z) relative to the camera (z along the light's travel direction), a view ray has
//!   constant y/x (its row) and z/x (its depth), so the map is one 4×4 matrix ([`Rectification::raster`])
//!   and a host can rasterize the scene straight into it. Rows: y/x ∈ [q₀, q₁]; depth: z/x ∈ [r₀, r₁];
//!   columns: 1/x, the perspective "depth" of the projection, between the near and far x of the
//!   frustum corners, optionally in regions ("split shadow maps", §4.2).
//! - **Epipolar** (§4.1, after Baran et al. 2010; any light): slices are the half-planes through
//!   the camera and the light, indexed by their angle φ around the camera→light axis a; the
//!   depth of a view ray is its angle θ to a; columns index the light lines of the slice (for a
//!   directional light, their distance from the axis through the camera; for a local light,
//!   their angle ψ at the light from the light→camera direction). The map is built by resampling
//!   a standard shadow map texel by texel. Used when the light is local, and for a directional
//!   light when the epipole is on or near the screen (the projective construction is then
//!   impossible or badly non-linear, §4.2 "Non-linearity").
//!
//! In both, a point is lit by a texel when its depth is at most the texel's (V = H(z_r − z_i),
//! §3.1), and every function here has a WGSL twin of the same name in `common_prefiltered.wgsl`.

use crate::frame::FrameDesc;
use crate::model::Light;
use crate::shadow::{ShadowMap, cube_face};
use glam::{Mat4, Vec3, Vec4, Vec4Swizzles};
use serde::{Deserialize, Serialize};

use super::raster::{RasterRegion, RectifiedRaster};

/// Largest number of regions per row (column partitions with their own prefix sums).
pub const MAX_REGIONS: u32 = 8;

/// Where depths enter the Fourier basis (eq. 8–9): a depth z ∈ [0, 1] goes to m + (1 − 2m)·z,
/// and a texel with no occluder in the rays' range (stored depth ≥ 1: nothing drawn, or beyond
/// every ray) goes to exactly 1. The series of eq. 9 is periodic in z_r − z_i with its jumps at
/// 0 and ±1, so an unoccluded texel at 1 is at least m from every ray on both sides (rays lie in
/// [m, 1 − m]). The paper's full [0, 1] range put a ray at depth 0 exactly on the jump (½), and
/// storing "unoccluded" as depth 1 (the top of the rays' range) darkened the deepest lit rays by
/// up to 16 % (the test `an_empty_map_leaves_every_ray_lit`); with the sentinel the worst lit
/// ray of an empty map reads 0.974 at M = 32, the series' own ripple. A larger m was tried
/// (0.1, with more depth padding): it costs depth resolution, stained-glass 49.2 → 45.4 dB.
/// Our finding.
pub const Z_MARGIN: f32 = 0.0625;

/// Which rectification to use.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum RectificationChoice {
    /// Projective for a directional light whose projected camera frustum spans at most
    /// `max_projective_angle`; epipolar otherwise (and for every local light).
    #[default]
    Auto,
    /// Projective (§4.2) whenever it is possible (a directional light, epipole off screen);
    /// epipolar otherwise.
    Projective,
    /// Epipolar resampling (§4.1) always.
    Epipolar,
}

/// How the reference ray of a slice is chosen (§3.2, "Transmittance Weighting").
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum ReferenceRay {
    /// The bisectrix between the rays with the smallest and the largest world step per texel
    /// (the paper's default).
    #[default]
    Bisectrix,
    /// k_ref = √(k_min·k_max), the minimiser of the largest step-size ratio; falls back to the
    /// bisectrix where a view ray of the slice is parallel to the light (k_min = 0). Directional
    /// lights only (for a local light the bisectrix is used).
    Optimal,
}

/// The construction chosen for a frame.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Mode {
    /// §4.2.
    Projective,
    /// §4.1.
    Epipolar,
}

impl Mode {
    /// Code shared with WGSL.
    pub fn code(self) -> u32 {
        match self {
            Mode::Projective => 0,
            Mode::Epipolar => 1,
        }
    }
    /// Name.
    pub fn name(self) -> &'static str {
        match self {
            Mode::Projective => "projective",
            Mode::Epipolar => "epipolar",
        }
    }
}

/// What [`Rectification::new`] needs from the settings.
#[derive(Clone, Copy, Debug)]
pub struct RectifyOptions {
    /// Map columns.
    pub width: u32,
    /// Map rows (slices).
    pub height: u32,
    /// Regions per row, 1..=[`MAX_REGIONS`].
    pub regions: u32,
    /// Split between a single projective map (0) and regions of equal x extent (1).
    pub split_lambda: f32,
    /// Which construction.
    pub choice: RectificationChoice,
    /// Largest full angle (degrees) of the projected frustum for `Auto` to go projective.
    pub max_projective_angle: f32,
    /// Reference ray per slice (with one band).
    pub reference: ReferenceRay,
    /// Reference rays (bands) per slice, 1..=[`MAX_BANDS`].
    pub bands: u32,
    /// Largest ratio of the far to the near x of the projective map for `Auto` to go
    /// projective.
    pub max_projective_depth_ratio: f32,
}

/// The fraction of the rays' depth range added at each end before normalising to [0, 1], so
/// that no ray sits on a range end: 1 %. (Occluders between the light and the frustum clamp to
/// depth 0; wider padding keeps the lowest rays further from them but costs the depth
/// resolution every shadow edge needs — 2.5/M and 5/M lost 2–6 dB on stained-glass.)
pub const DEPTH_PADDING: f32 = 0.01;

/// Largest number of reference rays (bands) per slice.
pub const MAX_BANDS: u32 = 8;

/// The per-frame rectification: every number the passes need, computed once on the CPU.
#[derive(Clone, Debug)]
pub struct Rectification {
    /// Construction.
    pub mode: Mode,
    /// Map columns.
    pub width: u32,
    /// Map rows.
    pub height: u32,
    /// Regions per row.
    pub regions: u32,
    /// Camera position.
    pub camera: Vec3,
    /// Light position (local lights).
    pub light: Vec3,
    /// True for a spot or point light.
    pub local: bool,
    /// Projective: the light-view axes (x = bisectrix, y, z = light travel direction).
    /// Epipolar: (e₁, e₂, a): a towards the light, e₁ and e₂ spanning the plane ⊥ a.
    pub axes: [Vec3; 3],
    /// Projective: (q₀, q₁, r₀, r₁), the y/x and z/x ranges. Epipolar: (φ₀, φ₁, θ₀, θ₁).
    pub ranges: Vec4,
    /// Projective: the x boundaries of the regions (regions + 1 of them). Epipolar: [0, c_max]
    /// with c_max the largest column coordinate (distance from the axis, or ψ).
    pub region_x: Vec<f32>,
    /// Epipolar: the slice angle covers the full circle (the epipole or its opposite is in the
    /// frustum), so rows wrap.
    pub full_circle: bool,
    /// Distance from the camera to a local light.
    pub light_distance: f32,
    /// Reference rays (bands) per row.
    pub bands: u32,
    /// Per row and band (`row·bands + band`): the reference ray's r = z/x (projective) or θ
    /// (epipolar), ascending within a row.
    pub rows: Vec<f32>,
    /// The projected frustum's full angle around the bisectrix, degrees (projective; for the stats).
    pub frustum_angle: f32,
}

fn perpendicular(a: Vec3) -> Vec3 {
    if a.x.abs() < 0.9 { Vec3::X.cross(a).normalize() } else { Vec3::Z.cross(a).normalize() }
}

/// Directions of the four frustum corner rays.
fn corner_dirs(desc: &FrameDesc) -> [Vec3; 4] {
    let c = desc.camera.frustum_corners(1.0, 2.0);
    [0, 1, 2, 3].map(|i| (c[i] - desc.camera.position).normalize())
}

/// True when the direction `d` from the camera is inside the view frustum's angular extent,
/// grown by `margin` in NDC.
fn direction_on_screen(desc: &FrameDesc, d: Vec3, margin: f32) -> bool {
    let vp = desc.camera.view_proj();
    let p = desc.camera.position + d;
    let c = vp * p.extend(1.0);
    c.w > 1e-6 && (c.x / c.w).abs() <= 1.0 + margin && (c.y / c.w).abs() <= 1.0 + margin
}

impl Rectification {
    /// The rectification of `desc`'s camera and light under `opt`.
    pub fn new(desc: &FrameDesc, opt: &RectifyOptions) -> Self {
        let local = !matches!(desc.lights[0].light, Light::Directional { .. });
        let projective = if local || opt.choice == RectificationChoice::Epipolar {
            None
        } else {
            Self::projective(desc, opt).filter(|r| {
                opt.choice == RectificationChoice::Projective
                    || (r.frustum_angle <= opt.max_projective_angle
                        && r.region_x[r.regions as usize] / r.region_x[0] <= opt.max_projective_depth_ratio)
            })
        };
        projective.unwrap_or_else(|| Self::epipolar(desc, opt))
    }

    fn base(desc: &FrameDesc, opt: &RectifyOptions, mode: Mode) -> Self {
        let light = crate::integrand::light_position(&desc.lights[0].light);
        Self {
            mode,
            width: opt.width,
            height: opt.height,
            regions: opt.regions.clamp(1, MAX_REGIONS),
            camera: desc.camera.position,
            light,
            local: !matches!(desc.lights[0].light, Light::Directional { .. }),
            axes: [Vec3::X, Vec3::Y, Vec3::Z],
            ranges: Vec4::ZERO,
            region_x: vec![],
            full_circle: false,
            light_distance: (light - desc.camera.position).length(),
            bands: opt.bands.clamp(1, MAX_BANDS),
            rows: vec![],
            frustum_angle: 0.0,
        }
    }

    /// §4.2, Fig. 4. None when a view ray is parallel to the light (the projected frustum spans
    /// 180° or more: the epipole is on screen).
    fn projective(desc: &FrameDesc, opt: &RectifyOptions) -> Option<Self> {
        let Light::Directional { direction, .. } = &desc.lights[0].light else { return None };
        let wl = direction.normalize();
        // The epipole (or its opposite) on or near the screen: view rays (nearly) parallel to
        // the light, the construction is impossible or degenerate (§4.2). A margin of 0.1 in NDC:
        // with the sun exactly on a screen corner the corner ray's projection onto the light
        // plane vanishes, its angle is noise, and the depth range blew up to [−3·10⁵, 3·10³]
        // (found by the robustness sweep).
        if direction_on_screen(desc, wl, 0.1) || direction_on_screen(desc, -wl, 0.1) {
            return None;
        }
        // Standard light view with any up: the plane ⊥ the light, spanned by (p1, p2).
        let p1 = perpendicular(wl);
        let p2 = wl.cross(p1);
        let proj2 = |d: Vec3| glam::Vec2::new(d.dot(p1), d.dot(p2));
        let f2 = proj2(desc.camera.forward());
        if f2.length() < 1e-4 {
            return None;
        }
        let f2 = f2.normalize();
        // Angles of the projected corner rays from the projected forward axis, which lies inside
        // their cone: no wrap-around while the cone is under 180°.
        let mut lo = f32::MAX;
        let mut hi = f32::MIN;
        for d in corner_dirs(desc) {
            let v = proj2(d);
            if v.length() < 1e-6 {
                return None;
            }
            let ang = f2.perp_dot(v).atan2(f2.dot(v));
            lo = lo.min(ang);
            hi = hi.max(ang);
        }
        let span = hi - lo;
        if !(span < std::f32::consts::PI - 1e-3) || lo <= -std::f32::consts::FRAC_PI_2 * 1.999 {
            return None;
        }
        // The 2D bisectrix, made 3D with no light-direction component: the new x axis.
        let mid = 0.5 * (lo + hi);
        let b2 = glam::Vec2::from_angle(mid).rotate(f2);
        let ex = (p1 * b2.x + p2 * b2.y).normalize();
        let ez = wl;
        let ey = ez.cross(ex);
        let mut r = Self::base(desc, opt, Mode::Projective);
        r.axes = [ex, ey, ez];
        r.frustum_angle = span.to_degrees();
        let (mut q0, mut q1, mut r0, mut r1) = (f32::MAX, f32::MIN, f32::MAX, f32::MIN);
        for d in corner_dirs(desc) {
            let l = Vec3::new(d.dot(ex), d.dot(ey), d.dot(ez));
            q0 = q0.min(l.y / l.x);
            q1 = q1.max(l.y / l.x);
            r0 = r0.min(l.z / l.x);
            r1 = r1.max(l.z / l.x);
        }
        if !(q1 - q0).is_finite() || !(r1 - r0).is_finite() || (q1 - q0).max(r1 - r0) > 1e3 {
            return None;
        }
        // Half a row / a little depth of margin so the frustum edges land inside the map.
        let dq = (q1 - q0).max(1e-6) * 0.5 / opt.height as f32;
        let dr = (r1 - r0).max(1e-6) * DEPTH_PADDING;
        r.ranges = Vec4::new(q0 - dq, q1 + dq, r0 - dr, r1 + dr);
        // Near / far along x: the frustum corners (Fig. 4, bottom left).
        let corners = desc.camera.frustum_corners(desc.camera.near, desc.camera.far);
        let xs = corners.map(|c| (c - desc.camera.position).dot(ex));
        let xn = xs[..4].iter().copied().fold(f32::MAX, f32::min).max(1e-4);
        let xf = xs[4..].iter().copied().fold(f32::MIN, f32::max).max(xn * 1.001);
        let n = r.regions;
        let lam = opt.split_lambda.clamp(0.0, 1.0);
        r.region_x = (0..=n)
            .map(|i| {
                let f = i as f32 / n as f32;
                let proj = 1.0 / (1.0 / xn - f * (1.0 / xn - 1.0 / xf));
                let lin = xn + f * (xf - xn);
                (1.0 - lam) * proj + lam * lin
            })
            .collect();
        let (r0, r1, nb) = (r.ranges.z, r.ranges.w, r.bands);
        let rows: Vec<f32> = (0..opt.height)
            .flat_map(|j| {
                let single = r.projective_reference(r.row_q(j as f32 + 0.5), opt.reference);
                // Several bands: the centres of equal cells of r (ascending).
                (0..nb).map(move |b| if nb == 1 { single } else { r0 + (b as f32 + 0.5) / nb as f32 * (r1 - r0) })
            })
            .collect();
        r.rows = rows;
        Some(r)
    }

    /// Row coordinate → y/x of the projective map.
    fn row_q(&self, row: f32) -> f32 {
        self.ranges.x + row / self.height as f32 * (self.ranges.y - self.ranges.x)
    }

    /// The reference ray's r = z/x for the slice y/x = q (§3.2): rays of the slice are
    /// (1, q, r); k(ω) = ω·ω⊥ with ω⊥ = (1, q, 0)/|·| is √(1+q²)/√(1+q²+r²).
    fn projective_reference(&self, q: f32, reference: ReferenceRay) -> f32 {
        let (r0, r1) = (self.ranges.z, self.ranges.w);
        let d0 = Vec3::new(1.0, q, r0).normalize();
        let d1 = Vec3::new(1.0, q, r1).normalize();
        let bis = d0 + d1;
        let r_bis = bis.z / bis.x;
        if reference == ReferenceRay::Bisectrix {
            return r_bis;
        }
        let k = |r: f32| ((1.0 + q * q) / (1.0 + q * q + r * r)).sqrt();
        let k_max = if r0 <= 0.0 && r1 >= 0.0 { 1.0 } else { k(r0).max(k(r1)) };
        let (k_min, r_far) = if k(r0) < k(r1) { (k(r0), r0) } else { (k(r1), r1) };
        if k_min < 1e-4 {
            return r_bis;
        }
        let k_ref = (k_min * k_max).sqrt();
        let r2 = (1.0 + q * q) * (1.0 / (k_ref * k_ref) - 1.0);
        r2.max(0.0).sqrt().copysign(r_far)
    }

    /// §4.1: slices around the camera→light axis.
    fn epipolar(desc: &FrameDesc, opt: &RectifyOptions) -> Self {
        let mut r = Self::base(desc, opt, Mode::Epipolar);
        let c = desc.camera.position;
        let a = match &desc.lights[0].light {
            Light::Directional { direction, .. } => -direction.normalize(),
            _ => (r.light - c).try_normalize().unwrap_or(desc.camera.forward()),
        };
        let fwd = desc.camera.forward();
        let e1 = (fwd - a * a.dot(fwd)).try_normalize().unwrap_or_else(|| perpendicular(a));
        let e2 = a.cross(e1);
        r.axes = [e1, e2, a];
        r.full_circle = direction_on_screen(desc, a, 0.0) || direction_on_screen(desc, -a, 0.0);
        // θ and φ over the frustum: corners, then its four edges sampled densely (the extreme
        // angle to a of a convex cone lies on its boundary).
        let corners = corner_dirs(desc);
        let mut boundary = Vec::with_capacity(4 * 65);
        for i in 0..4 {
            for k in 0..=64 {
                boundary.push(corners[i].lerp(corners[(i + 1) % 4], k as f32 / 64.0).normalize());
            }
        }
        let theta = |d: Vec3| angle_between(d, a);
        let phi = |d: Vec3| d.dot(e2).atan2(d.dot(e1));
        let mut t0 = boundary.iter().map(|&d| theta(d)).fold(f32::MAX, f32::min);
        let mut t1 = boundary.iter().map(|&d| theta(d)).fold(f32::MIN, f32::max);
        if direction_on_screen(desc, a, 0.0) {
            t0 = 0.0;
        }
        if direction_on_screen(desc, -a, 0.0) {
            t1 = std::f32::consts::PI;
        }
        // Padding in θ: not clamped to [0, π] — an occluder beyond the padded range clamps to
        // it, and θ only names a depth here.
        let pad = (t1 - t0).max(1e-4) * DEPTH_PADDING;
        t0 -= pad;
        t1 += pad;
        let (p0, p1) = if r.full_circle {
            (-std::f32::consts::PI, std::f32::consts::PI)
        } else {
            let lo = boundary.iter().map(|&d| phi(d)).fold(f32::MAX, f32::min);
            let hi = boundary.iter().map(|&d| phi(d)).fold(f32::MIN, f32::max);
            let pad = (hi - lo).max(1e-4) * 0.5 / opt.height as f32;
            (lo - pad, hi + pad)
        };
        r.ranges = Vec4::new(p0, p1, t0, t1);
        let c_max = if r.local {
            (std::f32::consts::PI - t0.max(0.0)).max(1e-3)
        } else {
            let cs = desc.camera.frustum_corners(desc.camera.near, desc.camera.far);
            cs.iter().map(|&p| (p - c).reject_from_normalized(a).length()).fold(1e-3, f32::max) * 1.001
        };
        // Columns: for a directional light, warped so that half of them fall within the knee k
        // — the side of the standard shadow map, i.e. the extent of the shadow casters — where
        // the shafts are, instead of spreading evenly to the far plane (linear columns put the
        // colonnade's whole shadow structure in its first 5 % of columns at far = 200 m). Our
        // choice; §4.1 leaves the x parameterisation open. Local lights: ψ linear.
        let knee = if r.local {
            0.0
        } else {
            (desc.lights[0].shadow.texel_world * desc.lights[0].shadow.size as f32).max(1e-3)
        };
        r.region_x = vec![0.0, c_max, knee];
        // Per row: the θ interval of the slice inside the frustum, and its reference ray.
        let planes = frustum_side_normals(&corners);
        let nb = r.bands;
        let rows: Vec<f32> = (0..opt.height)
            .flat_map(|j| {
                let w = r.slice_dir(r.row_phi(j as f32 + 0.5));
                let (lo, hi) = slice_theta_range(a, w, &planes, t0, t1).unwrap_or((t0, t1));
                let single = epipolar_reference(lo, hi, if r.local { ReferenceRay::Bisectrix } else { opt.reference });
                // Several bands: the centres of equal cells of ln θ over [max(lo, hi/32), hi]
                // (ascending): rays near the epipole, where the world step per column changes
                // fastest with θ, get bands of their own.
                let lo = lo.max(hi / 32.0).max(1e-4);
                (0..nb).map(move |b| if nb == 1 { single } else { lo * (hi / lo).powf((b as f32 + 0.5) / nb as f32) })
            })
            .collect();
        r.rows = rows;
        r
    }

    /// Row coordinate → slice angle φ.
    pub fn row_phi(&self, row: f32) -> f32 {
        self.ranges.x + row / self.height as f32 * (self.ranges.y - self.ranges.x)
    }

    /// The unit direction of slice φ perpendicular to the axis: w(φ) = cos φ·e₁ + sin φ·e₂.
    pub fn slice_dir(&self, phi: f32) -> Vec3 {
        self.axes[0] * phi.cos() + self.axes[1] * phi.sin()
    }

    /// The region of column `c`: the r with ⌊r·W/R⌋ ≤ c < ⌊(r+1)·W/R⌋, i.e.
    /// ⌊((c + 1)·R − 1)/W⌋, as [`Rectification::region_columns`] cuts them. Mirrors
    /// `region_of_column` in WGSL.
    pub fn region_of_column(&self, c: u32) -> u32 {
        (((c.min(self.width - 1) + 1) * self.regions - 1) / self.width).min(self.regions - 1)
    }

    /// Columns per region.
    pub fn region_columns(&self, region: u32) -> [u32; 2] {
        [region * self.width / self.regions, (region + 1) * self.width / self.regions]
    }

    /// The column coordinate (in texels, [0, width]) of the boundary at which the light line
    /// `c` (x in the projective map; the distance from the axis or ψ in the epipolar one) is
    /// crossed, and its region. Mirrors `column_of` in WGSL.
    pub fn column_of(&self, c: f32) -> (u32, f32) {
        match self.mode {
            Mode::Projective => {
                let mut r = 0;
                while r + 1 < self.regions && c >= self.region_x[r as usize + 1] {
                    r += 1;
                }
                let (x0, x1) = (self.region_x[r as usize], self.region_x[r as usize + 1]);
                let u = ((1.0 / x0 - 1.0 / c.max(1e-6)) / (1.0 / x0 - 1.0 / x1)).clamp(0.0, 1.0);
                let [a, b] = self.region_columns(r);
                (r, a as f32 + u * (b - a) as f32)
            }
            Mode::Epipolar => {
                let u = column_warp(c, self.region_x[1], self.region_x[2]);
                let col = u * self.width as f32;
                (self.region_of_column(col as u32), col)
            }
        }
    }

    /// Inverse of [`Rectification::column_of`]: the light-line coordinate at column coordinate
    /// `col` (texels). Mirrors `line_of_column` in WGSL.
    pub fn line_of_column(&self, col: f32) -> f32 {
        match self.mode {
            Mode::Projective => {
                let r = self.region_of_column(col.max(0.0) as u32);
                let [a, b] = self.region_columns(r);
                let u = (col - a as f32) / (b - a) as f32;
                let (x0, x1) = (self.region_x[r as usize], self.region_x[r as usize + 1]);
                1.0 / (1.0 / x0 - u * (1.0 / x0 - 1.0 / x1))
            }
            Mode::Epipolar => column_unwarp(col / self.width as f32, self.region_x[1], self.region_x[2]),
        }
    }

    /// World distance along row `row`'s reference ray to where it crosses the light line of
    /// column coordinate `col`; infinite when it never does (a local light's line behind the
    /// ray). Mirrors `reference_distance` in WGSL.
    pub fn reference_distance(&self, row: u32, band: u32, col: f32) -> f32 {
        let c = self.line_of_column(col);
        let rr = self.rows[(row * self.bands + band) as usize];
        match self.mode {
            Mode::Projective => {
                let q = self.row_q(row as f32 + 0.5);
                c * (1.0 + q * q + rr * rr).sqrt()
            }
            Mode::Epipolar if !self.local => c / rr.sin().max(1e-6),
            Mode::Epipolar => {
                if rr + c >= std::f32::consts::PI - 1e-6 {
                    return f32::INFINITY;
                }
                self.light_distance * c.sin() / (rr + c).sin().max(1e-9)
            }
        }
    }

    /// The reference ray's unit direction for row `row`, band `band`.
    pub fn reference_dir(&self, row: u32, band: u32) -> Vec3 {
        let rr = self.rows[(row * self.bands + band) as usize];
        match self.mode {
            Mode::Projective => {
                let q = self.row_q(row as f32 + 0.5);
                let [ex, ey, ez] = self.axes;
                (ex + ey * q + ez * rr).normalize()
            }
            Mode::Epipolar => self.axes[2] * rr.cos() + self.slice_dir(self.row_phi(row as f32 + 0.5)) * rr.sin(),
        }
    }

    /// The bands that bracket the view ray of unit direction `dir` at row coordinate `row`, and
    /// the weight of the second: its r = z/x (projective; linear between bands) or θ (epipolar;
    /// linear in ln θ) against the bands of the nearest row; clamped to the end bands.
    /// Mirrors `band_bracket` in WGSL.
    pub fn band_bracket(&self, row: f32, dir: Vec3) -> (u32, u32, f32) {
        if self.bands == 1 {
            return (0, 0, 0.0);
        }
        let j = (row.max(0.0) as u32).min(self.height - 1);
        let band = |b: u32| self.rows[(j * self.bands + b) as usize];
        let (param, geometric) = match self.mode {
            Mode::Projective => {
                let [ex, _, ez] = self.axes;
                (dir.dot(ez) / dir.dot(ex).max(1e-6), false)
            }
            Mode::Epipolar => (angle_between(dir, self.axes[2]), true),
        };
        let f = |a: f32, b: f32| {
            if geometric { (param.max(1e-6) / a).ln() / (b / a).ln() } else { (param - a) / (b - a) }
        };
        if param <= band(0) {
            return (0, 0, 0.0);
        }
        for b in 0..self.bands - 1 {
            if param < band(b + 1) {
                return (b, b + 1, f(band(b), band(b + 1)).clamp(0.0, 1.0));
            }
        }
        (self.bands - 1, self.bands - 1, 0.0)
    }

    /// Where a world point `p` (on the view ray of unit direction `dir`) falls: (row coordinate in
    /// [0, height], column coordinate in [0, width], its region, the ray's depth in [0, 1]).
    /// Mirrors `rectify_point` in WGSL.
    pub fn rectify_point(&self, p: Vec3, dir: Vec3) -> (f32, f32, u32, f32) {
        let v = p - self.camera;
        match self.mode {
            Mode::Projective => {
                let [ex, ey, ez] = self.axes;
                let l = Vec3::new(dir.dot(ex), dir.dot(ey), dir.dot(ez));
                let lx = l.x.max(1e-6);
                let row = (l.y / lx - self.ranges.x) / (self.ranges.y - self.ranges.x) * self.height as f32;
                let z = (l.z / lx - self.ranges.z) / (self.ranges.w - self.ranges.z);
                let (region, col) = self.column_of(v.dot(ex).max(self.region_x[0]));
                (row, col, region, z.clamp(0.0, 1.0))
            }
            Mode::Epipolar => {
                let [e1, e2, a] = self.axes;
                let mut phi = dir.dot(e2).atan2(dir.dot(e1));
                if !self.full_circle {
                    phi = phi.clamp(self.ranges.x, self.ranges.y);
                }
                let row = (phi - self.ranges.x) / (self.ranges.y - self.ranges.x) * self.height as f32;
                let theta = angle_between(dir, a);
                let z = (theta - self.ranges.z) / (self.ranges.w - self.ranges.z);
                let c = if self.local {
                    let (to_cam, to_p) = (self.camera - self.light, p - self.light);
                    if to_cam.length_squared() > 0.0 && to_p.length_squared() > 0.0 {
                        angle_between(to_cam, to_p)
                    } else {
                        0.0
                    }
                } else {
                    v.reject_from_normalized(a).length()
                };
                let (region, col) = self.column_of(c);
                (row, col, region, z.clamp(0.0, 1.0))
            }
        }
    }

    /// The light line through texel (`col`, `row`) (texel-centre coordinates): a point on it and
    /// the direction in which light travels along it. Mirrors `texel_line` in WGSL.
    pub fn texel_line(&self, col: f32, row: f32) -> (Vec3, Vec3) {
        let c = self.line_of_column(col);
        match self.mode {
            Mode::Projective => {
                let q = self.row_q(row);
                let [ex, ey, ez] = self.axes;
                (self.camera + ex * c + ey * (q * c), ez)
            }
            Mode::Epipolar => {
                let w = self.slice_dir(self.row_phi(row));
                let a = self.axes[2];
                if self.local {
                    (self.light, (-a * c.cos() + w * c.sin()).normalize())
                } else {
                    (self.camera + w * c, -a)
                }
            }
        }
    }

    /// The normalised depth in [0, 1] of the occluder point `o` on the light line of texel
    /// (`col`, `row`). Mirrors `occluder_depth` in WGSL.
    pub fn occluder_depth(&self, col: f32, o: Vec3) -> f32 {
        let v = o - self.camera;
        match self.mode {
            Mode::Projective => {
                let x = self.line_of_column(col);
                ((v.dot(self.axes[2]) / x - self.ranges.z) / (self.ranges.w - self.ranges.z)).clamp(0.0, 1.0)
            }
            Mode::Epipolar => {
                let len = v.length();
                if len < 1e-6 {
                    return 0.0;
                }
                let theta = angle_between(v, self.axes[2]);
                ((theta - self.ranges.z) / (self.ranges.w - self.ranges.z)).clamp(0.0, 1.0)
            }
        }
    }

    /// The host raster request of a projective rectification (None for an epipolar one): one
    /// matrix per region mapping world space to the region's viewport, depth = normalised z.
    pub fn raster(&self) -> Option<RectifiedRaster> {
        if self.mode != Mode::Projective {
            return None;
        }
        let [ex, ey, ez] = self.axes;
        // World → light view (x, y, z, 1) relative to the camera.
        let view = Mat4::from_cols(
            Vec4::new(ex.x, ey.x, ez.x, 0.0),
            Vec4::new(ex.y, ey.y, ez.y, 0.0),
            Vec4::new(ex.z, ey.z, ez.z, 0.0),
            Vec4::new(-ex.dot(self.camera), -ey.dot(self.camera), -ez.dot(self.camera), 1.0),
        );
        let (q0, q1, r0, r1) = (self.ranges.x, self.ranges.y, self.ranges.z, self.ranges.w);
        let regions = (0..self.regions)
            .map(|r| {
                let (x0, x1) = (self.region_x[r as usize], self.region_x[r as usize + 1]);
                // u = (1/x0 − 1/x)/(1/x0 − 1/x1) = A − B/x; NDC x = 2u − 1 ⇒ clip x = (2A − 1)·x − 2B.
                let inv = 1.0 / (1.0 / x0 - 1.0 / x1);
                let a = inv / x0;
                // Rows: v = (y/x − q0)/(q1 − q0), NDC y = 1 − 2v ⇒ clip y = x + 2q0/(q1−q0)·x − 2y/(q1−q0).
                let sq = 2.0 / (q1 - q0);
                // Depth: z/x normalised ⇒ clip z = (z − r0·x)/(r1 − r0).
                let sr = 1.0 / (r1 - r0);
                let proj = Mat4::from_cols(
                    Vec4::new(2.0 * a - 1.0, 1.0 + sq * q0, -r0 * sr, 1.0),
                    Vec4::new(0.0, -sq, 0.0, 0.0),
                    Vec4::new(0.0, 0.0, sr, 0.0),
                    Vec4::new(-2.0 * inv, 0.0, 0.0, 0.0),
                );
                RasterRegion { view_proj: proj * view, columns: self.region_columns(r) }
            })
            .collect();
        Some(RectifiedRaster { width: self.width, height: self.height, regions })
    }
}

/// The epipolar map's column coordinate u ∈ [0, 1] of the light line at `c` ∈ [0, c_max]:
/// u = c/(c + k) · (c_max + k)/c_max, a projective warp with knee `k` (linear for k = 0).
/// Mirrors `column_warp` in WGSL.
pub fn column_warp(c: f32, c_max: f32, k: f32) -> f32 {
    if k <= 0.0 {
        return (c / c_max).clamp(0.0, 1.0);
    }
    (c.max(0.0) / (c.max(0.0) + k) * (c_max + k) / c_max).clamp(0.0, 1.0)
}

/// Inverse of [`column_warp`]. Mirrors `column_unwarp` in WGSL.
pub fn column_unwarp(u: f32, c_max: f32, k: f32) -> f32 {
    if k <= 0.0 {
        return u * c_max;
    }
    let v = u * c_max / (c_max + k);
    k * v / (1.0 - v).max(1e-9)
}

/// Inward normals of the frustum's four side planes from its corner rays (in order around it).
fn frustum_side_normals(corners: &[Vec3; 4]) -> [Vec3; 4] {
    let centre = (corners[0] + corners[1] + corners[2] + corners[3]).normalize();
    [0, 1, 2, 3].map(|i| {
        let n = corners[i].cross(corners[(i + 1) % 4]).normalize();
        if n.dot(centre) < 0.0 { -n } else { n }
    })
}

/// The θ interval of one slice inside the view frustum: the smallest [lo, hi] ⊂ [t0, t1] that
/// holds every θ whose direction d(θ) = a·cos θ + w·sin θ lies inside the frustum's four side
/// planes (n·d ≥ −10⁻⁶ for each inward normal n); None where no θ in [t0, t1] does.
///
/// In closed form, once per row and frame: n·d(θ) = A·cos θ + B·sin θ = R·cos(θ − α) with
/// A = n·a, B = n·w, R = √(A² + B²), α = atan2(B, A), so each plane keeps the arc
/// |θ − α| ≤ acos(−10⁻⁶/R) (mod 2π), and the slice keeps the intersection of four such arcs
/// with [t0, t1] (a plane with R = 0 keeps every θ). Where that intersection is two pieces
/// (possible only when [t0, t1], padded, is longer than π), the interval spans both.
fn slice_theta_range(a: Vec3, w: Vec3, planes: &[Vec3; 4], t0: f32, t1: f32) -> Option<(f32, f32)> {
    use std::f32::consts::TAU;
    // The set kept so far: disjoint intervals of [t0, t1]. Each plane's arc is shorter than
    // 2π − (its gap), so it meets an interval in at most two pieces, and four planes leave at
    // most a handful (bounded here by 8: a fixed array, no allocation per row).
    let mut kept = [(t0, t1); 8];
    let mut count = 1;
    for n in planes {
        let (ca, cb) = (n.dot(a), n.dot(w));
        let r = ca.hypot(cb);
        if r <= 1e-6 {
            continue;
        }
        let alpha = cb.atan2(ca);
        let half = (-1e-6 / r).clamp(-1.0, 1.0).acos();
        let mut next = [(0.0, 0.0); 8];
        let mut next_count = 0;
        for &(lo, hi) in &kept[..count] {
            // The arc's copies that can meet [lo, hi] ⊂ [t0, t1] ⊂ [−π − 1, 2π + 1].
            for k in -1..=2 {
                let centre = alpha + k as f32 * TAU;
                let (a0, a1) = ((centre - half).max(lo), (centre + half).min(hi));
                if a0 <= a1 && next_count < next.len() {
                    next[next_count] = (a0, a1);
                    next_count += 1;
                }
            }
        }
        if next_count == 0 {
            return None;
        }
        (kept, count) = (next, next_count);
    }
    let lo = kept[..count].iter().map(|k| k.0).fold(f32::MAX, f32::min);
    let hi = kept[..count].iter().map(|k| k.1).fold(f32::MIN, f32::max);
    Some((lo, hi))
}

/// The reference angle θ_ref in the θ interval [lo, hi] of a slice, measured from the axis
/// towards the light; the direction ⊥ to the light in the slice is θ = 90°, so k = sin θ.
fn epipolar_reference(lo: f32, hi: f32, reference: ReferenceRay) -> f32 {
    let bis = 0.5 * (lo + hi);
    if reference == ReferenceRay::Bisectrix {
        return bis;
    }
    let half = std::f32::consts::FRAC_PI_2;
    let k_max = if lo <= half && hi >= half { 1.0 } else { lo.sin().max(hi.sin()) };
    let (k_min, far) = if lo.sin() < hi.sin() { (lo.sin(), lo) } else { (hi.sin(), hi) };
    if k_min < 1e-4 {
        return bis;
    }
    let s = (k_min * k_max).sqrt().asin();
    if far < half { s } else { std::f32::consts::PI - s }
}

/// The first occluder on the light line through `p` travelling along `dir`, from the standard
/// shadow map, pushed `bias` further along the line; None when the line is outside the map or
/// nothing was drawn on it (the line is lit everywhere). Mirrors `line_occluder` in WGSL.
pub fn line_occluder(shadow: &ShadowMap, light_pos: Vec3, p: Vec3, dir: Vec3, bias: f32) -> Option<Vec3> {
    let pr = &shadow.projection;
    // A point on the line in front of the light: the line point itself for an orthographic map,
    // the point at unit distance along the line from the light otherwise.
    let q = if pr.orthographic { p } else { light_pos + dir };
    let layer = if pr.layers == 6 { cube_face(dir) } else { 0 };
    let c = pr.view_proj[layer as usize] * q.extend(1.0);
    if c.w <= 0.0 {
        return None;
    }
    let ndc = c.xyz() / c.w;
    if ndc.x.abs() > 1.0 || ndc.y.abs() > 1.0 {
        return None;
    }
    let n = pr.size as f32;
    let tx = ((ndc.x * 0.5 + 0.5) * n).floor().min(n - 1.0) as u32;
    let ty = ((0.5 - ndc.y * 0.5) * n).floor().min(n - 1.0) as u32;
    let d = shadow.texel(layer, tx, ty);
    if pr.is_empty(d) {
        return None;
    }
    let stored = pr.linear(d);
    let o = if pr.orthographic { q + dir * (stored - pr.linear(ndc.z)) } else { light_pos + dir * (stored / c.w) };
    Some(o + dir * bias)
}

/// The angle between `a` and `b` (any non-zero lengths), atan2(|a × b|, a · b): well
/// conditioned near 0 and π, where acos of the normalised dot product loses √(2ε) ≈ 3.5e-4 rad
/// in f32. Mirrors `angle_between` in geometry.wgsl.
pub fn angle_between(a: Vec3, b: Vec3) -> f32 {
    a.cross(b).length().atan2(a.dot(b))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::{Camera, Medium};
    use crate::shadow::ShadowProjection;

    fn desc(light: Light, camera: Camera) -> FrameDesc {
        let bounds = crate::shadow::Bounds { min: Vec3::splat(-10.0), max: Vec3::splat(10.0) };
        let shadow = ShadowProjection::fit(&light, &camera, 16.0 / 9.0, bounds, 256);
        let mut light = crate::FrameLight::new(light, shadow);
        light.shadow_bias = 0.0;
        FrameDesc {
            camera: crate::FrameCamera::look_at(&camera, 16.0 / 9.0).unwrap(),
            lights: vec![light],
            medium: Medium::default(),
            width: 160,
            height: 90,
        }
    }

    fn sun(dir: Vec3) -> Light {
        Light::Directional { direction: dir.normalize(), color: Vec3::ONE, intensity: 1.0 }
    }

    fn opts(choice: RectificationChoice, regions: u32, lambda: f32) -> RectifyOptions {
        RectifyOptions {
            width: 256,
            height: 128,
            regions,
            split_lambda: lambda,
            choice,
            max_projective_angle: 150.0,
            reference: ReferenceRay::Bisectrix,
            bands: 2,
            max_projective_depth_ratio: f32::INFINITY,
        }
    }

    /// Every view ray keeps one row and one depth along its whole length, runs left to right, and
    /// the camera frustum maps inside [0, 1] (ISSUE 4, tests: the rectification's math).
    #[test]
    fn view_rays_keep_one_row_and_one_depth() {
        let cam = Camera { position: Vec3::new(0.0, 2.0, 8.0), look_at: Vec3::new(0.0, 1.0, 0.0), ..Camera::default() };
        for (light, choice) in [
            (sun(Vec3::new(1.0, -0.6, 0.2)), RectificationChoice::Projective),
            (sun(Vec3::new(1.0, -0.6, 0.2)), RectificationChoice::Epipolar),
            (sun(Vec3::new(0.1, -0.3, 1.0)), RectificationChoice::Epipolar),
            (
                Light::Point { position: Vec3::new(1.0, 3.0, 0.0), color: Vec3::ONE, intensity: 1.0 },
                RectificationChoice::Auto,
            ),
        ] {
            for regions in [1, 3] {
                let d = desc(light.clone(), cam.clone());
                let r = Rectification::new(&d, &opts(choice, regions, 0.5));
                for (x, y) in [(0, 0), (159, 0), (0, 89), (159, 89), (80, 45), (13, 70)] {
                    let dir = d.pixel_ray(x, y);
                    let mut last_col = -1.0;
                    let mut first = None;
                    for t in [0.5f32, 1.0, 3.0, 10.0, 50.0, 190.0] {
                        let (row, col, _, z) = r.rectify_point(d.camera.position + dir * t, dir);
                        assert!((0.0..=r.height as f32).contains(&row), "{:?} row {row}", r.mode);
                        assert!((0.0..=r.width as f32).contains(&col));
                        assert!(z > 0.0 && z < 1.0, "{:?} depth {z}", r.mode);
                        let (r0, z0) = *first.get_or_insert((row, z));
                        assert!((row - r0).abs() < 1e-3 * r.height as f32, "{:?}: row {row} vs {r0}", r.mode);
                        assert!((z - z0).abs() < 1e-4, "{:?}: depth {z} vs {z0}", r.mode);
                        assert!(col >= last_col - 1e-3, "{:?}: columns go backwards: {col} after {last_col}", r.mode);
                        last_col = col;
                    }
                }
            }
        }
    }

    /// The projective map is one matrix per region: the raster request maps a world point to the
    /// same row, column and depth as `rectify_point`.
    #[test]
    fn raster_matrix_agrees_with_rectify_point() {
        let cam = Camera { position: Vec3::new(0.0, 2.0, 8.0), look_at: Vec3::new(0.0, 1.0, 0.0), ..Camera::default() };
        let d = desc(sun(Vec3::new(1.0, -0.6, 0.2)), cam);
        for regions in [1, 2, 4] {
            let r = Rectification::new(&d, &opts(RectificationChoice::Projective, regions, 0.3));
            assert_eq!(r.mode, Mode::Projective);
            let raster = r.raster().unwrap();
            for p in [Vec3::new(0.0, 0.0, 0.0), Vec3::new(3.0, 1.0, -4.0), Vec3::new(-2.0, 0.5, 5.0)] {
                let dir = (p - r.camera).normalize();
                let (row, col, region, z) = r.rectify_point(p, dir);
                let reg = &raster.regions[region as usize];
                let c = reg.view_proj * p.extend(1.0);
                let ndc = c.xyz() / c.w;
                let w = (reg.columns[1] - reg.columns[0]) as f32;
                let col2 = reg.columns[0] as f32 + (ndc.x * 0.5 + 0.5) * w;
                let row2 = (0.5 - ndc.y * 0.5) * r.height as f32;
                assert!((col - col2).abs() < 1e-2, "column {col} vs {col2}");
                assert!((row - row2).abs() < 1e-2, "row {row} vs {row2}");
                assert!((z - ndc.z).abs() < 1e-4, "depth {z} vs {}", ndc.z);
            }
        }
    }

    /// The reference distance inverts the column mapping: the point at that distance along the
    /// reference ray rectifies back to the column.
    #[test]
    fn reference_distance_lands_on_its_column() {
        let cam = Camera { position: Vec3::new(0.0, 2.0, 8.0), look_at: Vec3::new(0.0, 1.0, 0.0), ..Camera::default() };
        for (light, choice) in [
            (sun(Vec3::new(1.0, -0.6, 0.2)), RectificationChoice::Projective),
            (sun(Vec3::new(1.0, -0.6, 0.2)), RectificationChoice::Epipolar),
            (
                Light::Point { position: Vec3::new(1.0, 3.0, 0.0), color: Vec3::ONE, intensity: 1.0 },
                RectificationChoice::Auto,
            ),
        ] {
            let d = desc(light, cam.clone());
            let r = Rectification::new(&d, &opts(choice, 2, 0.0));
            for (row, band) in [(0, 0), (40, 1), (127, 0)] {
                for col in [3.0f32, 64.0, 130.0, 200.0] {
                    let t = r.reference_distance(row, band, col);
                    if !t.is_finite() || t > 180.0 {
                        continue;
                    }
                    let dir = r.reference_dir(row, band);
                    let (row2, col2, _, _) = r.rectify_point(r.camera + dir * t, dir);
                    assert!((col2 - col).abs() < 0.05, "{:?} row {row}: column {col} → t {t} → {col2}", r.mode);
                    assert!((row2 - (row as f32 + 0.5)).abs() < 0.05, "{:?}: row {row} → {row2}", r.mode);
                }
            }
        }
    }

    /// The closed-form θ interval of a slice (`slice_theta_range`) is the interval a dense scan
    /// of the slice's directions finds inside the frustum, to within the scan's step, for suns
    /// and lamps on and off screen, in front of and behind the camera (the epipole and its
    /// opposite on screen), and every row.
    #[test]
    fn a_slices_theta_range_is_the_dense_scans() {
        let cam = Camera { position: Vec3::new(0.0, 2.0, 8.0), look_at: Vec3::new(0.0, 1.0, 0.0), ..Camera::default() };
        let mut checked = 0;
        for light in [
            sun(Vec3::new(1.0, -0.6, 0.2)),
            sun(Vec3::new(0.1, -0.3, 1.0)),
            sun(Vec3::new(0.0, -0.2, -1.0)),
            sun(Vec3::new(0.0, -1.0, 0.0)),
            Light::Point { position: Vec3::new(1.0, 3.0, 0.0), color: Vec3::ONE, intensity: 1.0 },
            Light::Point { position: Vec3::new(0.0, 2.0, 20.0), color: Vec3::ONE, intensity: 1.0 },
        ] {
            let d = desc(light, cam.clone());
            let r = Rectification::new(&d, &opts(RectificationChoice::Epipolar, 1, 0.0));
            let [e1, e2, a] = r.axes;
            let planes = frustum_side_normals(&corner_dirs(&d));
            let (t0, t1) = (r.ranges.z, r.ranges.w);
            let n = 20000;
            let step = (t1 - t0) / n as f32;
            for j in 0..r.height {
                let phi = r.row_phi(j as f32 + 0.5);
                let w = e1 * phi.cos() + e2 * phi.sin();
                let inside = |t: f32| planes.iter().all(|p| p.dot(a * t.cos() + w * t.sin()) >= -1e-6);
                let ts: Vec<f32> =
                    (0..=n).map(|k| t0 + (t1 - t0) * k as f32 / n as f32).filter(|&t| inside(t)).collect();
                let got = slice_theta_range(a, w, &planes, t0, t1);
                match (ts.first(), ts.last(), got) {
                    (Some(&lo), Some(&hi), Some((glo, ghi))) => {
                        assert!(
                            glo <= lo + 1e-4 && glo >= lo - step - 1e-4,
                            "row {j}: lo {glo} against the scan's {lo}"
                        );
                        assert!(
                            ghi >= hi - 1e-4 && ghi <= hi + step + 1e-4,
                            "row {j}: hi {ghi} against the scan's {hi}"
                        );
                        checked += 1;
                    }
                    (None, None, None) => {}
                    (lo, hi, got) => panic!("row {j}: the scan found {lo:?}..{hi:?}, the closed form {got:?}"),
                }
            }
        }
        assert!(checked > 500, "only {checked} rows had a range");
    }

    #[test]
    fn auto_goes_epipolar_when_the_sun_is_on_screen() {
        let cam = Camera { position: Vec3::new(0.0, 1.0, 8.0), look_at: Vec3::new(0.0, 1.0, 0.0), ..Camera::default() };
        // The sun straight ahead, slightly above: its epipole is on screen.
        let d = desc(sun(Vec3::new(0.0, -0.2, 1.0)), cam.clone());
        let r = Rectification::new(&d, &opts(RectificationChoice::Auto, 1, 0.0));
        assert_eq!(r.mode, Mode::Epipolar);
        assert!(r.full_circle);
        // From the side: projective.
        let d = desc(sun(Vec3::new(1.0, -0.5, 0.0)), cam);
        let r = Rectification::new(&d, &opts(RectificationChoice::Auto, 1, 0.0));
        assert_eq!(r.mode, Mode::Projective);
        assert!(r.frustum_angle < 150.0);
    }
}
