//! Settings presets named by intent — [`Preset::Fast`], [`Preset::Balanced`],
//! [`Preset::ReferenceLike`] — for every technique, so that a renderer can offer "quality:
//! low / medium / high" without knowing what each technique's knobs mean.
//!
//! [`TechniqueSettings`] (the registry's, [`crate::techniques`]) is one technique's settings,
//! tagged with its name; it is serde-serialisable (`{ technique = "brute-force", steps = 32, ... }`), so a user can save a
//! preset (or a tuned variant of one) and load it back.
//!
//! What each preset chooses, and why:
//!
//! | technique | `fast` | `balanced` | `reference-like` |
//! | --- | --- | --- | --- |
//! | `brute-force` | 32 steps | 64 steps (the default) | 256 steps |
//! | `interleaved` | M = 4, 32 steps (2 per pixel) | M = 4, 64 steps (the default, 4 per pixel) | M = 2, 256 steps (64 per pixel) |
//! | `subsampled` | factor 4, 32 steps | factor 4, 64 steps (the default) | factor 2, 256 steps |
//! | `epipolar` | K = 16, 32 steps | K = 32, 64 steps (the default) | K = 64, 256 steps, growth 0.02, 5 taps |
//! | `prefiltered` | 512² map, M = 16, 1 band | 1024² map, M = 32, 4 bands (the default) | 2048² map, M = 64, 8 bands |
//! | `minmax` | 512² map, 16 light segments | 1024² map, 32 light segments (the default) | 2048² map, 128 light segments |
//! | `reference` | 64 steps | 256 steps | 1024 steps (the default) |
//!
//! - **Fast** halves the steps of the defaults: visible banding in thin shafts, about half the
//!   march cost. The sample layouts stay at their defaults: coarser grids or fewer lines lose
//!   whole shafts, which costs more quality per saved millisecond than fewer steps do.
//! - **Balanced** is every technique's default: the settings the README's quality table and the
//!   bench were measured at.
//! - **ReferenceLike** marches 256 steps (brute-force at 256 steps is within ~0.1 dB of the
//!   1024-step reference on the built-in scenes) and tightens the sample layouts (a finer grid,
//!   a smaller interleaving block, more initial samples and a lower discontinuity threshold),
//!   at 4× to 16× the cost of `balanced`. Spot lights keep `exact-cone` step placement in every
//!   preset (the library's default: the only policy that is exact for a spot aimed across the
//!   view, docs/ROBUSTNESS.md). Jitter stays off: a still image without temporal accumulation
//!   looks better banded than noisy.

use crate::error::Error;
use crate::march::{MarchSettings, SpotSteps, StepPolicy};
use crate::techniques::TechniqueSettings;
use crate::techniques::brute_force::BruteForceSettings;
use crate::techniques::epipolar::EpipolarSettings;
use crate::techniques::interleaved::InterleavedSettings;
use crate::techniques::minmax::MinmaxSettings;
use crate::techniques::prefiltered::PrefilteredSettings;
use crate::techniques::reference::ReferenceSettings;
use crate::techniques::subsampled::SubsampledSettings;
use serde::{Deserialize, Serialize};

/// A quality/cost intent.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Preset {
    /// Half the steps of the defaults: the cheapest settings that still look like shafts.
    Fast,
    /// Each technique's defaults.
    #[default]
    Balanced,
    /// 256 steps and tightened sample layouts: close to `reference`, several times the cost.
    ReferenceLike,
}

impl Preset {
    /// Every preset, cheapest first.
    pub const ALL: [Preset; 3] = [Preset::Fast, Preset::Balanced, Preset::ReferenceLike];

    /// Name, as on the command line (`fast`, `balanced`, `reference-like`).
    pub fn name(self) -> &'static str {
        match self {
            Preset::Fast => "fast",
            Preset::Balanced => "balanced",
            Preset::ReferenceLike => "reference-like",
        }
    }

    /// Parses a name (`fast`, `balanced`, `reference-like`).
    pub fn parse(name: &str) -> Result<Preset, Error> {
        Preset::ALL
            .into_iter()
            .find(|p| p.name() == name)
            .ok_or_else(|| Error::invalid("preset", name, "must be one of fast, balanced, reference-like"))
    }

    /// The settings of `technique` (a name from [`super::TECHNIQUES`]) for this preset; None
    /// for an unknown technique.
    pub fn settings(self, technique: &str) -> Option<TechniqueSettings> {
        Some(match technique {
            "brute-force" => TechniqueSettings::BruteForce(self.brute_force()),
            "interleaved" => TechniqueSettings::Interleaved(self.interleaved()),
            "subsampled" => TechniqueSettings::Subsampled(self.subsampled()),
            "epipolar" => TechniqueSettings::Epipolar(self.epipolar()),
            "prefiltered" => TechniqueSettings::Prefiltered(self.prefiltered()),
            "minmax" => TechniqueSettings::Minmax(self.minmax()),
            "reference" => TechniqueSettings::Reference(self.reference()),
            _ => return None,
        })
    }

    fn steps(self) -> u32 {
        match self {
            Preset::Fast => 32,
            Preset::Balanced => 64,
            Preset::ReferenceLike => 256,
        }
    }

    /// `brute-force`: 32 / 64 / 256 steps, `exact-cone` for spot lights.
    pub fn brute_force(self) -> BruteForceSettings {
        BruteForceSettings {
            ray_march: MarchSettings { steps: self.steps(), ..Default::default() },
            policy: StepPolicy { spot: SpotSteps::ExactCone, ..Default::default() },
            ..Default::default()
        }
    }

    /// `interleaved`: M = 4 with 32 / 64 steps, M = 2 with 256 steps for `reference-like` (a
    /// smaller block blurs thin shafts over fewer pixels).
    pub fn interleaved(self) -> InterleavedSettings {
        let block = if self == Preset::ReferenceLike { 2 } else { 4 };
        InterleavedSettings {
            ray_march: MarchSettings { steps: self.steps(), ..Default::default() },
            policy: StepPolicy { spot: SpotSteps::ExactCone, ..Default::default() },
            block,
            ..Default::default()
        }
    }

    /// `subsampled`: factor 4 with 32 / 64 steps, factor 2 with 256 steps for `reference-like`;
    /// silhouette re-marching on in all.
    pub fn subsampled(self) -> SubsampledSettings {
        let factor = if self == Preset::ReferenceLike { 2 } else { 4 };
        SubsampledSettings {
            ray_march: MarchSettings { steps: self.steps(), ..Default::default() },
            policy: StepPolicy { spot: SpotSteps::ExactCone, ..Default::default() },
            factor,
            edge_remarch: true,
            ..Default::default()
        }
    }

    /// `epipolar`: K = 16 / 32 / 64 initial samples per line with 32 / 64 / 256 steps; the
    /// automatic line and texel counts; `reference-like` also lowers the relative discontinuity
    /// threshold to 0.02 (more samples at silhouettes) and filters with 5 taps.
    pub fn epipolar(self) -> EpipolarSettings {
        let d = EpipolarSettings::default();
        let (initial_samples, threshold_growth, taps) = match self {
            Preset::Fast => (16, d.threshold_growth, d.taps),
            Preset::Balanced => (d.initial_samples, d.threshold_growth, d.taps),
            Preset::ReferenceLike => (64, 0.02, 5),
        };
        EpipolarSettings {
            ray_march: MarchSettings { steps: self.steps(), ..Default::default() },
            policy: StepPolicy { spot: SpotSteps::ExactCone, ..Default::default() },
            initial_samples,
            threshold_growth,
            taps,
            ..d
        }
    }

    /// `prefiltered`: a 512² map, M = 16, one band (the paper's single reference ray) / the
    /// defaults (1024², M = 32, 4 bands) / a 2048² map, M = 64, 8 bands and a 16-pixel
    /// ray-marched epipole disc; the disc marches 32 / 64 / 256 steps.
    pub fn prefiltered(self) -> PrefilteredSettings {
        let d = PrefilteredSettings::default();
        let (map, bases, bands, radius) = match self {
            Preset::Fast => (512, 16, 1, d.epipole_radius),
            Preset::Balanced => (d.map_size[0], d.bases, d.bands, d.epipole_radius),
            Preset::ReferenceLike => (2048, 64, 8, 16),
        };
        PrefilteredSettings {
            policy: StepPolicy { spot: SpotSteps::ExactCone, ..Default::default() },
            map_size: [map, map],
            bases,
            bands,
            bases_per_thread: d.bases_per_thread.min(bases),
            epipole_radius: radius,
            epipole_steps: self.steps(),
            ..d
        }
    }

    /// `minmax`: a 512² / 1024² (the default) / 2048² rectified map — its resolution is what the
    /// result is exact at —, 16 / 32 / 128 quadrature segments for spot and point lights, and the
    /// epipole disc as `prefiltered`'s (32 / 64 / 256 steps, 16 pixels for `reference-like`).
    pub fn minmax(self) -> MinmaxSettings {
        let d = MinmaxSettings::default();
        let (map, light_steps, radius) = match self {
            Preset::Fast => (512, 16, d.epipole_radius),
            Preset::Balanced => (d.map_size[0], d.light_steps, d.epipole_radius),
            Preset::ReferenceLike => (2048, 128, 16),
        };
        MinmaxSettings {
            policy: StepPolicy { spot: SpotSteps::ExactCone, ..Default::default() },
            map_size: [map, map],
            light_steps,
            epipole_radius: radius,
            epipole_steps: self.steps(),
            ..d
        }
    }

    /// `reference`: 64 / 256 / 1024 stratified steps (a quick look, a fair comparison, the
    /// default ground truth).
    pub fn reference(self) -> ReferenceSettings {
        let steps = match self {
            Preset::Fast => 64,
            Preset::Balanced => 256,
            Preset::ReferenceLike => 1024,
        };
        ReferenceSettings { steps, ..Default::default() }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Ray-marching steps per ray (per pixel, sample or reference pixel).
    fn march_steps(s: &TechniqueSettings) -> u32 {
        match s {
            TechniqueSettings::BruteForce(s) => s.ray_march.steps,
            TechniqueSettings::Interleaved(s) => s.ray_march.steps,
            TechniqueSettings::Subsampled(s) => s.ray_march.steps,
            TechniqueSettings::Epipolar(s) => s.ray_march.steps,
            TechniqueSettings::Prefiltered(s) => s.epipole_steps,
            TechniqueSettings::Minmax(s) => s.epipole_steps,
            TechniqueSettings::Reference(s) => s.steps,
        }
    }

    #[test]
    fn every_preset_of_every_technique_validates() {
        for t in super::super::TECHNIQUES {
            for p in Preset::ALL {
                let s = p.settings(t.name).unwrap_or_else(|| panic!("{}: no {} preset", t.name, p.name()));
                assert_eq!(s.name(), t.name);
                s.validate().unwrap_or_else(|e| panic!("{} {}: {e}", t.name, p.name()));
            }
        }
        assert!(Preset::Fast.settings("no-such-technique").is_none());
    }

    #[test]
    fn steps_grow_with_quality() {
        for t in super::super::TECHNIQUES {
            let steps = Preset::ALL.map(|p| march_steps(&p.settings(t.name).unwrap()));
            assert!(steps[0] <= steps[1] && steps[1] <= steps[2], "{}: {steps:?}", t.name);
        }
    }

    #[test]
    fn balanced_is_the_default() {
        assert_eq!(Preset::Balanced.brute_force(), BruteForceSettings::default());
        assert_eq!(Preset::Balanced.interleaved(), InterleavedSettings::default());
        assert_eq!(Preset::Balanced.subsampled(), SubsampledSettings::default());
        assert_eq!(Preset::Balanced.epipolar(), EpipolarSettings::default());
        assert_eq!(Preset::Balanced.minmax(), MinmaxSettings::default());
    }

    #[test]
    fn presets_round_trip_through_toml() {
        for t in super::super::TECHNIQUES {
            for p in Preset::ALL {
                let s = p.settings(t.name).unwrap();
                let text = toml::to_string(&s).unwrap();
                let back: TechniqueSettings = toml::from_str(&text).unwrap();
                assert_eq!(back, s, "{text}");
            }
            assert_eq!(Preset::parse(Preset::ReferenceLike.name()).unwrap(), Preset::ReferenceLike);
            assert!(Preset::parse("ultra").is_err());
        }
    }

    #[test]
    fn the_shared_march_keys_are_keys_of_every_technique_table() {
        use crate::march::LocalSteps;
        let table = |text: &str| toml::Value::Table(toml::from_str(text).unwrap());
        let march = "steps = 17\njitter = true\nframe_index = 3\n";
        let policy = "spot_steps = \"fixed\"\nspot_denominator = 0.5\nlocal_steps = \"uniform\"\n";
        let want_march = MarchSettings { steps: 17, jitter: true, frame_index: 3 };
        let want_policy = StepPolicy { spot: SpotSteps::Fixed, denominator: 0.5, local: LocalSteps::Uniform };
        for name in ["brute-force", "interleaved", "subsampled", "epipolar", "prefiltered", "minmax"] {
            let marches = !matches!(name, "prefiltered" | "minmax");
            let text = if marches { format!("{march}{policy}") } else { policy.to_string() };
            let s = TechniqueSettings::deserialize_named(name, table(&text)).unwrap().unwrap();
            let (m, p) = match &s {
                TechniqueSettings::BruteForce(s) => (Some(s.ray_march), s.policy),
                TechniqueSettings::Interleaved(s) => (Some(s.ray_march), s.policy),
                TechniqueSettings::Subsampled(s) => (Some(s.ray_march), s.policy),
                TechniqueSettings::Epipolar(s) => (Some(s.ray_march), s.policy),
                TechniqueSettings::Prefiltered(s) => (None, s.policy),
                TechniqueSettings::Minmax(s) => (None, s.policy),
                _ => unreachable!(),
            };
            assert_eq!(p, want_policy, "{name}");
            assert_eq!(m, marches.then_some(want_march), "{name}");
            // Written back, the keys are the technique table's own (nothing nested).
            let back = toml::to_string(&s).unwrap();
            assert!(
                back.contains("\nspot_denominator = 0.5\n") && !back.contains("ray_march") && !back.contains("policy"),
                "{name}: {back}"
            );
            // An unknown key is still refused, next to the shared ones.
            let e = TechniqueSettings::deserialize_named(name, table(&format!("{text}stepz = 1\n"))).unwrap_err();
            assert!(e.to_string().contains("stepz"), "{name}: {e}");
            if !marches {
                assert!(TechniqueSettings::deserialize_named(name, table("steps = 4")).is_err(), "{name}");
            }
            // A shared setting's range error names the technique's key.
            let mut bad = s.clone();
            match &mut bad {
                TechniqueSettings::BruteForce(s) => s.ray_march.steps = 0,
                TechniqueSettings::Interleaved(s) => s.ray_march.steps = 0,
                TechniqueSettings::Subsampled(s) => s.ray_march.steps = 0,
                TechniqueSettings::Epipolar(s) => s.ray_march.steps = 0,
                TechniqueSettings::Prefiltered(s) => s.policy.denominator = 0.0,
                TechniqueSettings::Minmax(s) => s.policy.denominator = 0.0,
                _ => unreachable!(),
            }
            let key = if marches { format!("{name}.steps") } else { format!("{name}.spot_denominator") };
            let e = bad.validate().unwrap_err().to_string();
            assert!(e.contains(&key), "{name}: {e}");
        }
    }
}
