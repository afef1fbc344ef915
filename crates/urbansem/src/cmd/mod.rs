//! One module per command group; each has a clap `…Command` enum and a `run` function.

/// An error in how a command was called (exit code 2), as opposed to a failure while it ran
/// (exit code 1).
#[derive(Debug)]
pub struct UsageError(pub String);

impl std::fmt::Display for UsageError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for UsageError {}

/// Returns a [`UsageError`] from the enclosing function, formatted like `format!`.
macro_rules! usage {
    ($($arg:tt)*) => {
        return Err(anyhow::Error::new($crate::cmd::UsageError(format!($($arg)*))))
    };
}
pub(crate) use usage;

pub mod bench;
pub mod bench_parsers;
pub mod cloud;
pub mod demo;
pub mod localize;
pub mod mln;
pub mod osm;
pub mod pbo;
pub mod sim;
pub mod srtree;
pub mod streets;
