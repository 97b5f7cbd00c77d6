//! The `crepuscular` command-line tool as a library: the render pipeline (scene → host
//! renderer → technique → composite), metrics and atomic file output, so that tests and other
//! front ends share exactly what the binary does.

pub mod animate;
pub mod bench;
pub mod compare;
pub mod metrics;
pub mod output;
pub mod quality;
pub mod render;
pub mod view;
