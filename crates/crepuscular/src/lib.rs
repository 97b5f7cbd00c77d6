//! # crepuscular
//!
//! Real-time single scattering in homogeneous participating media — crepuscular rays, light
//! shafts, volumetric shadows — on the GPU through wgpu, with a CPU mirror of every step.
//!
//! The effect takes what a renderer already has (camera, light, medium, a depth texture and a
//! shadow map) through one boundary, [`frame`], and writes an in-scattering texture.
#![deny(missing_docs)]

pub mod camera;
pub mod composite;
pub mod debug;
pub mod error;
pub mod frame;
pub mod gpu;
pub mod image;
pub mod integrand;
mod light_sum;
pub mod march;
pub mod model;
pub mod record;
pub mod scattering;
pub mod shaders;
pub mod shadow;
pub mod stats;
pub mod techniques;
pub mod temporal;
#[doc(hidden)]
pub mod testing;
pub mod tonemap;

pub use camera::{DepthConvention, FrameCamera};
pub use composite::{Composite, CompositeInputs, CompositeTarget};
pub use error::Error;
pub use frame::{CpuFrame, FrameDesc, FrameLight, FrameUniforms, GpuFrame, LightUniforms, LightsUniforms, MAX_LIGHTS};
pub use gpu::{GpuContext, StatsMode};
pub use image::Image;
pub use model::{Camera, Light, Medium, Phase, RgbTexture};
pub use scattering::Scattering;
pub use shadow::{Bounds, ShadowCoord, ShadowFilter, ShadowMap, ShadowProjection, ShadowSettings};
pub use techniques::{AnyGpuTechnique, TechniqueSettings};
pub use temporal::{CpuTemporal, HistoryFilter, Temporal, TemporalSettings};
