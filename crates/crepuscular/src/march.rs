//! Where a ray-marching technique puts its N steps on a view ray: the spot-light step policy
//! of Wyman & Ramsey 2008, Appendix B, and equiangular steps about a local light
//! (docs/MODEL.md §9), shared by `brute-force`, `interleaved`, `subsampled`, `epipolar` and the
//! local-light quadratures of `prefiltered` and `minmax`. Each function has a WGSL twin of the same name in `shaders/common.wgsl`
//! (`cone_interval`, `appendix_b_chord`, `march_interval`), with the same f32 arithmetic.
//!
//! Every policy returns an interval [t₀, t₁] of the view ray, measured from the eye, inside
//! [0, s] (s = distance to the visible surface or the far plane): no policy ever marches past
//! the surface or the far plane. For directional and point lights every spot policy is `Fixed`;
//! [`LocalSteps`] then says how a point or spot light's steps are spread over the interval.

use crate::error::Error;
use crate::frame::FrameLight;
use crate::frame::{CpuFrame, FrameDesc};
use crate::integrand::inscatter_density;
use crate::model::Light;
use crate::model::segment_transmittance;
use glam::{Vec3, Vec4};
use serde::{Deserialize, Serialize};

/// How the N steps of a ray are placed for a spot light (`spot_steps` in every ray-marching
/// technique's settings).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum SpotSteps {
    /// N steps from the eye to the surface, as for any light. Most steps of a ray that only
    /// grazes the cone fall outside it and are wasted. The default.
    #[default]
    Fixed,
    /// N steps over the exact chord of the ray inside the spot's cone (outer half-angle), from a
    /// ray–cone intersection; rays that miss the cone cost nothing. Exact: the light is zero
    /// outside the cone.
    ExactCone,
    /// Wyman & Ramsey 2008, App. B, eq. 3 with a constant denominator: from the point where the
    /// ray enters the cone, march Δ = d·sinφ / `spot_denominator`. Cheap, but some rays stop
    /// before the cone's far side and others march past it.
    AppendixBConstant,
    /// Wyman & Ramsey 2008, App. B, eq. 3–4: Δ = d·sinφ / sin(β − φ/2), with the denominator
    /// clamped smoothly (smoothstep) to at least about `spot_denominator`, so Δ stays bounded
    /// as the ray turns parallel to the cone's edge (β → φ/2).
    AppendixBSmoothstep,
}

impl SpotSteps {
    /// Code shared with WGSL (`march_interval`).
    pub fn code(self) -> u32 {
        match self {
            SpotSteps::Fixed => 0,
            SpotSteps::ExactCone => 1,
            SpotSteps::AppendixBConstant => 2,
            SpotSteps::AppendixBSmoothstep => 3,
        }
    }

    /// Every policy, for sweeps.
    pub const ALL: [SpotSteps; 4] =
        [SpotSteps::Fixed, SpotSteps::ExactCone, SpotSteps::AppendixBConstant, SpotSteps::AppendixBSmoothstep];

    /// The name used in settings.
    pub fn name(self) -> &'static str {
        match self {
            SpotSteps::Fixed => "fixed",
            SpotSteps::ExactCone => "exact-cone",
            SpotSteps::AppendixBConstant => "appendix-b-constant",
            SpotSteps::AppendixBSmoothstep => "appendix-b-smoothstep",
        }
    }
}

/// Default of every technique's `spot_denominator`.
pub const DEFAULT_SPOT_DENOMINATOR: f32 = 0.3;

/// Checks a technique's `spot_denominator` (`key` names it in the error).
pub fn validate_spot_denominator(key: &str, v: f32) -> Result<(), Error> {
    if !(v.is_finite() && v > 0.0 && v <= 1.0) {
        return Err(Error::invalid(key, v, "must be in (0, 1]"));
    }
    Ok(())
}

/// How the N steps of a local (spot or point) light's march are spread over its interval
/// (`local_steps` in every ray-marching technique's settings; docs/MODEL.md §9 has the model
/// and the measurements). A sun is always marched in equal steps.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum LocalSteps {
    /// Equal steps in distance along the ray (eq. 1 of Tóth & Umenhoffer 2009), as for the sun;
    /// a point light then shares one march with the other lights that share theirs. Where a ray
    /// passes within a step of the light, its 1/d² peak falls between samples or on one, and
    /// neighbouring pixels disagree by up to the peak (the robustness sweep's point lights next
    /// to the view rays: NMAE up to 0.58 at 64 steps, converging only slowly with N).
    Uniform,
    /// Equal steps in the angle the ray subtends at the light: short steps where the ray passes
    /// the light, long ones far from it, so each step carries about the same share of the 1/d²
    /// falloff, which is then integrated exactly. The default: it fixes those views (0.58 →
    /// 0.002) and gains up to 26 dB on the built-in local-light scenes (docs/MODEL.md §9).
    /// Costs a sine and cosine per step boundary, N more samples per point light on rays that
    /// also see a sun (every local light gets its own march), and far from the light its steps
    /// are coarser than uniform ones, so the worst pixel of a smooth unshadowed frame converges
    /// more slowly with N.
    #[default]
    Equiangular,
}

/// Bit of [`StepPolicy::code`] set for [`LocalSteps::Equiangular`] (`MARCH_EQUIANGULAR` in
/// common.wgsl).
pub const EQUIANGULAR_BIT: u32 = 4;

/// The bits of [`StepPolicy::code`] that hold the [`SpotSteps`] code (`MARCH_SPOT_MASK`).
const SPOT_CODE_MASK: u32 = 3;

/// Where a ray-marching technique puts its steps for local lights: the settings `spot_steps`,
/// `spot_denominator` and `local_steps` that every technique which marches shares (flattened
/// into its settings, so a scene file writes them as keys of the technique's own table).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct StepPolicy {
    /// Where the N steps go for a spot light (Wyman & Ramsey 2008, App. B): `"fixed"` (eye to
    /// surface), `"exact-cone"` (the ray's chord inside the cone), `"appendix-b-constant"`,
    /// `"appendix-b-smoothstep"`. Ignored for other lights. The cone policies cost one ray–cone
    /// intersection per pixel and skip rays that miss the cone. Default `"exact-cone"` (the
    /// robustness sweep: on a spot aimed across the view, `"fixed"` is off by 108 % NMAE,
    /// `"exact-cone"` by 0.4 %; docs/ROBUSTNESS.md).
    #[serde(rename = "spot_steps")]
    pub spot: SpotSteps,
    /// The App. B denominator (`spot_denominator`): the constant of `appendix-b-constant`, the
    /// smoothstep floor of `appendix-b-smoothstep` (a sine, in (0, 1]). Smaller marches longer
    /// chords. Default 0.3.
    #[serde(rename = "spot_denominator")]
    pub denominator: f32,
    /// How a point or spot light's steps are spread over its interval (`local_steps`):
    /// `"equiangular"` (equal angles seen from the light, so a 1/d² peak narrower than a step
    /// is resolved; every local light gets its own march) or `"uniform"` (equal lengths, as
    /// eq. 1). Ignored for a sun. Cost and effect, measured: [`LocalSteps`] and docs/MODEL.md
    /// §9. Default `"equiangular"`.
    #[serde(rename = "local_steps")]
    pub local: LocalSteps,
}

impl Default for StepPolicy {
    fn default() -> Self {
        Self { spot: SpotSteps::ExactCone, denominator: DEFAULT_SPOT_DENOMINATOR, local: LocalSteps::Equiangular }
    }
}

impl StepPolicy {
    /// Checks the ranges; `technique` prefixes the key in the error (`epipolar.spot_denominator`).
    pub fn validate(&self, technique: &str) -> Result<(), Error> {
        validate_spot_denominator(&format!("{technique}.spot_denominator"), self.denominator)
    }

    /// The code the shaders read (`spot_steps` in the techniques' uniforms): the
    /// [`SpotSteps::code`] in bits 0–1, [`EQUIANGULAR_BIT`] for equiangular steps.
    pub fn code(self) -> u32 {
        self.spot.code() | if self.local == LocalSteps::Equiangular { EQUIANGULAR_BIT } else { 0 }
    }

    /// The policy of a [`StepPolicy::code`] (unknown spot codes read as `fixed`).
    pub fn from_code(code: u32, denominator: f32) -> Self {
        StepPolicy {
            spot: SpotSteps::ALL.get((code & SPOT_CODE_MASK) as usize).copied().unwrap_or_default(),
            denominator,
            local: if code & EQUIANGULAR_BIT != 0 { LocalSteps::Equiangular } else { LocalSteps::Uniform },
        }
    }
}

/// The spot cone as the shaders see it: apex, unit axis, cos of the outer half-angle.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SpotCone {
    /// Apex (the light's position).
    pub apex: Vec3,
    /// Unit axis.
    pub axis: Vec3,
    /// cos of the outer half-angle φ/2 (the cone reaches zero there).
    pub cos_half: f32,
}

impl SpotCone {
    /// The cone of a spot light, computed as `FrameDesc::uniforms` does; None for other lights.
    pub fn of(light: &Light) -> Option<SpotCone> {
        match light {
            Light::Spot { position, direction, outer_angle_degrees, .. } => Some(SpotCone {
                apex: *position,
                axis: direction.normalize(),
                cos_half: outer_angle_degrees.to_radians().cos(),
            }),
            _ => None,
        }
    }

    /// Whether `p` is inside the (forward) cone.
    pub fn contains(&self, p: Vec3) -> bool {
        let v = p - self.apex;
        v.dot(self.axis) >= self.cos_half * v.length()
    }
}

/// The part of the ray `o + t·d`, t in [0, s], inside the cone: Some((t₀, t₁)) or None.
/// The cone (half-angle < 90°) is convex, so the part is one interval: solve the quadratic
/// (v·a)² = cos²·|v|² for its roots, split [0, s] there, and keep the pieces whose midpoints
/// are inside. Mirrors `cone_interval` in common.wgsl.
pub fn cone_interval(cone: &SpotCone, o: Vec3, d: Vec3, s: f32) -> Option<(f32, f32)> {
    if s <= 0.0 {
        return None;
    }
    let v = o - cone.apex;
    let c2 = cone.cos_half * cone.cos_half;
    let dv = d.dot(cone.axis);
    let va = v.dot(cone.axis);
    let qa = dv * dv - c2;
    let qb = 2.0 * (dv * va - c2 * d.dot(v));
    let qc = va * va - c2 * v.dot(v);
    let mut cuts = [s, s];
    if qa.abs() > 1e-7 {
        let disc = qb * qb - 4.0 * qa * qc;
        if disc >= 0.0 {
            let q = -0.5 * (qb + qb.signum() * disc.sqrt());
            cuts[0] = q / qa;
            cuts[1] = if q != 0.0 { qc / q } else { cuts[0] };
        }
    } else if qb != 0.0 {
        cuts[0] = -qc / qb;
    }
    let lo = cuts[0].min(cuts[1]).clamp(0.0, s);
    let hi = cuts[0].max(cuts[1]).clamp(0.0, s);
    let bounds = [0.0, lo, hi, s];
    let (mut t0, mut t1) = (s, 0.0f32);
    for i in 0..3 {
        let (a, b) = (bounds[i], bounds[i + 1]);
        if b > a && cone.contains(o + d * (0.5 * (a + b))) {
            t0 = t0.min(a);
            t1 = t1.max(b);
        }
    }
    if t1 > t0 { Some((t0, t1)) } else { None }
}

/// Wyman & Ramsey 2008, App. B, eq. 3–4: the chord Δ = d·sinφ / sin(β − φ/2) of a ray that
/// enters the light frustum at distance `d` from the light, with cos β = `cos_beta` (the angle
/// between the eye ray and the light's viewing direction) and φ/2 the cone's half-angle.
/// Returns (d·sinφ, sin(β − φ/2)) so the caller can apply a remedy to the denominator.
/// Mirrors `appendix_b_chord` in common.wgsl.
pub fn appendix_b_chord(d: f32, cos_beta: f32, cos_half: f32) -> (f32, f32) {
    let sin_half = (1.0 - cos_half * cos_half).max(0.0).sqrt();
    let sin_phi = 2.0 * sin_half * cos_half; // sin φ = 2 sin(φ/2) cos(φ/2)
    let sin_beta = (1.0 - cos_beta * cos_beta).max(0.0).sqrt(); // App. B: sin β = √(1 − cos²β)
    (d * sin_phi, sin_beta * cos_half - cos_beta * sin_half) // eq. 4
}

/// App. B's second remedy: the denominator clamped to a floor `k` with smoothstep (a Bernstein
/// interpolant), so the step size changes smoothly: `den` for den ≥ 2k, `k` for den ≤ 0.
pub fn smooth_denominator(den: f32, k: f32) -> f32 {
    let t = (den / (2.0 * k)).clamp(0.0, 1.0);
    let w = t * t * (3.0 - 2.0 * t);
    k + (den - k) * w
}

/// Optical depth along the light path beyond which a local light's contribution is dropped:
/// −ln 10⁻⁶, i.e. light-path transmittance below 10⁻⁶ in the least-extinguished channel.
pub const REACH_OPTICAL_DEPTH: f32 = 13.815511;

/// The sphere around a local (spot or point) light outside which its light has crossed more
/// than [`REACH_OPTICAL_DEPTH`] of medium in every channel: (centre, radius R = 13.8 / min σt).
/// None for directional lights and when some channel has σt = 0 (the light reaches everywhere).
/// In light fog (σt = 0.025 m⁻¹) R = 553 m and nothing changes; in a dense medium (σt = 5 m⁻¹)
/// R = 2.8 m, and the N steps go where there is light instead of 200 m of darkness.
/// Mirrors `light_reach` in common.wgsl.
pub fn light_reach(fl: &FrameLight, medium: &crate::Medium) -> Option<(Vec3, f32)> {
    let sigma = medium.extinction().min_element();
    match &fl.light {
        Light::Directional { .. } => None,
        _ if sigma <= 0.0 => None,
        Light::Spot { position, .. } | Light::Point { position, .. } => Some((*position, REACH_OPTICAL_DEPTH / sigma)),
    }
}

/// What a march needs of each light that reaches the view: its index in the frame's lights,
/// its spot cone and its reach. Built once per frame ([`MarchLights::of`]).
#[derive(Clone, Debug, Default)]
pub struct MarchLights {
    /// Indices into [`FrameDesc::lights`] ([`FrameDesc::scattering_lights`]).
    pub indices: Vec<usize>,
    /// Each light's cone ([`SpotCone::of`]).
    pub cones: Vec<Option<SpotCone>>,
    /// Each light's reach ([`light_reach`]).
    pub reaches: Vec<Option<(Vec3, f32)>>,
    /// Each local light's position (None for a sun): the centre of its equiangular steps.
    pub centres: Vec<Option<Vec3>>,
}

impl MarchLights {
    /// The lights of `desc` that reach the view.
    pub fn of(desc: &FrameDesc) -> Self {
        let indices = desc.scattering_lights();
        let cones = indices.iter().map(|&k| SpotCone::of(&desc.lights[k].light)).collect();
        let reaches = indices.iter().map(|&k| light_reach(&desc.lights[k], &desc.medium)).collect();
        let centres = indices.iter().map(|&k| local_position(&desc.lights[k].light)).collect();
        Self { indices, cones, reaches, centres }
    }

    /// True when light `i` (of [`MarchLights::indices`]) is marched over its own interval
    /// with its own N steps: a spot under a cone policy (its chord is its own; marching it
    /// with the others would spread its samples over their longer interval), and every local
    /// light under equiangular steps (its steps are placed about its own position). Every
    /// other light shares one march. Mirrors `own_interval` in WGSL.
    pub fn owns_interval(&self, i: usize, policy: StepPolicy) -> bool {
        (self.cones[i].is_some() && policy.spot != SpotSteps::Fixed)
            || (self.centres[i].is_some() && policy.local == LocalSteps::Equiangular)
    }

    /// The steps of light `i`'s own march over `iv` ([`MarchLights::owns_interval`]):
    /// equiangular about the light under [`LocalSteps::Equiangular`], else uniform.
    pub fn own_steps(&self, i: usize, iv: (f32, f32), n: u32, o: Vec3, d: Vec3, policy: StepPolicy) -> Steps {
        Steps::of_light(self.centres[i], iv, n, o, d, policy)
    }

    /// The shared march of the view ray o + t·d, t in [0, s]: the smallest interval holding
    /// the [`march_interval`] of every light that does not own one ((0, s) as soon as one is
    /// directional), and the set of those lights whose interval is not empty on this ray; the
    /// others are not evaluated at its samples (a local light's reach missed by the ray costs
    /// nothing there). Empty (0, 0) with no lights when none reaches the ray. Mirrors
    /// `shared_march` in WGSL.
    pub fn shared_march(&self, o: Vec3, d: Vec3, s: f32, policy: StepPolicy) -> ((f32, f32), LightSet) {
        let (mut lo, mut hi) = (f32::MAX, f32::MIN);
        let mut set = LightSet::EMPTY;
        for i in 0..self.indices.len() {
            if self.owns_interval(i, policy) {
                continue;
            }
            let iv = march_interval(self.cones[i].as_ref(), self.reaches[i], o, d, s, policy);
            if iv.1 > iv.0 {
                lo = lo.min(iv.0);
                hi = hi.max(iv.1);
                set = set.with(i);
            }
        }
        if hi > lo { ((lo, hi), set) } else { ((0.0, 0.0), LightSet::EMPTY) }
    }

    /// Light `i`'s own [`march_interval`].
    pub fn own_interval(&self, i: usize, o: Vec3, d: Vec3, s: f32, policy: StepPolicy) -> (f32, f32) {
        march_interval(self.cones[i].as_ref(), self.reaches[i], o, d, s, policy)
    }
}

/// Which lights one march evaluates: a set of indices into [`MarchLights::indices`] (at most
/// [`crate::MAX_LIGHTS`], one bit each; the `u32` light mask in WGSL). The shared march's set
/// comes from [`MarchLights::shared_march`]; a light marched on its own interval is
/// [`LightSet::one`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct LightSet(pub u32);

impl LightSet {
    /// No light.
    pub const EMPTY: LightSet = LightSet(0);

    /// Light `i` alone.
    pub fn one(i: usize) -> Self {
        LightSet(1 << i)
    }

    /// This set and light `i`.
    pub fn with(self, i: usize) -> Self {
        LightSet(self.0 | 1 << i)
    }

    /// The lights of the set in increasing order (the order the shaders sum them in).
    pub fn iter(self) -> impl Iterator<Item = usize> {
        (0..u32::BITS as usize).filter(move |&i| self.0 >> i & 1 == 1)
    }
}

/// σs·p·L_in·V at `p`, summed over the lights `which` selects. Mirrors `march_density` in WGSL.
pub fn march_density(frame: &CpuFrame, lights: &MarchLights, which: LightSet, dir: Vec3, p: Vec3) -> Vec3 {
    let desc = frame.desc;
    which
        .iter()
        .map(|i| {
            let k = lights.indices[i];
            inscatter_density(&desc.lights[k], &desc.medium, &frame.shadow_maps[k], dir, p)
        })
        .sum()
}

/// The part [t₀, t₁] ∩ [a, b] of the ray o + t·d (d unit) inside the sphere (c, r); empty
/// (t₁ ≤ t₀) when the ray misses it. Mirrors `clip_to_sphere` in common.wgsl.
pub fn clip_to_sphere(iv: (f32, f32), o: Vec3, d: Vec3, c: Vec3, r: f32) -> (f32, f32) {
    let v = o - c;
    let b = d.dot(v);
    let disc = b * b - (v.dot(v) - r * r);
    if disc < 0.0 {
        return (iv.0, iv.0);
    }
    let q = disc.sqrt();
    (iv.0.max(-b - q), iv.1.min(-b + q))
}

/// The interval [t₀, t₁] of the view ray from the eye `o` along `d` (unit) that a technique
/// marches with its N steps, under `policy` (its spot part); `s` is the distance to the surface
/// or far plane.
/// For a local light the interval is then cut to the light's reach ([`light_reach`]), whatever
/// the policy. An empty interval (t₁ ≤ t₀) means the ray gets no light and is not marched.
/// Mirrors `march_interval` in common.wgsl.
pub fn march_interval(
    cone: Option<&SpotCone>,
    reach: Option<(Vec3, f32)>,
    o: Vec3,
    d: Vec3,
    s: f32,
    policy: StepPolicy,
) -> (f32, f32) {
    let iv = policy_interval(cone, o, d, s, policy.spot, policy.denominator);
    match reach {
        Some((c, r)) if iv.1 > iv.0 => clip_to_sphere(iv, o, d, c, r),
        _ => iv,
    }
}

/// [`march_interval`] before the reach cut: the spot-step policy's interval.
fn policy_interval(
    cone: Option<&SpotCone>,
    o: Vec3,
    d: Vec3,
    s: f32,
    policy: SpotSteps,
    denominator: f32,
) -> (f32, f32) {
    let Some(cone) = cone else { return (0.0, s) };
    if policy == SpotSteps::Fixed {
        return (0.0, s);
    }
    let Some((t0, t1)) = cone_interval(cone, o, d, s) else { return (0.0, 0.0) };
    if policy == SpotSteps::ExactCone {
        return (t0, t1);
    }
    // App. B: d is the distance from the light to where the eye ray enters the frustum (the
    // eye itself when it is inside); β the angle between the eye ray and the light's axis.
    let dist = (o + d * t0 - cone.apex).length();
    let (num, den) = appendix_b_chord(dist, d.dot(cone.axis), cone.cos_half);
    let den = if policy == SpotSteps::AppendixBConstant { denominator } else { smooth_denominator(den, denominator) };
    (t0, (t0 + num / den).min(s))
}

/// A spot or point light's position; None for a sun.
pub fn local_position(light: &Light) -> Option<Vec3> {
    match light {
        Light::Directional { .. } => None,
        Light::Spot { position, .. } | Light::Point { position, .. } => Some(*position),
    }
}

/// The model's floor on a local light's distance (integrand.rs clamps d at 10⁻⁴ m): the
/// smallest distance from the ray an equiangular march is laid out for.
const MIN_LIGHT_DISTANCE: f32 = 1e-4;

/// Relative to the light's coordinates, the distance from a ray under which the light counts as
/// on it (about a hundred f32 ulps): [`Steps::equiangular`] keeps uniform steps there.
pub const UNRESOLVED_DISTANCE: f32 = 1e-5;

/// The N steps of one march over the interval [a, b] of a view ray: their boundaries
/// a = t₀ < t₁ < … < t_N = b, equal in length (eq. 1 of Tóth & Umenhoffer 2009) or equal in
/// the angle the ray subtends at a local light (docs/MODEL.md §9). Mirrors `Steps` in
/// common.wgsl.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Steps {
    /// The interval (a, b).
    pub iv: (f32, f32),
    /// N.
    pub n: u32,
    /// (b − a)/N, the length of a uniform step.
    pub delta: f32,
    /// The angular layout, if any.
    angular: Option<Angular>,
}

/// One step of a march ([`Steps::step`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Step {
    /// Its start tᵢ.
    pub t0: f32,
    /// Where its sample sits past tᵢ.
    pub off: f32,
    /// Its transmittance integral ∫₀^len e^(−σt·u) du.
    pub seg: Vec3,
    /// What the integrand at the sample is multiplied by besides: 1 for a uniform step; for an
    /// equiangular one its length under the change of variables over its length,
    /// (d²/D·Δφ)/len at the sample (docs/MODEL.md §9), so a pure 1/d² falloff is integrated
    /// exactly whatever the step.
    pub scale: f32,
}

/// An equiangular layout (docs/MODEL.md §9): the light's foot on the ray at t = `along`, its
/// distance `dist` from the ray; a boundary at angle φ (measured at the light from the ray's
/// direction `sign`·d) lies at t = along + sign·dist·cot φ; φ runs from `phi0` in steps of
/// `dphi`.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Angular {
    along: f32,
    dist: f32,
    sign: f32,
    phi0: f32,
    dphi: f32,
}

impl Steps {
    /// N equal steps over `iv`.
    pub fn uniform(iv: (f32, f32), n: u32) -> Self {
        Steps { iv, n, delta: (iv.1 - iv.0) / n as f32, angular: None }
    }

    /// N steps over `iv` of the ray o + t·d (d unit), equal in the angle subtended at `centre`
    /// (docs/MODEL.md §9): with the light at distance D from the ray and its foot at t = Δ,
    /// t(φ) = Δ + D·cot φ, φ = atan2(D, t − Δ) ∈ (0, π). The angle is measured from whichever
    /// direction along the ray holds the longer part of the interval, where φ < π/2 and cot φ
    /// keeps its precision when D ≪ |t − Δ|. D is floored at the model's 10⁻⁴ m. Where the
    /// light lies on the ray to within [`UNRESOLVED_DISTANCE`] of its coordinates (a light at
    /// the eye: every ray starts at it and the integral diverges, docs/ROBUSTNESS.md), points
    /// that close to it cannot be told apart in f32 (p − light is rounding), and the steps stay
    /// uniform.
    pub fn equiangular(iv: (f32, f32), n: u32, o: Vec3, d: Vec3, centre: Vec3) -> Self {
        let mut steps = Steps::uniform(iv, n);
        if !(iv.1 > iv.0) {
            return steps;
        }
        let v = centre - o;
        let along = d.dot(v);
        let dist = (v - d * along).length();
        if dist <= UNRESOLVED_DISTANCE * (1.0 + centre.abs().max_element()) {
            return steps;
        }
        let dist = dist.max(MIN_LIGHT_DISTANCE);
        let (xa, xb) = (iv.0 - along, iv.1 - along);
        let sign = if xb.abs() >= xa.abs() { 1.0 } else { -1.0 };
        let phi0 = dist.atan2(sign * xa);
        let phi1 = dist.atan2(sign * xb);
        steps.angular = Some(Angular { along, dist, sign, phi0, dphi: (phi1 - phi0) / n as f32 });
        steps
    }

    /// Boundary t_k, k in 0..=N (t₀ = a and t_N = b exactly).
    pub fn boundary(&self, k: u32) -> f32 {
        if k == 0 {
            return self.iv.0;
        }
        if k >= self.n {
            return self.iv.1;
        }
        match self.angular {
            None => self.iv.0 + k as f32 * self.delta,
            Some(g) => {
                let phi = g.phi0 + k as f32 * g.dphi;
                (g.along + g.sign * g.dist * phi.cos() / phi.sin()).clamp(self.iv.0, self.iv.1)
            }
        }
    }

    /// The layout of a march of a light at `centre` (None: a sun) over `iv` under `policy`:
    /// equiangular about a local light under [`LocalSteps::Equiangular`], else uniform.
    /// Mirrors `own_steps` in common.wgsl.
    pub fn of_light(centre: Option<Vec3>, iv: (f32, f32), n: u32, o: Vec3, d: Vec3, policy: StepPolicy) -> Self {
        match centre {
            Some(c) if policy.local == LocalSteps::Equiangular => Steps::equiangular(iv, n, o, d, c),
            _ => Steps::uniform(iv, n),
        }
    }

    /// The step every step of a uniform layout shares (its `t0` unused), found once per march:
    /// the [`step_offset`] and transmittance integral of a step of length (b − a)/N. Mirrors
    /// `uniform_step` in common.wgsl.
    pub fn uniform_step(&self, sigma: Vec3, j: f32) -> Step {
        Step {
            t0: 0.0,
            off: step_offset(channel_mean(sigma), self.delta, j),
            seg: segment_transmittance(sigma, self.delta),
            scale: 1.0,
        }
    }

    /// Step i: its start tᵢ, its sample's offset past tᵢ ([`step_offset`] of its length, at
    /// fraction `j`), its transmittance integral and its [`Step::scale`]; `uni` is
    /// [`Steps::uniform_step`]. Mirrors `march_step` in common.wgsl.
    pub fn step(&self, i: u32, sigma: Vec3, j: f32, uni: &Step) -> Step {
        let Some(g) = self.angular else {
            return Step { t0: self.iv.0 + i as f32 * self.delta, ..*uni };
        };
        let t0 = self.boundary(i);
        let len = self.boundary(i + 1) - t0;
        let off = step_offset(channel_mean(sigma), len, j);
        // dt = d²/D·dφ at the sample (docs/MODEL.md §9).
        let x = t0 + off - g.along;
        let scale = if len > 0.0 { (g.dist * g.dist + x * x) / g.dist * g.dphi.abs() / len } else { 0.0 };
        Step { t0, off, seg: segment_transmittance(sigma, len), scale }
    }

    /// The step k in 0..N that holds distance `t` (clamped to the interval).
    pub fn index_of(&self, t: f32) -> u32 {
        let x = match self.angular {
            None => (t - self.iv.0) / self.delta,
            Some(g) => (g.dist.atan2(g.sign * (t - g.along)) - g.phi0) / g.dphi,
        };
        if x.is_finite() { (x.max(0.0) as u32).min(self.n - 1) } else { 0 }
    }
}

/// Where in a step of length Δ its sample goes, for a fraction j ∈ [0, 1) (½, or the pixel's
/// jitter): the j-quantile of the transmittance e^(−σ̄·t) over the step, with σ̄ the mean
/// extinction of the three channels, t = −ln(1 − j·(1 − e^(−σ̄Δ)))/σ̄. In thin media (σ̄Δ → 0)
/// this is j·Δ, the step midpoint of eq. 1 of Tóth & Umenhoffer 2009 at j = ½; in a dense
/// medium (σ̄Δ ≫ 1) the step's weight ∫T sits at its start, and so does its sample, where the
/// visibility and the light are then taken. Mirrors `step_offset` in common.wgsl.
pub fn step_offset(sigma_mean: f32, delta: f32, j: f32) -> f32 {
    let x = sigma_mean * delta;
    if x < 1e-2 {
        // Series of the quantile to first order in x (error O(x²)·Δ < 1e-5·Δ).
        return j * delta * (1.0 + 0.5 * x * (1.0 - j));
    }
    -(1.0 - j * (1.0 - (-x).exp())).ln() / sigma_mean
}

/// The mean extinction σ̄ of the three channels, which [`step_offset`] places samples by.
pub fn mean_extinction(desc: &FrameDesc) -> f32 {
    channel_mean(desc.medium.extinction())
}

/// The mean of an rgb coefficient's three channels.
fn channel_mean(v: Vec3) -> f32 {
    (v.x + v.y + v.z) / 3.0
}

/// Eq. 1 of Tóth & Umenhoffer 2009 over the N `steps` of the view ray from the eye along
/// `dir`: the sum over steps i = `first`, `first` + `stride`, … < N (brute-force: 0, 1;
/// interleaved: the pixel's block offset, M²), step i = [tᵢ, tᵢ₊₁] sampled at
/// tᵢ + [`step_offset`]`(σ̄, tᵢ₊₁ − tᵢ, j)` and weighted by the transmittance integrated exactly
/// over the step (an improvement on eq. 1's exp(−τ(s − l))·Δl that is exact for a constant
/// integrand; an equiangular step's integrand also carries its [`Step::scale`]), of the lights
/// `which` selects. Mirrors `march_steps` in common.wgsl.
#[allow(clippy::too_many_arguments)]
pub fn march_steps(
    frame: &CpuFrame,
    lights: &MarchLights,
    which: LightSet,
    dir: Vec3,
    steps: &Steps,
    first: u32,
    stride: u32,
    j: f32,
) -> Vec4 {
    let desc = frame.desc;
    let o = desc.camera.position;
    march_samples(desc, steps, first, stride, j, |t| march_density(frame, lights, which, dir, o + dir * t))
}

/// The loop of [`march_steps`] for any integrand `density(t)` (σs·p·L_in·V at distance t):
/// Σᵢ density(tᵢ + offset)·scaleᵢ·e^(−σt·tᵢ)·∫₀^{tᵢ₊₁−tᵢ} e^(−σt·u) du over i = first,
/// first + stride, … < N ([`Steps::step`]; the scale is 1 for uniform steps), in xyz; in w the
/// same sum of each term's luminance times its sample's distance, from which
/// [`scattering_distance`] finds where along the ray the light scattered (docs/MODEL.md §7).
/// A uniform layout's step length, offset and step transmittance are found once.
pub fn march_samples(
    desc: &FrameDesc,
    steps: &Steps,
    first: u32,
    stride: u32,
    j: f32,
    mut density: impl FnMut(f32) -> Vec3,
) -> Vec4 {
    let (a, b) = steps.iv;
    if b <= a {
        return Vec4::ZERO;
    }
    let sigma = desc.medium.extinction();
    let uni = steps.uniform_step(sigma, j);
    let mut sum = Vec4::ZERO;
    let mut i = first;
    while i < steps.n {
        let step = steps.step(i, sigma, j, &uni);
        // One loop over the samples; every selected light at each (docs/MODEL.md §6): the
        // position and the transmittance are shared, the lights' densities summed.
        let t = step.t0 + step.off;
        let term = density(t) * step.scale * (-sigma * step.t0).exp() * step.seg;
        sum += term.extend(luminance(term) * t);
        i += stride;
    }
    sum
}

/// Rec. 709 luminance of linear RGB, the weight of [`scattering_distance`]. Mirrors
/// `luminance` in common.wgsl.
pub fn luminance(c: Vec3) -> f32 {
    c.dot(Vec3::new(0.2126, 0.7152, 0.0722))
}

/// A view ray's *scattering distance* (docs/MODEL.md §7, step 1): where along the ray the
/// light of its point and spot lights scattered — the luminance-weighted mean distance from the
/// eye (m) of the terms of the marches over those lights' own intervals, Σ Y(term)·t / Σ Y(term)
/// (`own`: their summed [`march_samples`]), where those lights give at least half the ray's
/// in-scattering luminance (`total`); 0 elsewhere (the temporal stage then reprojects by the
/// surface). A sun's light is left out: it scatters all along the ray, whose length the
/// surface already carries (measured: reprojecting a sun's shafts by its scattering distance
/// lost 1.4–2.8 dB, docs/RESULTS.md). Which lights own an interval ([`MarchLights::owns_interval`]):
/// every point and spot light under the default `local_steps = "equiangular"`; under
/// `"uniform"`, spots under a cone `spot_steps` policy; with neither, none, and the distance is
/// always 0. Mirrors `scattering_distance` in common.wgsl.
pub fn scattering_distance(total: Vec3, own: Vec4) -> f32 {
    let y = luminance(own.truncate());
    if y > 0.0 && y >= 0.5 * luminance(total) { (own.w / y).max(0.0) } else { 0.0 }
}

/// Every light's in-scattering on one view ray of length `s` (docs/MODEL.md §6): one march
/// over the shared interval for the lights that share it, plus one over its own interval for
/// each light that owns one ([`MarchLights::owns_interval`], with [`MarchLights::own_steps`]);
/// the steps i = first, first + stride, … < n of each. `march` runs one march (the lights of a
/// set over a layout; its last argument true for a light's own interval); [`march_lights`]
/// passes [`march_steps`]. Mirrors `march_lights` in WGSL.
#[allow(clippy::too_many_arguments)]
pub fn march_light_groups<T: std::ops::Add<Output = T>>(
    o: Vec3,
    lights: &MarchLights,
    dir: Vec3,
    s: f32,
    n: u32,
    policy: StepPolicy,
    mut march: impl FnMut(LightSet, &Steps, bool) -> T,
) -> T {
    let (shared, set) = lights.shared_march(o, dir, s, policy);
    let mut sum = march(set, &Steps::uniform(shared, n), false);
    for i in 0..lights.indices.len() {
        if lights.owns_interval(i, policy) {
            let iv = lights.own_interval(i, o, dir, s, policy);
            sum = sum + march(LightSet::one(i), &lights.own_steps(i, iv, n, o, dir, policy), true);
        }
    }
    sum
}

/// [`march_light_groups`] with [`march_steps`]: every light's in-scattering on the view ray
/// `dir` of length `s`, steps i = first, first + stride, … < n, in xyz; in w its
/// [`scattering_distance`] from the marches of the lights that own their interval. Mirrors
/// `march_lights` in WGSL.
#[allow(clippy::too_many_arguments)]
pub fn march_lights(
    frame: &CpuFrame,
    lights: &MarchLights,
    dir: Vec3,
    s: f32,
    n: u32,
    first: u32,
    stride: u32,
    j: f32,
    policy: StepPolicy,
) -> Vec4 {
    let o = frame.desc.camera.position;
    let mut own = Vec4::ZERO;
    let total = march_light_groups(o, lights, dir, s, n, policy, |set, steps, owned| {
        let m = march_steps(frame, lights, set, dir, steps, first, stride, j);
        if owned {
            own += m;
        }
        m
    });
    total.truncate().extend(scattering_distance(total.truncate(), own))
}

/// How a ray-marching technique marches a view ray: the N steps of eq. 1 (Tóth & Umenhoffer
/// 2009) and their jitter — the settings `steps`, `jitter` and `frame_index` that
/// `brute-force`, `interleaved`, `subsampled` and `epipolar` share, beside the [`StepPolicy`]
/// that says where the steps go (both flattened into each technique's settings: a scene file
/// writes them as keys of the technique's own table, `[render.epipolar] steps = 128`; serde
/// cannot nest one flattened struct in another under `deny_unknown_fields`, so they are
/// siblings).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct MarchSettings {
    /// Ray-marching steps N per view ray (eq. 1): per pixel for `brute-force`, per grid sample
    /// for `subsampled`, per ray-march sample for `epipolar`, and in total over the M² pixels
    /// of a window for `interleaved`. More steps resolve thinner shafts and reduce banding;
    /// cost is linear in N (one shadow-map lookup per step). Must be in 1..=4096. Default 64.
    pub steps: u32,
    /// Offset the samples by a fraction of a step (per pixel; per aligned M×M block for
    /// `interleaved`) instead of the step midpoint. Trades banding for noise at no extra cost.
    /// Default false.
    pub jitter: bool,
    /// Seed of the jitter (change it per frame for temporal accumulation: the offsets then
    /// follow a low-discrepancy sequence, docs/MODEL.md §7). Default 0.
    pub frame_index: u32,
}

impl Default for MarchSettings {
    fn default() -> Self {
        Self { steps: 64, jitter: false, frame_index: 0 }
    }
}

impl MarchSettings {
    /// Checks the ranges; `technique` prefixes the key in the error (`brute-force.steps`).
    pub fn validate(&self, technique: &str) -> Result<(), Error> {
        if !(1..=4096).contains(&self.steps) {
            return Err(Error::invalid(format!("{technique}.steps"), self.steps, "must be in 1..=4096"));
        }
        Ok(())
    }
}

/// Eq. 1 of Tóth & Umenhoffer 2009 for pixel (x, y), ray `dir`, surface distance `s`: N steps
/// over the spot-step policy's interval, sampled at step midpoints or at the pixel's jitter.
/// Mirrors `march_pixel` in common.wgsl.
#[allow(clippy::too_many_arguments)]
pub fn march_pixel(
    frame: &CpuFrame,
    lights: &MarchLights,
    m: &MarchSettings,
    policy: StepPolicy,
    x: u32,
    y: u32,
    dir: Vec3,
    s: f32,
) -> Vec4 {
    let j = if m.jitter { crate::shaders::pixel_jitter(x, y, m.frame_index) } else { 0.5 };
    march_lights(frame, lights, dir, s, m.steps, 0, 1, j, policy)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cone(half_deg: f32) -> SpotCone {
        SpotCone { apex: Vec3::new(0.0, 10.0, 0.0), axis: Vec3::NEG_Y, cos_half: half_deg.to_radians().cos() }
    }

    /// The exact chord from the interval, for a ray far enough to leave the cone.
    fn exact_chord(c: &SpotCone, o: Vec3, d: Vec3) -> Option<(f32, f32)> {
        cone_interval(c, o, d, 1.0e4)
    }

    #[test]
    fn appendix_b_equals_the_exact_chord_in_the_axial_plane() {
        // Rays in the plane spanned by the axis and x, starting outside the cone, entering
        // through one edge and leaving through the other: eq. 3 is exact there (App. B).
        let mut checked = 0;
        for half in [10.0f32, 24.0, 45.0, 70.0] {
            let c = cone(half);
            for h in [1.0f32, 3.0, 7.5] {
                for tilt_deg in [-60.0f32, -30.0, -5.0, 0.0, 5.0, 20.0, 40.0] {
                    // Start left of the cone at depth h below the apex, heading right and tilted.
                    let tilt = tilt_deg.to_radians();
                    let d = Vec3::new(tilt.cos(), -tilt.sin(), 0.0);
                    let o = c.apex + Vec3::new(-h * 3.0, -h, 0.0);
                    if c.contains(o) {
                        continue;
                    }
                    let Some((t0, t1)) = exact_chord(&c, o, d) else { continue };
                    if t1 >= 1.0e4 * 0.99 {
                        continue; // never leaves: β ≤ φ/2, eq. 3 is infinite (the instability)
                    }
                    let dist = (o + d * t0 - c.apex).length();
                    let (num, den) = appendix_b_chord(dist, d.dot(c.axis), c.cos_half);
                    let chord = num / den;
                    let exact = t1 - t0;
                    assert!(
                        (chord - exact).abs() <= 1e-3 * exact.max(1.0),
                        "half {half}°, h {h}, tilt {tilt_deg}°: App. B Δ {chord} vs exact chord {exact}"
                    );
                    checked += 1;
                }
            }
        }
        assert!(checked >= 40, "only {checked} rays checked");
    }

    #[test]
    fn appendix_b_is_unstable_as_beta_approaches_half_phi_and_the_remedies_bound_it() {
        let c = cone(30.0);
        let half = 30.0f32.to_radians();
        // A ray entering at distance 5 that turns parallel to the far edge: β → φ/2.
        for eps in [1e-1f32, 1e-2, 1e-3] {
            let beta = half + eps;
            let (num, den) = appendix_b_chord(5.0, beta.cos(), c.cos_half);
            assert!(num / den > 5.0 * (2.0 * half).sin() / eps.sin() * 0.9);
            let k = DEFAULT_SPOT_DENOMINATOR;
            assert!(smooth_denominator(den, k) >= 0.9 * k);
        }
        // The smooth clamp is the identity above 2k and k at or below 0.
        assert_eq!(smooth_denominator(0.8, 0.3), 0.8);
        assert_eq!(smooth_denominator(-0.5, 0.3), 0.3);
        assert_eq!(smooth_denominator(0.0, 0.3), 0.3);
    }

    #[test]
    fn cone_interval_handles_inside_outside_and_misses() {
        let c = cone(20.0);
        // Eye inside the cone looking down the axis: from 0 to s.
        let o = c.apex + Vec3::new(0.0, -1.0, 0.0);
        assert_eq!(cone_interval(&c, o, Vec3::NEG_Y, 5.0), Some((0.0, 5.0)));
        // Behind the apex looking away: miss (the backward nappe does not count).
        assert_eq!(cone_interval(&c, c.apex + Vec3::Y, Vec3::Y, 50.0), None);
        // Parallel to the axis outside the cone: miss.
        assert_eq!(cone_interval(&c, c.apex + Vec3::new(100.0, 0.0, 0.0), Vec3::NEG_Y, 50.0), None);
        // Through the axis horizontally at depth 4: the chord is 2·4·tan 20°, centred on the axis.
        let o = c.apex + Vec3::new(-10.0, -4.0, 0.0);
        let (t0, t1) = cone_interval(&c, o, Vec3::X, 100.0).unwrap();
        let half = 4.0 * 20.0f32.to_radians().tan();
        assert!((t0 - (10.0 - half)).abs() < 1e-4 && (t1 - (10.0 + half)).abs() < 1e-4, "{t0} {t1}");
        // Clipped by s: never past the surface.
        assert_eq!(cone_interval(&c, o, Vec3::X, 10.0).unwrap().1, 10.0);
        // march_interval never exceeds [0, s] under any policy.
        for p in SpotSteps::ALL {
            let policy = StepPolicy { spot: p, denominator: 0.05, local: LocalSteps::Uniform };
            let (a, b) = march_interval(Some(&c), None, o, Vec3::new(1.0, -0.2, 0.0).normalize(), 9.0, policy);
            assert!(a >= 0.0 && b <= 9.0, "{p:?}: {a} {b}");
        }
        let exact = StepPolicy { spot: SpotSteps::ExactCone, denominator: 0.3, local: LocalSteps::Equiangular };
        assert_eq!(march_interval(None, None, o, Vec3::X, 9.0, exact), (0.0, 9.0));
    }

    /// Σ over the steps of (step length)/d(sample)², the march of 1/d² in an empty medium,
    /// against its closed form (atan(x_b/D) − atan(x_a/D))/D (docs/MODEL.md §9).
    fn inverse_square_sum(steps: &Steps, o: Vec3, d: Vec3, c: Vec3) -> f32 {
        let uni = steps.uniform_step(Vec3::ZERO, 0.5);
        (0..steps.n)
            .map(|i| {
                let st = steps.step(i, Vec3::ZERO, 0.5, &uni);
                st.seg.x * st.scale / (o + d * (st.t0 + st.off) - c).length_squared()
            })
            .sum()
    }

    #[test]
    fn equiangular_steps_tile_the_interval_and_resolve_the_inverse_square_peak() {
        let (o, d) = (Vec3::ZERO, Vec3::X);
        // A light 5 cm from a 40 m ray, its foot 12 m in; and one beside the ray's start, and
        // one past its end (the interval wholly on one side: the mirrored layout).
        for (c, iv) in [
            (Vec3::new(12.0, 0.05, 0.0), (0.0f32, 40.0f32)),
            (Vec3::new(0.5, 0.0, 0.3), (0.0, 40.0)),
            (Vec3::new(55.0, 0.2, 0.0), (3.0, 40.0)),
        ] {
            let dist = (c - o).cross(d).length();
            let along = (c - o).dot(d);
            let exact = (((iv.1 - along) / dist).atan() - ((iv.0 - along) / dist).atan()) / dist;
            for n in [8u32, 16, 64] {
                let eq = Steps::equiangular(iv, n, o, d, c);
                // Boundaries increase from a to b, and each t lies in the step index_of names.
                let b: Vec<f32> = (0..=n).map(|k| eq.boundary(k)).collect();
                assert_eq!((b[0], b[n as usize]), iv);
                assert!(b.windows(2).all(|w| w[0] <= w[1]), "{c} {n}: {b:?}");
                for k in 0..n {
                    let mid = 0.5 * (b[k as usize] + b[k as usize + 1]);
                    if b[k as usize + 1] - b[k as usize] > 1e-4 * mid.max(1.0) {
                        assert_eq!(eq.index_of(mid), k, "{c} {n}: step {k} [{}, {}]", b[k as usize], b[k as usize + 1]);
                    }
                }
                let e = inverse_square_sum(&eq, o, d, c);
                assert!(((e - exact) / exact).abs() < 0.02, "{c}, {n} equiangular steps: {e} vs {exact}");
            }
            // Uniform steps miss or overshoot the peak of the first light (measured: 16 steps of
            // 2.5 m against a 5 cm peak).
            if c.y == 0.05 {
                let u = inverse_square_sum(&Steps::uniform(iv, 16), o, d, c);
                assert!(((u - exact) / exact).abs() > 0.5, "uniform steps: {u} vs {exact}");
            }
        }
        // A light on the ray (within f32 resolution of its coordinates) keeps uniform steps.
        let on = Steps::equiangular((0.0, 10.0), 8, o, d, Vec3::new(4.0, 0.0, 0.0));
        assert_eq!(on, Steps::uniform((0.0, 10.0), 8));
        // An empty interval is an empty march.
        assert_eq!(Steps::equiangular((3.0, 3.0), 8, o, d, Vec3::Y).iv, (3.0, 3.0));
    }

    #[test]
    fn step_policy_codes_round_trip() {
        for spot in SpotSteps::ALL {
            for local in [LocalSteps::Uniform, LocalSteps::Equiangular] {
                let p = StepPolicy { spot, denominator: 0.3, local };
                assert_eq!(StepPolicy::from_code(p.code(), 0.3), p);
            }
        }
    }

    #[test]
    fn light_sets_list_their_lights_in_increasing_order() {
        assert_eq!(LightSet::EMPTY.iter().count(), 0);
        assert_eq!(LightSet::one(3).iter().collect::<Vec<_>>(), vec![3]);
        let s = LightSet::EMPTY.with(15).with(0).with(7);
        assert_eq!(s.iter().collect::<Vec<_>>(), vec![0, 7, 15]);
        assert_eq!(s, LightSet(1 | 1 << 7 | 1 << 15));
    }

    #[test]
    fn spot_steps_parse_by_their_names() {
        for p in SpotSteps::ALL {
            #[derive(Deserialize)]
            struct T {
                s: SpotSteps,
            }
            let t: T = toml::from_str(&format!("s = \"{}\"", p.name())).unwrap();
            assert_eq!(t.s, p);
            assert_eq!(SpotSteps::ALL[p.code() as usize], p);
        }
    }
}
