//! The techniques, one folder each: settings, GPU passes with their WGSL beside them, and
//! `cpu.rs`, the CPU mirror with the same sample placement and function names.

use crate::error::Error;
use crate::frame::{CpuFrame, FrameDesc, GpuFrame};
use crate::gpu::{GpuContext, Recorder};
use crate::image::Image;
use crate::stats::TechniqueStats;

/// Implements [`GpuTechnique`] for a technique's GPU side `$gpu` (fields `settings` and
/// `binds`, inherent `new`, `encode` and `gpu_memory_bytes`) with settings `$settings`.
macro_rules! gpu_technique {
    ($gpu:ident, $settings:ident) => {
        impl crate::techniques::GpuTechnique for $gpu {
            type Settings = $settings;
            fn new(gpu: &GpuContext, settings: $settings, output: wgpu::TextureFormat) -> Result<Self, Error> {
                $gpu::new(gpu, settings, output)
            }
            fn settings_mut(&mut self) -> &mut $settings {
                &mut self.settings
            }
            fn settings(&self) -> &$settings {
                &self.settings
            }
            fn encode(
                &mut self,
                gpu: &GpuContext,
                rec: &mut Recorder,
                frame: &GpuFrame,
                output: &wgpu::TextureView,
            ) -> Result<TechniqueStats, Error> {
                $gpu::encode(self, gpu, rec, frame, output)
            }
            fn gpu_memory_bytes(&self) -> u64 {
                $gpu::gpu_memory_bytes(self)
            }
            fn bind_group_builds(&self) -> u64 {
                self.binds.builds()
            }
        }
    };
}

pub mod brute_force;
pub mod epipolar;
pub mod interleaved;
pub mod minmax;
pub mod pass;
pub mod prefiltered;
pub mod presets;
pub mod reference;
pub mod subsampled;

/// What the tool and the docs list about a technique.
#[derive(Clone, Copy, Debug)]
pub struct TechniqueInfo {
    /// Name used on the command line and in scene files (`[render.<name>]`).
    pub name: &'static str,
    /// One line.
    pub summary: &'static str,
    /// The paper it implements.
    pub paper: &'static str,
    /// Runs on the GPU.
    pub gpu: bool,
    /// Runs on the CPU.
    pub cpu: bool,
    /// How it handles several lights (docs/MODEL.md §6). False: one march evaluates every light
    /// at each sample (the positions, transmittance and per-pixel work are shared). True: its
    /// structure depends on where the light is (epipolar lines, a rectified map), so it runs
    /// once per light that reaches the view, on [`FrameDesc::with_light`], and
    /// [`crate::Scattering`] and [`TechniqueSettings::render_cpu`] add the lights up.
    pub per_light: bool,
}

/// What a technique's folder provides to the registry (the `registry!` macro below): its description, its
/// settings' checks, its CPU mirror and (for GPU techniques) its GPU side. Implemented on the
/// technique's settings type.
pub trait Technique: Clone + std::fmt::Debug + Default + serde::Serialize + serde::de::DeserializeOwned {
    /// Name, summary and paper.
    const INFO: TechniqueInfo;
    /// Checks the ranges; the error names the setting and value.
    fn validate(&self) -> Result<(), Error>;
    /// The CPU implementation of the technique on a frame; `rectified` as in
    /// [`TechniqueSettings::render_cpu`].
    fn render_cpu(
        &self,
        frame: &CpuFrame,
        rectified: Option<&[f32]>,
        progress: &(dyn Fn(u64, u64) + Sync),
    ) -> Result<(Image, TechniqueStats), Error>;
    /// The host raster the technique wants for a one-light frame (only `prefiltered` has one).
    fn raster_request(&self, _desc: &FrameDesc) -> Option<prefiltered::RectifiedRaster> {
        None
    }
}

/// A technique's GPU side, built once on a device and recorded every frame.
pub trait GpuTechnique: Sized {
    /// Its settings.
    type Settings: Technique;
    /// Builds pipelines and size-independent buffers; the final pass writes the in-scattering
    /// in `output`'s format (one of [`pass::OUTPUT_FORMATS`]).
    fn new(gpu: &GpuContext, settings: Self::Settings, output: wgpu::TextureFormat) -> Result<Self, Error>;
    /// The settings used from the next frame on.
    fn settings_mut(&mut self) -> &mut Self::Settings;
    /// The current settings.
    fn settings(&self) -> &Self::Settings;
    /// Records one frame through `rec` (pass times and counters are filled in by
    /// [`crate::Scattering`]).
    fn encode(
        &mut self,
        gpu: &GpuContext,
        rec: &mut Recorder,
        frame: &GpuFrame,
        output: &wgpu::TextureView,
    ) -> Result<TechniqueStats, Error>;
    /// Bytes of GPU memory held.
    fn gpu_memory_bytes(&self) -> u64;
    /// How many times the frame's bind groups were built (on the first frame, a resize, a
    /// settings change that reallocates, or other input textures; not per frame).
    fn bind_group_builds(&self) -> u64;
}

/// Generates the technique registry from one line per technique: [`TechniqueSettings`] (a
/// technique and its settings), [`AnyGpuTechnique`] (its built GPU side) and [`TECHNIQUES`].
macro_rules! registry {
    (gpu: [$($variant:ident($module:ident::$settings:ident) => $gpu:ident),* $(,)?],
     cpu: [$($cvariant:ident($cmodule:ident::$csettings:ident)),* $(,)?]) => {
        /// A technique and its settings: what a scene file's `[render.<name>]` table, a
        /// `--set key=value` and [`crate::Scattering::new`] take.
        #[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
        #[serde(tag = "technique", rename_all = "kebab-case")]
        pub enum TechniqueSettings {
            $(#[doc = concat!("`", stringify!($module), "`: [`", stringify!($module), "::", stringify!($settings), "`].")]
              $variant($module::$settings),)*
            $(#[doc = concat!("`", stringify!($cmodule), "` (CPU only).")]
              $cvariant($cmodule::$csettings),)*
        }

        /// Every technique, in the order the tool lists them.
        pub const TECHNIQUES: &[TechniqueInfo] = &[
            $(<$module::$settings as Technique>::INFO,)* $(<$cmodule::$csettings as Technique>::INFO,)*
        ];

        impl TechniqueSettings {
            /// The technique's name (`brute-force`, …).
            pub fn name(&self) -> &'static str {
                match self {
                    $(Self::$variant(_) => <$module::$settings as Technique>::INFO.name,)*
                    $(Self::$cvariant(_) => <$cmodule::$csettings as Technique>::INFO.name,)*
                }
            }

            /// The technique called `name` at its default settings; an error lists the names.
            pub fn named(name: &str) -> Result<Self, Error> {
                $(if name == <$module::$settings as Technique>::INFO.name {
                    return Ok(Self::$variant(Default::default()));
                })*
                $(if name == <$cmodule::$csettings as Technique>::INFO.name {
                    return Ok(Self::$cvariant(Default::default()));
                })*
                Err(unknown(name))
            }

            /// The technique called `name` with its settings read from `d` (a scene file's table:
            /// every field optional, unknown fields refused). `Ok(None)`: no such technique.
            pub fn deserialize_named<'de, D: serde::Deserializer<'de>>(
                name: &str,
                d: D,
            ) -> Result<Option<Self>, D::Error> {
                use serde::Deserialize;
                $(if name == <$module::$settings as Technique>::INFO.name {
                    return $module::$settings::deserialize(d).map(|s| Some(Self::$variant(s)));
                })*
                $(if name == <$cmodule::$csettings as Technique>::INFO.name {
                    return $cmodule::$csettings::deserialize(d).map(|s| Some(Self::$cvariant(s)));
                })*
                Ok(None)
            }

            /// Checks the ranges; the error names the setting and value.
            pub fn validate(&self) -> Result<(), Error> {
                match self {
                    $(Self::$variant(s) => s.validate(),)*
                    $(Self::$cvariant(s) => s.validate(),)*
                }
            }

            /// True for the techniques with a GPU side.
            pub fn has_gpu(&self) -> bool {
                !matches!(self, $(Self::$cvariant(_))|*)
            }

            /// The technique's name, summary and paper.
            pub fn info(&self) -> &'static TechniqueInfo {
                match self {
                    $(Self::$variant(_) => &<$module::$settings as Technique>::INFO,)*
                    $(Self::$cvariant(_) => &<$cmodule::$csettings as Technique>::INFO,)*
                }
            }

            /// The host raster of a one-light frame (see [`crate::Scattering::raster_requests`]).
            pub fn raster_request(&self, desc: &FrameDesc) -> Option<prefiltered::RectifiedRaster> {
                match self {
                    $(Self::$variant(s) => s.raster_request(desc),)*
                    $(Self::$cvariant(s) => s.raster_request(desc),)*
                }
            }

            pub(crate) fn render_cpu_unchecked(
                &self,
                frame: &CpuFrame,
                rectified: Option<&[f32]>,
                progress: &(dyn Fn(u64, u64) + Sync),
            ) -> Result<(Image, TechniqueStats), Error> {
                match self {
                    $(Self::$variant(s) => s.render_cpu(frame, rectified, progress),)*
                    $(Self::$cvariant(s) => s.render_cpu(frame, rectified, progress),)*
                }
            }
        }

        /// A technique's built GPU side (inside a [`crate::Scattering`]); match on it for a
        /// technique's own debug readbacks and intermediate textures.
        pub enum AnyGpuTechnique {
            $(#[doc = concat!("[`", stringify!($module), "::", stringify!($gpu), "`].")]
              $variant($module::$gpu),)*
        }

        impl AnyGpuTechnique {
            pub(crate) fn new(
                gpu: &GpuContext,
                settings: TechniqueSettings,
                output: wgpu::TextureFormat,
            ) -> Result<Self, Error> {
                match settings {
                    $(TechniqueSettings::$variant(s) => {
                        Ok(Self::$variant(<$module::$gpu as GpuTechnique>::new(gpu, s, output)?))
                    })*
                    other => Err(Error::invalid(
                        "technique",
                        other.name(),
                        "runs on the CPU only (TechniqueSettings::render_cpu)",
                    )),
                }
            }

            /// The technique's name.
            pub fn name(&self) -> &'static str {
                self.info().name
            }

            /// The technique's name, summary, paper and how it handles lights.
            pub fn info(&self) -> &'static TechniqueInfo {
                match self {
                    $(Self::$variant(_) => &<$module::$settings as Technique>::INFO,)*
                }
            }

            /// Its current settings.
            pub fn settings(&self) -> TechniqueSettings {
                match self {
                    $(Self::$variant(t) => TechniqueSettings::$variant(t.settings().clone()),)*
                }
            }

            pub(crate) fn update(&mut self, settings: &TechniqueSettings) -> bool {
                match (self, settings) {
                    $((Self::$variant(t), TechniqueSettings::$variant(s)) => *t.settings_mut() = s.clone(),)*
                    _ => return false,
                }
                true
            }

            pub(crate) fn encode(
                &mut self,
                gpu: &GpuContext,
                rec: &mut Recorder,
                frame: &GpuFrame,
                output: &wgpu::TextureView,
            ) -> Result<TechniqueStats, Error> {
                match self {
                    $(Self::$variant(t) => t.encode(gpu, rec, frame, output),)*
                }
            }

            /// Bytes of GPU memory held.
            pub fn gpu_memory_bytes(&self) -> u64 {
                match self {
                    $(Self::$variant(t) => t.gpu_memory_bytes(),)*
                }
            }

            /// How many times the frame's bind groups were built (see
            /// [`GpuTechnique::bind_group_builds`]).
            pub fn bind_group_builds(&self) -> u64 {
                match self {
                    $(Self::$variant(t) => t.bind_group_builds(),)*
                }
            }
        }
    };
}

fn unknown(name: &str) -> Error {
    let known: Vec<_> = TECHNIQUES.iter().map(|t| t.name).collect();
    Error::invalid("technique", name, format!("unknown technique (known: {})", known.join(", ")))
}

// The registry: one line per technique (its folder implements `Technique` on its settings and,
// for the GPU techniques, `GpuTechnique` on its GPU side).
registry! {
    gpu: [
        BruteForce(brute_force::BruteForceSettings) => BruteForce,
        Interleaved(interleaved::InterleavedSettings) => Interleaved,
        Subsampled(subsampled::SubsampledSettings) => Subsampled,
        Epipolar(epipolar::EpipolarSettings) => Epipolar,
        Prefiltered(prefiltered::PrefilteredSettings) => Prefiltered,
        Minmax(minmax::MinmaxSettings) => MinMax,
    ],
    cpu: [
        Reference(reference::ReferenceSettings),
    ]
}

/// Looks a technique up by name.
pub fn find(name: &str) -> Option<&'static TechniqueInfo> {
    TECHNIQUES.iter().find(|t| t.name == name)
}

impl TechniqueSettings {
    /// Whether the technique's in-scattering carries, in alpha, minus each pixel's scattering
    /// distance (the luminance-weighted mean distance from the eye of its point and spot
    /// lights' light along its ray, [`crate::march::scattering_distance`]; 0 where they give
    /// less than half of it), which
    /// the temporal stage reprojects by under
    /// [`crate::TemporalSettings::scattering_distance`]. Only `brute-force` writes it, from
    /// its own march's samples; the other techniques write 1 there (their samples are not one
    /// ray's march per pixel: interleaved's are split over a window, subsampled's and
    /// epipolar's interpolated, prefiltered's and minmax's not point samples).
    pub fn writes_scattering_distance(&self) -> bool {
        matches!(self, Self::BruteForce(_))
    }

    /// How the technique marches its view rays ([`crate::march::MarchSettings`]: `steps`,
    /// `jitter`, `frame_index`), where it marches them: `brute-force`, `interleaved`,
    /// `subsampled` and `epipolar`. None for `prefiltered`, `minmax` and `reference`, which
    /// have no march whose samples a frame could move.
    pub fn ray_march(&self) -> Option<&crate::march::MarchSettings> {
        match self {
            Self::BruteForce(s) => Some(&s.ray_march),
            Self::Interleaved(s) => Some(&s.ray_march),
            Self::Subsampled(s) => Some(&s.ray_march),
            Self::Epipolar(s) => Some(&s.ray_march),
            Self::Prefiltered(_) | Self::Minmax(_) | Self::Reference(_) => None,
        }
    }

    /// [`Self::ray_march`], to change.
    pub fn ray_march_mut(&mut self) -> Option<&mut crate::march::MarchSettings> {
        match self {
            Self::BruteForce(s) => Some(&mut s.ray_march),
            Self::Interleaved(s) => Some(&mut s.ray_march),
            Self::Subsampled(s) => Some(&mut s.ray_march),
            Self::Epipolar(s) => Some(&mut s.ray_march),
            Self::Prefiltered(_) | Self::Minmax(_) | Self::Reference(_) => None,
        }
    }

    /// These settings for frame `frame` of a jittered sequence, as the temporal stage wants
    /// them (docs/MODEL.md §7): `jitter` on and `frame_index` = `frame` where the technique
    /// marches ([`Self::ray_march`]); unchanged where it does not. Feeding the result to
    /// [`crate::Scattering::update`] every frame changes no pipeline and no allocation.
    pub fn jittered(&self, frame: u32) -> Self {
        let mut s = self.clone();
        if let Some(m) = s.ray_march_mut() {
            m.jitter = true;
            m.frame_index = frame;
        }
        s
    }
}

#[cfg(test)]
mod tests {
    use super::{TECHNIQUES, TechniqueSettings};

    /// `ray_march` is there exactly for the techniques whose settings have the march's keys
    /// (`steps`, `jitter`, `frame_index` in their scene-file table), and `jittered` sets the
    /// two that move the samples and nothing else.
    #[test]
    fn jittered_moves_the_march_of_exactly_the_marching_techniques() {
        let mut marching = Vec::new();
        for info in TECHNIQUES {
            let base = TechniqueSettings::named(info.name).expect("a listed technique");
            let table = toml::Value::try_from(&base).expect("settings serialise");
            let has_keys = ["steps", "jitter", "frame_index"].iter().all(|k| table.get(k).is_some());
            assert_eq!(base.ray_march().is_some(), has_keys, "{}", info.name);
            let j = base.jittered(7);
            match j.ray_march() {
                Some(m) => {
                    marching.push(info.name);
                    assert!(m.jitter && m.frame_index == 7, "{}", info.name);
                    let mut back = j.clone();
                    let m = back.ray_march_mut().expect("marches");
                    (m.jitter, m.frame_index) = (false, 0);
                    assert_eq!(back, base, "{}: jittered changed another setting", info.name);
                }
                None => assert_eq!(j, base, "{}: a technique without a march is unchanged", info.name),
            }
        }
        assert_eq!(marching, ["brute-force", "interleaved", "subsampled", "epipolar"]);
    }
}
