//! One module per command group; each has a clap `…Command` enum and a `run` function.

pub mod bench;
pub mod cloud;
pub mod demo;
pub mod localize;
pub mod mln;
pub mod osm;
pub mod pbo;
pub mod sim;
pub mod srtree;
pub mod streets;
