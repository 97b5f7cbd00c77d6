//! CPU mirror of `prefiltered`: the same arithmetic (f32) as rectify.wgsl, prefilter.wgsl and
//! evaluate.wgsl, function for function, including the storage's quantisation of the filtered
//! bases. Each pass is public so a test can compare it with its GPU twin.

use super::rectify::{Mode, Rectification, Z_MARGIN, line_occluder};
use super::settings::PrefilteredSettings;
use super::{epipole_pixel, stats_extra};
use crate::error::Error;
use crate::frame::{CpuFrame, FrameDesc};
use crate::image::Image;
use crate::integrand::{light_incident, light_position};
use crate::march::{
    MarchSettings, Steps, light_reach, local_position, march_interval, march_pixel, march_samples, mean_extinction,
};
use crate::model::segment_transmittance;
use crate::stats::{PassTime, TechniqueStats};
use glam::Vec3;
use rayon::prelude::*;
use std::f32::consts::PI;

/// The outputs of every pass of one frame.
#[derive(Clone, Debug)]
pub struct Passes {
    /// The rectification of the frame.
    pub rect: Rectification,
    /// The rectified shadow map: normalised depths, `width × height`, row-major.
    pub depth: Vec<f32>,
    /// The filtered bases as stored (in [0, 1]): `sets × layers × height × width` RGBA texels
    /// (a set per band and colour channel, set = band·channels + channel).
    pub basis: Vec<[f32; 4]>,
    /// The running weight sum of each region's prefix sum, `sets × height × width`.
    pub cumw: Vec<f32>,
    /// Colour channels with their own weights (1 or 3).
    pub channels: u32,
    /// The in-scattering.
    pub image: Image,
}

/// Mirrors `basis_z` in WGSL: a [0, 1) depth into the Fourier domain [m, 1 − m], an unoccluded
/// texel (depth ≥ 1) to 1 ([`Z_MARGIN`]).
pub fn basis_z(z: f32) -> f32 {
    if z >= 1.0 {
        return 1.0;
    }
    Z_MARGIN + (1.0 - 2.0 * Z_MARGIN) * z.max(0.0)
}

/// Eq. 8: the basis values B_n(z) for n = 4·layer … 4·layer + 3: B_{2k} = sin(c_k z),
/// B_{2k+1} = cos(c_k z), c_k = π(2k + 1) (the paper's k counts from 1). Mirrors `basis4`.
pub fn basis4(z: f32, layer: u32) -> [f32; 4] {
    let k0 = 2 * layer;
    let c0 = PI * (2 * k0 + 1) as f32;
    let c1 = PI * (2 * k0 + 3) as f32;
    [(c0 * z).sin(), (c0 * z).cos(), (c1 * z).sin(), (c1 * z).cos()]
}

/// Eq. 8's bases layer after layer by rotation, as prefilter.wgsl computes them: sin and cos of
/// c_k·z for k = 2·`layer`, 2·`layer` + 1, … from one sin/cos of the first harmonic and one of
/// the step 2π·z (two sin/cos per texel instead of M). Equal to [`basis4`] up to f32 rounding.
#[derive(Clone, Copy, Debug)]
pub struct BasisRotor {
    sc: [f32; 2],
    step: [f32; 2],
}

/// The rotor of layer `layer` at depth `z` (basis domain).
pub fn basis_rotor(z: f32, layer: u32) -> BasisRotor {
    let a = PI * (4 * layer + 1) as f32 * z;
    let s = 2.0 * PI * z;
    BasisRotor { sc: [a.sin(), a.cos()], step: [s.sin(), s.cos()] }
}

impl BasisRotor {
    fn rotate(sc: [f32; 2], st: [f32; 2]) -> [f32; 2] {
        [sc[0] * st[1] + sc[1] * st[0], sc[1] * st[1] - sc[0] * st[0]]
    }
    /// The next layer's four bases.
    pub fn next4(&mut self) -> [f32; 4] {
        let sc2 = Self::rotate(self.sc, self.step);
        let b = [self.sc[0], self.sc[1], sc2[0], sc2[1]];
        self.sc = Self::rotate(sc2, self.step);
        b
    }
}

/// Eq. 8: the ray coefficients a_n(z_r) for the same n: a_{2k} = 2/c_k·cos(c_k z_r),
/// a_{2k+1} = −2/c_k·sin(c_k z_r). Mirrors `coeff4`.
pub fn coeff4(z: f32, layer: u32) -> [f32; 4] {
    let k0 = 2 * layer;
    let c0 = PI * (2 * k0 + 1) as f32;
    let c1 = PI * (2 * k0 + 3) as f32;
    [2.0 / c0 * (c0 * z).cos(), -2.0 / c0 * (c0 * z).sin(), 2.0 / c1 * (c1 * z).cos(), -2.0 / c1 * (c1 * z).sin()]
}

/// Eq. 9–10: the truncated Fourier series of the visibility step V(z_r, z_i) = H(z_r − z_i)
/// with `bases` terms (unclamped, so its ringing can be measured).
pub fn fourier_visibility(z_r: f32, z_i: f32, bases: u32) -> f32 {
    let mut v = 0.5;
    for l in 0..bases / 4 {
        let a = coeff4(z_r, l);
        let b = basis4(z_i, l);
        v += a[0] * b[0] + a[1] * b[1] + a[2] * b[2] + a[3] * b[3];
    }
    v
}

/// Pass `rectify` (§4.1 resampling; the projective map resampled the same way when the host did
/// not rasterize it): per texel, the first occluder on its light line from the standard shadow
/// map, as a normalised depth (1 where the line is unoccluded). Mirrors rectify.wgsl.
pub fn rectify(frame: &CpuFrame, rect: &Rectification) -> Vec<f32> {
    let (w, h) = (rect.width as usize, rect.height as usize);
    let light = light_position(&frame.desc.lights[0].light);
    let bias = frame.desc.lights[0].shadow_bias;
    let mut out = vec![1.0f32; w * h];
    out.par_chunks_mut(w).enumerate().for_each(|(row, line)| {
        for (col, z) in line.iter_mut().enumerate() {
            let (c, r) = (col as f32 + 0.5, row as f32 + 0.5);
            let (p, dir) = rect.texel_line(c, r);
            *z = match line_occluder(&frame.shadow_maps[0], light, p, dir, bias) {
                Some(o) => rect.occluder_depth(c, o),
                None => 1.0,
            };
        }
    });
    out
}

/// Mirrors `texel_depth` in geometry.wgsl: a texel's depth, with the volume bias added when
/// the host rasterized the map (`bias` world units along the light, i.e. bias/(x·(r₁ − r₀)) in
/// the projective depth).
pub fn texel_depth(rect: &Rectification, stored: f32, col: u32, bias: Option<f32>) -> f32 {
    match bias {
        Some(b) if rect.mode == Mode::Projective => {
            let x = rect.line_of_column(col as f32 + 0.5);
            stored + b / (x * (rect.ranges.w - rect.ranges.z))
        }
        _ => stored,
    }
}

/// The weight of texel `col` of row `row` in the prefix sum (§3.2, eq. 11 and Listing 2):
/// 1 without transmittance weighting; for a directional light the transmittance integrated over
/// the texel's segment of the reference ray, e^(−σ̄t_a)·(1 − e^(−σ̄(t_b − t_a)))/σ̄ (eq. 11, with
/// the exact segment ends of the projective map rather than eq. 12's constant ratio; the first
/// texel reaches back to the camera); for a local light that times the light's falloff, cone
/// and phase function at the segment's midpoint (§3.2, "Angular-dependency").
/// Mirrors `texel_weight` in prefilter.wgsl.
#[allow(clippy::too_many_arguments)]
pub fn texel_weight(
    desc: &FrameDesc,
    rect: &Rectification,
    weighted: bool,
    row: u32,
    band: u32,
    channel: u32,
    channels: u32,
    col: u32,
) -> f32 {
    if !weighted {
        return 1.0;
    }
    let sigma = mean_extinction(desc);
    let ta = if col == 0 { 0.0 } else { rect.reference_distance(row, band, col as f32) };
    let tb = rect.reference_distance(row, band, col as f32 + 1.0);
    if !ta.is_finite() {
        return 0.0;
    }
    if !rect.local {
        return (-sigma * ta).exp() * segment_transmittance(Vec3::splat(sigma), tb - ta).x;
    }
    if !tb.is_finite() {
        return 0.0;
    }
    let tm = 0.5 * (ta + tb);
    let dir = rect.reference_dir(row, band);
    let p = rect.camera + dir * tm;
    let (l_in, wl) = light_incident(&desc.lights[0], &desc.medium, p);
    let ph = desc.medium.phase.eval(wl.dot(-dir));
    let c = l_in * ph;
    let lum = if channels == 3 { c[channel as usize] } else { c.dot(Vec3::splat(1.0 / 3.0)) };
    lum * (-sigma * tm).exp() * (tb - ta)
}

/// Pass `prefilter` (§3.3, Listings 1–3): per row, region and group of `bases_per_thread`
/// bases, the weighted running mean Σwᵢ·B(zᵢ)/Σwᵢ of eq. 8's bases of the row's depths (fused
/// basis transform, Listing 3), stored mapped to [0, 1] (Appendix A) and quantised as the
/// texture stores it; and each region's running weight sum. Mirrors prefilter.wgsl.
pub fn prefilter(
    desc: &FrameDesc,
    rect: &Rectification,
    settings: &PrefilteredSettings,
    depth: &[f32],
    host_bias: Option<f32>,
) -> (Vec<[f32; 4]>, Vec<f32>) {
    let (w, h) = (rect.width as usize, rect.height as usize);
    let layers = settings.layers() as usize;
    let weighted = settings.transmittance_weights;
    let group_layers = settings.bases_per_thread / 4;
    let channels = settings.channels(&desc.lights[0].light);
    let sets = (rect.bands * channels) as usize;
    // Per row: (sets × layers × width bases, sets × width weight sums).
    let rows: Vec<(Vec<[f32; 4]>, Vec<f32>)> = (0..h)
        .into_par_iter()
        .map(|row| {
            let mut basis = vec![[0.0f32; 4]; sets * layers * w];
            let mut cumw = vec![0.0f32; sets * w];
            for set in 0..sets {
                let (band, channel) = (set as u32 / channels, set as u32 % channels);
                for region in 0..rect.regions {
                    let [c0, c1] = rect.region_columns(region);
                    let mut filt = vec![[0.0f32; 4]; layers];
                    let mut sum = 0.0f32;
                    for col in c0..c1 {
                        let z = basis_z(texel_depth(rect, depth[row * w + col as usize], col, host_bias));
                        let wt = texel_weight(desc, rect, weighted, row as u32, band, channel, channels, col);
                        sum += wt;
                        let f = if sum > 0.0 { wt / sum } else { 1.0 };
                        cumw[set * w + col as usize] = sum;
                        let mut rotor = basis_rotor(z, 0);
                        for (l, fl) in filt.iter_mut().enumerate() {
                            // Each thread group of prefilter.wgsl starts its own rotor.
                            if l as u32 % group_layers == 0 {
                                rotor = basis_rotor(z, l as u32);
                            }
                            let b = rotor.next4();
                            for c in 0..4 {
                                fl[c] += (b[c] - fl[c]) * f;
                            }
                            basis[(set * layers + l) * w + col as usize] =
                                fl.map(|v| settings.precision.quantise(v * 0.5 + 0.5));
                        }
                    }
                }
            }
            (basis, cumw)
        })
        .collect();
    let mut basis = vec![[0.0f32; 4]; sets * layers * w * h];
    let mut cumw = vec![0.0f32; sets * w * h];
    for (row, (b, c)) in rows.into_iter().enumerate() {
        for sl in 0..sets * layers {
            basis[(sl * h + row) * w..(sl * h + row + 1) * w].copy_from_slice(&b[sl * w..(sl + 1) * w]);
        }
        for set in 0..sets {
            cumw[(set * h + row) * w..(set * h + row + 1) * w].copy_from_slice(&c[set * w..(set + 1) * w]);
        }
    }
    (basis, cumw)
}

/// Bilinear footprint of a lookup at column coordinate `col` (the end of the prefix at the
/// surface) and row coordinate `row` in region [c0, c1): texel positions, weights. The prefix
/// through texel i ends at column i + 1, hence the −1. Mirrors `lookup_coords` in evaluate.wgsl.
fn footprint(rect: &Rectification, col: f32, row: f32, c0: u32, c1: u32) -> ([usize; 2], [usize; 2], f32, f32) {
    let px = (col - 1.0).clamp(c0 as f32, (c1 - 1) as f32);
    let py = row - 0.5;
    let x0 = px.floor();
    let y0 = py.floor();
    let (fx, fy) = (px - x0, py - y0);
    let h = rect.height as i32;
    let wrap = |y: i32| if rect.full_circle { y.rem_euclid(h) } else { y.clamp(0, h - 1) };
    let x0 = x0 as usize;
    let x1 = (x0 + 1).min(rect.width as usize - 1);
    let y0i = y0 as i32;
    ([x0, x1], [wrap(y0i) as usize, wrap(y0i + 1) as usize], fx, fy)
}

fn bilinear<T: Copy>(
    get: impl Fn(usize, usize) -> T,
    lerp: impl Fn(T, T, f32) -> T,
    fp: ([usize; 2], [usize; 2], f32, f32),
) -> T {
    let ([x0, x1], [y0, y1], fx, fy) = fp;
    let a = lerp(get(x0, y0), get(x1, y0), fx);
    let b = lerp(get(x0, y1), get(x1, y1), fx);
    lerp(a, b, fy)
}

/// The prefiltered average visibility of a ray of depth `z` (normalised) ending at column `col`,
/// row `row`, region `region` (Listing 4; with regions, the weight-sum-weighted mean of one
/// lookup per region, §3.3). Clamped to [0, 1] (Appendix A). Mirrors `prefiltered_visibility`.
pub fn prefiltered_visibility(p: &Passes, bases: u32, set: u32, row: f32, col: f32, region: u32, z: f32) -> f32 {
    let rect = &p.rect;
    let (w, h) = (rect.width as usize, rect.height as usize);
    let zs = basis_z(z);
    let layers = bases / 4;
    let first = (set * layers) as usize;
    let coeffs: Vec<[f32; 4]> = (0..layers).map(|l| coeff4(zs, l)).collect();
    let lerp4 = |a: [f32; 4], b: [f32; 4], t: f32| [0, 1, 2, 3].map(|i| a[i] + (b[i] - a[i]) * t);
    let vis_at = |fp| {
        let mut v = 0.5;
        for (l, a) in coeffs.iter().enumerate() {
            let b = bilinear(|x, y| p.basis[((first + l) * h + y) * w + x], lerp4, fp);
            for c in 0..4 {
                v += a[c] * (2.0 * b[c] - 1.0);
            }
        }
        v
    };
    let lerp1 = |a: f32, b: f32, t: f32| a + (b - a) * t;
    let mut num = 0.0;
    let mut den = 0.0;
    for r in 0..=region {
        let [c0, c1] = rect.region_columns(r);
        let at = if r == region { col } else { c1 as f32 };
        let fp = footprint(rect, at, row, c0, c1);
        let v = vis_at(fp);
        if rect.regions == 1 {
            return v.clamp(0.0, 1.0);
        }
        let wt = bilinear(|x, y| p.cumw[(set as usize * h + y) * w + x], lerp1, fp);
        num += wt * v;
        den += wt;
    }
    let v = if den > 0.0 { num / den } else { 0.5 };
    v.clamp(0.0, 1.0)
}

/// The unoccluded in-scattering along the view ray to distance `s`, the factor the prefiltered
/// visibility multiplies. Directional: the closed form σs·p·E·(1 − e^(−σt·s))/σt (eq. 2–3).
/// Spot and point: `light_steps` shadow-free quadrature points over the ray's lit interval,
/// placed and weighted as `brute-force` places its samples (equiangular under the default
/// `local_steps`) (the "quadrature table" route to the
/// unoccluded integral of Sun et al. 2005). Mirrors `unoccluded_inscatter` in evaluate.wgsl.
pub fn unoccluded_inscatter(desc: &FrameDesc, settings: &PrefilteredSettings, dir: Vec3, s: f32) -> Vec3 {
    let st = desc.medium.extinction();
    let ss = desc.medium.scattering;
    let (l_in, wl) = light_incident(&desc.lights[0], &desc.medium, desc.camera.position);
    if matches!(desc.lights[0].light, crate::Light::Directional { .. }) {
        return ss * desc.medium.phase.eval(wl.dot(-dir)) * l_in * segment_transmittance(st, s);
    }
    let fl = &desc.lights[0];
    let cone = crate::march::SpotCone::of(&fl.light);
    let o = desc.camera.position;
    let policy = settings.policy;
    let iv = march_interval(cone.as_ref(), light_reach(fl, &desc.medium), o, dir, s, policy);
    let steps = Steps::of_light(local_position(&fl.light), iv, settings.light_steps, o, dir, policy);
    march_samples(desc, &steps, 0, 1, 0.5, |t| {
        let (l, wl) = light_incident(fl, &desc.medium, o + dir * t);
        ss * desc.medium.phase.eval(wl.dot(-dir)) * l
    })
    .truncate()
}

/// The prefiltered visibility of a view ray (unit `dir`) ending at `pt`, per colour channel:
/// [`prefiltered_visibility`] of the two bands around the ray, blended (one value for all
/// channels unless the light has per-channel weights). Mirrors `ray_visibility`.
pub fn ray_visibility(p: &Passes, bases: u32, pt: Vec3, dir: Vec3) -> Vec3 {
    let (row, col, region, z) = p.rect.rectify_point(pt, dir);
    let (b0, b1, f) = p.rect.band_bracket(row, dir);
    let ch = p.channels;
    let vis = |c: u32| {
        let v0 = prefiltered_visibility(p, bases, b0 * ch + c, row, col, region, z);
        if b1 == b0 {
            return v0;
        }
        let v1 = prefiltered_visibility(p, bases, b1 * ch + c, row, col, region, z);
        v0 + (v1 - v0) * f
    };
    if ch == 3 { Vec3::new(vis(0), vis(1), vis(2)) } else { Vec3::splat(vis(0)) }
}

/// Pass `evaluate` (Listing 4): per pixel, the unoccluded in-scattering times the prefiltered
/// visibility; then, when `epipole` is given, pass `epipole` over the disc around the visible
/// light ([`march_epipole`], §5). Mirrors evaluate.wgsl.
pub fn evaluate(frame: &CpuFrame, settings: &PrefilteredSettings, p: &Passes, epipole: Option<[f32; 2]>) -> Image {
    let desc = frame.desc;
    let w = desc.width as usize;
    let mut image = Image::new(desc.width, desc.height);
    image.pixels.par_chunks_mut(w).enumerate().for_each(|(y, line)| {
        for (x, out) in line.iter_mut().enumerate() {
            let (x, y) = (x as u32, y as u32);
            if in_epipole_disc(epipole, settings.epipole_radius, x, y) {
                continue;
            }
            let dir = desc.pixel_ray(x, y);
            let s = desc.view_distance(frame.depth[(y * desc.width + x) as usize], dir);
            let l = unoccluded_inscatter(desc, settings, dir, s)
                * ray_visibility(p, settings.bases, desc.camera.position + dir * s, dir);
            *out = [l.x, l.y, l.z, 1.0];
        }
    });
    march_epipole(frame, settings, epipole, &mut image);
    image
}

/// Pass `epipole` (the entry of that name in evaluate.wgsl): the pixels of the disc around a
/// visible light, ray-marched with `epipole_steps` as `brute-force` marches them (§5).
pub fn march_epipole(frame: &CpuFrame, settings: &PrefilteredSettings, epipole: Option<[f32; 2]>, image: &mut Image) {
    let desc = frame.desc;
    let lights = crate::march::MarchLights::of(desc);
    let march = MarchSettings::from(settings);
    for y in 0..desc.height {
        for x in 0..desc.width {
            if in_epipole_disc(epipole, settings.epipole_radius, x, y) {
                let dir = desc.pixel_ray(x, y);
                let s = desc.view_distance(frame.depth[(y * desc.width + x) as usize], dir);
                let l = march_pixel(frame, &lights, &march, settings.policy, x, y, dir, s);
                image.pixels[(y * desc.width + x) as usize] = [l.x, l.y, l.z, 1.0];
            }
        }
    }
}

/// Mirrors `in_epipole_disc` in evaluate.wgsl.
pub fn in_epipole_disc(epipole: Option<[f32; 2]>, radius: u32, x: u32, y: u32) -> bool {
    let Some([ex, ey]) = epipole else { return false };
    let (dx, dy) = (x as f32 + 0.5 - ex, y as f32 + 0.5 - ey);
    radius > 0 && dx * dx + dy * dy <= (radius * radius) as f32
}

/// The rectified map of `rect` for a frame: `host_depth` where the host rasterized it (a
/// projective rectification only; its size is checked, the error naming `what`), else the
/// shadow map resampled by [`rectify`]. Returns the map and whether it is the host's. Shared by
/// `prefiltered`, `minmax` and `epipolar`'s min-max march.
pub fn rectified_depth(
    frame: &CpuFrame,
    rect: &Rectification,
    host_depth: Option<&[f32]>,
    what: &str,
) -> Result<(Vec<f32>, bool), Error> {
    match host_depth.filter(|_| rect.mode == Mode::Projective) {
        Some(d) if d.len() != (rect.width * rect.height) as usize => {
            Err(Error::invalid(what, d.len(), "must hold map_size[0]·map_size[1] texels"))
        }
        Some(d) => Ok((d.to_vec(), true)),
        None => Ok((rectify(frame, rect), false)),
    }
}

/// Every pass of a frame; `host_depth` is a rectified map the host rasterized with
/// [`Rectification::raster`] (projective frames only), else the shadow map is resampled.
pub fn passes(
    frame: &CpuFrame,
    settings: &PrefilteredSettings,
    host_depth: Option<&[f32]>,
) -> Result<(Passes, Vec<PassTime>), Error> {
    settings.validate()?;
    let desc = frame.desc;
    let mut times = vec![];
    let mut timed = |name: &str, t: std::time::Instant| {
        times.push(PassTime { name: name.into(), ms: t.elapsed().as_secs_f64() * 1e3 })
    };
    let t = std::time::Instant::now();
    let rect = Rectification::new(desc, &settings.rectify_options());
    let (depth, host) = rectified_depth(frame, &rect, host_depth, "prefiltered host depth")?;
    timed("rectify", t);
    let t = std::time::Instant::now();
    let (basis, cumw) = prefilter(desc, &rect, settings, &depth, host.then_some(desc.lights[0].shadow_bias));
    timed("prefilter", t);
    let t = std::time::Instant::now();
    let channels = settings.channels(&desc.lights[0].light);
    let mut p = Passes { rect, depth, basis, cumw, channels, image: Image::new(1, 1) };
    let epipole = epipole_pixel(desc, settings.epipole_radius);
    p.image = evaluate(frame, settings, &p, None);
    timed("evaluate", t);
    if epipole.is_some() {
        let t = std::time::Instant::now();
        march_epipole(frame, settings, epipole, &mut p.image);
        timed("epipole", t);
    }
    Ok((p, times))
}

/// Renders `frame` on the CPU; the result matches `super::Prefiltered::encode` up to the GPU's
/// filtering precision.
pub fn render(frame: &CpuFrame, settings: &PrefilteredSettings) -> Result<(Image, TechniqueStats), Error> {
    render_with(frame, settings, None)
}

/// [`render`] with a host-rasterized rectified map (see [`passes`]).
pub fn render_with(
    frame: &CpuFrame,
    settings: &PrefilteredSettings,
    host_depth: Option<&[f32]>,
) -> Result<(Image, TechniqueStats), Error> {
    frame.desc.single_light()?;
    let (p, times) = passes(frame, settings, host_depth)?;
    let epipole = epipole_pixel(frame.desc, settings.epipole_radius);
    let stats = TechniqueStats {
        technique: "prefiltered".into(),
        backend: "cpu".into(),
        timing: "wall-clock".into(),
        passes: times,
        raymarched_samples: super::epipole_samples(frame.desc, settings, epipole),
        gpu_memory_bytes: 0,
        extra: stats_extra(settings, &p.rect, host_depth.is_some() && p.rect.mode == Mode::Projective),
    };
    Ok((p.image, stats))
}
