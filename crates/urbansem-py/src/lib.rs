//! The `urbansem` Python package's native module, `urbansem._urbansem`: a thin layer over the
//! urbansem libraries. Arrays cross as NumPy arrays (inputs read in place when contiguous,
//! outputs handed over without copying), reports as the libraries' typed values turned into
//! Python dicts by `pythonize`, errors as the exceptions of the `error` module. Every long call
//! releases the GIL. The Python side (`python/urbansem`) adds dataclasses, docstrings and
//! type stubs.

use pyo3::prelude::*;

mod arrays;
mod cloud;
mod error;
mod fleet;
mod localize;
mod mln;
mod osm;
mod pbo;
mod srtree;
mod streets;

/// The native module `urbansem._urbansem`.
#[pymodule]
fn _urbansem(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    error::register(m)?;
    cloud::register(m)?;
    osm::register(m)?;
    pbo::register(m)?;
    mln::register(m)?;
    srtree::register(m)?;
    localize::register(m)?;
    streets::register(m)?;
    fleet::register(m)?;
    Ok(())
}
