//! The package's exceptions: one base class, `urbansem.UrbansemError`, and one subclass per
//! library, each carrying the Rust error's message with its chain of causes.

use pyo3::create_exception;
use pyo3::exceptions::PyException;
use pyo3::prelude::*;

create_exception!(
    urbansem,
    UrbansemError,
    PyException,
    "Base class of every error urbansem raises."
);
create_exception!(
    urbansem,
    CloudError,
    UrbansemError,
    "A point cloud (or bag) could not be read or written."
);
create_exception!(
    urbansem,
    OsmError,
    UrbansemError,
    "An OpenStreetMap file could not be read."
);
create_exception!(
    urbansem,
    PboError,
    UrbansemError,
    "A pseudo-Boolean problem is malformed."
);
create_exception!(
    urbansem,
    MlnError,
    UrbansemError,
    "A Markov logic program, its evidence or its query could not be read or grounded."
);
create_exception!(
    urbansem,
    MapError,
    UrbansemError,
    "A semantic map could not be built, queried, read or written."
);
create_exception!(
    urbansem,
    LocalizeError,
    UrbansemError,
    "Localization failed: no usable map, index or scan."
);
create_exception!(
    urbansem,
    StreetsError,
    UrbansemError,
    "Street geometry could not be estimated."
);

create_exception!(
    urbansem,
    FleetError,
    UrbansemError,
    "A shard plan could not be made, a shard run or the results merged."
);

/// Adds the exception classes to the module.
pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    let py = m.py();
    m.add("UrbansemError", py.get_type::<UrbansemError>())?;
    m.add("CloudError", py.get_type::<CloudError>())?;
    m.add("OsmError", py.get_type::<OsmError>())?;
    m.add("PboError", py.get_type::<PboError>())?;
    m.add("MlnError", py.get_type::<MlnError>())?;
    m.add("MapError", py.get_type::<MapError>())?;
    m.add("LocalizeError", py.get_type::<LocalizeError>())?;
    m.add("StreetsError", py.get_type::<StreetsError>())?;
    m.add("FleetError", py.get_type::<FleetError>())?;
    Ok(())
}

/// The error's message followed by each cause not already part of it, as the CLI prints.
pub fn chain(e: &(dyn std::error::Error + 'static)) -> String {
    let mut text = e.to_string();
    let mut source = e.source();
    while let Some(cause) = source {
        let c = cause.to_string();
        if !text.contains(&c) {
            text.push_str(": ");
            text.push_str(&c);
        }
        source = cause.source();
    }
    text
}

/// Turns a library error into the given exception class with its whole chain as message.
macro_rules! raise {
    ($class:ident) => {
        |e| $crate::error::$class::new_err($crate::error::chain(&e))
    };
}
pub(crate) use raise;
