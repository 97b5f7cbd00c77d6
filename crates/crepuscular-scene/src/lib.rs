//! Scenes for crepuscular: built-in procedural scenes, TOML scene files, glTF/OBJ import, and
//! the host renderer (GPU and a CPU rasterizer with the same conventions) that produces the
//! depth, surface colour and shadow maps the effect reads.
#![deny(missing_docs)]

pub mod builtin;
pub mod file;
pub mod mesh;
pub mod raster;
pub mod scene;

pub use host::{GpuHost, HostTextures};
pub use scene::{Geometry, RenderSettings, Scene, SceneLight, Vertex};
pub mod host;
pub mod host_cpu;
