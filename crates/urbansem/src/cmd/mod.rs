//! One module per command group; each has a clap `…Command` enum and a `run` function.

/// An error in how a command was called (exit code 2), as opposed to a failure while it ran
/// (exit code 1); the bench harness raises the same type.
pub use urbansem_bench::UsageError;

/// Returns a [`UsageError`] from the enclosing function, formatted like `format!`.
macro_rules! usage {
    ($($arg:tt)*) => {
        return Err(anyhow::Error::new($crate::cmd::UsageError(format!($($arg)*))))
    };
}
pub(crate) use usage;

pub mod cloud;
pub mod demo;
pub mod localize;
pub mod mln;
pub mod osm;
pub mod pbo;
pub mod sim;
pub mod srtree;
pub mod streets;

/// Prints a report as pretty JSON, keys sorted.
pub(crate) fn print_json(report: &impl serde::Serialize) -> anyhow::Result<()> {
    println!(
        "{}",
        serde_json::to_string_pretty(&serde_json::to_value(report)?)?
    );
    Ok(())
}
