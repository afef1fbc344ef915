//! `urbansem bench …`: side-by-side benchmarks against the peers named in the issues.
//!
//! A harness, not a library of the pipeline: it sits above every crate, runs the peers
//! (Python scripts under `scripts/`), and prints tables or JSON. Like the binary it reports
//! errors with `anyhow`. The `urbansem` binary dispatches [`BenchCommand`] to [`run`].
//!
//! - [`pbo`]: QPBO and max-flow against Kolmogorov's QPBO and BK max-flow.
//! - [`mln`]: MLN MAP inference on the benchmark sets against Tuffy's answers.
//! - [`srtree`]: map insertion and box queries against OctoMap and libspatialindex.
//! - [`parsers`]: every reader on inputs of three sizes, and the OPB grid end to end.
//! - [`sim`]: the scan simulator's rays per second (`urbansem sim bench`).
//! - [`streets_svm`]: the street bin SVM beside libsvm (`urbansem streets bench-svm`).
//! - [`metrics`]: CPU time and memory of this process.

pub mod metrics;
pub mod mln;
pub mod parsers;
pub mod pbo;
pub mod sim;
pub mod srtree;
pub mod streets_svm;

use clap::Subcommand;

/// An error in how a benchmark was called (the binary exits with 2), as opposed to a
/// failure while it ran.
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
        return Err(anyhow::Error::new($crate::UsageError(format!($($arg)*))))
    };
}
pub(crate) use usage;

/// Subcommands of `urbansem bench`.
#[derive(Subcommand)]
pub enum BenchCommand {
    /// QPBO and max-flow against Kolmogorov's QPBO (thinqpbo) and BK max-flow (PyMaxflow).
    Pbo(pbo::PboBenchArgs),
    /// MLN MAP inference on the benchmark sets: our cost and time against Tuffy's shipped
    /// answers (re-scored by our evaluator) and the thesis' time targets.
    Mln(mln::MlnBenchArgs),
    /// SRTree map insertion and box queries on the real scans (peers: scripts/bench_srtree_octomap.py).
    Srtree(srtree::SrtreeBenchArgs),
    /// Every reader on inputs of three sizes (MB/s, growth per step) and the OPB grid end
    /// to end beside thinqpbo.
    Parsers(parsers::ParsersBenchArgs),
}

/// Runs one `urbansem bench` subcommand.
pub fn run(command: BenchCommand) -> anyhow::Result<()> {
    match command {
        BenchCommand::Pbo(args) => pbo::bench_pbo(&args),
        BenchCommand::Mln(args) => mln::bench_mln(&args),
        BenchCommand::Srtree(args) => srtree::bench_srtree(&args),
        BenchCommand::Parsers(args) => parsers::run(&args),
    }
}
