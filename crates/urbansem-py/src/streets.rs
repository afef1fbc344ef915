//! The streets bindings (see the package's docs).

use pyo3::prelude::*;

/// Adds the streets bindings to the module.
pub fn register(_m: &Bound<'_, PyModule>) -> PyResult<()> {
    Ok(())
}
