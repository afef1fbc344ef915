//! `urbansem`: the one binary. It parses the command line, dispatches to a command module,
//! and turns an error chain into a message and an exit code: 0 success, 1 an error while
//! running (bad input file, I/O), 2 a usage error (clap's, or a [`cmd::UsageError`]).

mod cmd;

use clap::{Parser, Subcommand};
use std::process::ExitCode;

/// mimalloc: the MLN grounder and the OSM reader allocate millions of small vectors.
#[global_allocator]
static GLOBAL: mimalloc::MiMalloc = mimalloc::MiMalloc;

/// mimalloc's `mi_option_purge_delay` (the same index in its v2 and v3 headers).
const MI_OPTION_PURGE_DELAY: libmimalloc_sys::mi_option_t = 15;

/// Makes the allocator keep freed memory for the process's reuse (purge delay −1; the default
/// returns it to the OS 10 ms after it is freed, and a later allocation faults it in again,
/// zeroed, a 2 MB huge page at a time). Measured on this 2-core VM: the localization search's
/// queue, freed and regrown scan after scan, made the simulated HDL-64 Helsinki evaluation
/// (80 scans, d_s) 0.378 s mean per scan against 0.349 s kept (three runs each, alternating;
/// system time 4.8–9.1 s against 3.6–4.4 s; peak RSS +2 %); the readers' benchmark
/// (`bench parsers`) ran the largest inputs up to 1.7× slower per byte (KITTI `.bin`) on pages
/// faulted in afresh on every read. Freed memory is not handed back before the process ends.
fn keep_freed_memory() {
    // SAFETY: sets one integer option of the global allocator; mimalloc documents
    // `mi_option_set` as callable at any time.
    unsafe { libmimalloc_sys::mi_option_set(MI_OPTION_PURGE_DELAY, -1) };
}

/// Semantic maps for robots in cities.
#[derive(Parser)]
#[command(name = "urbansem", version, about, long_about = None)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Run every capability on the embedded default city and write demo-out/.
    Demo(cmd::demo::DemoArgs),
    /// Pseudo-Boolean optimization (QPBO, quadratization, QSSR).
    #[command(subcommand)]
    Pbo(cmd::pbo::PboCommand),
    /// Markov logic networks: MAP inference.
    #[command(subcommand)]
    Mln(cmd::mln::MlnCommand),
    /// OpenStreetMap files: statistics and extraction.
    #[command(subcommand)]
    Osm(cmd::osm::OsmCommand),
    /// Point cloud files: statistics and conversion.
    #[command(subcommand)]
    Cloud(cmd::cloud::CloudCommand),
    /// Simulation: procedural cities and labelled scan datasets.
    #[command(subcommand)]
    Sim(cmd::sim::SimCommand),
    /// Street geometry: offset and width per OSM street segment.
    Streets(cmd::streets::StreetsArgs),
    /// Global localization of a 3-D scan on OSM building outlines.
    Localize(Box<cmd::localize::LocalizeArgs>),
    /// Semantic R-tree maps: build from a labelled cloud, query.
    #[command(subcommand)]
    Map(cmd::srtree::MapCommand),
    /// Spatial relations (On, LeftOf, Behind) with MLN consistency: train, infer, eval.
    #[command(subcommand)]
    Relations(cmd::srtree::RelationsCommand),
    /// Benchmarks against the peer implementations named in the issues.
    #[command(subcommand)]
    Bench(urbansem_bench::BenchCommand),
    /// Fleet jobs as engine-neutral shards: plan, run one shard anywhere, merge.
    #[command(subcommand)]
    Shard(cmd::shard::ShardCommand),
}

/// Exit code of an error while running (a file that cannot be read, bad input data).
const EXIT_RUNTIME: u8 = 1;
/// Exit code of a usage error (unknown option, missing argument, contradictory options).
const EXIT_USAGE: u8 = 2;

/// Replaces Rust's panic message by a bug report request: a panic is a bug in urbansem,
/// never the user's fault (bad input must give an error), so say so and where.
fn install_panic_hook() {
    std::panic::set_hook(Box::new(|info| {
        let message = info
            .payload()
            .downcast_ref::<&str>()
            .map(|s| (*s).to_owned())
            .or_else(|| info.payload().downcast_ref::<String>().cloned())
            .unwrap_or_else(|| "(no message)".to_owned());
        // `urbansem … | head`: the reader closed the pipe and wants no more output. Unix
        // tools stop quietly here (Rust ignores SIGPIPE, so `println!` panics instead).
        if message.starts_with("failed printing to stdout") && message.contains("Broken pipe") {
            std::process::exit(0);
        }
        let location = info
            .location()
            .map(|l| format!("{}:{}", l.file(), l.line()))
            .unwrap_or_default();
        let args: Vec<String> = std::env::args().collect();
        eprintln!(
            "error: internal error in urbansem {} (a bug, not a problem with your input): \
             {message} at {location}\n  command: {}\n  please report it with this message and, \
             if you can, the input files",
            env!("CARGO_PKG_VERSION"),
            args.join(" ")
        );
    }));
}

/// The error and its causes joined by ": ", each thing said once: an error whose message
/// already ends with its cause's text (a `thiserror` message with `{source}`) does not repeat
/// it, and a cause that starts by naming what the context above it ends with ("loading M" then
/// "M: cannot read …") does not name it again.
fn error_message(err: &anyhow::Error) -> String {
    let mut out = String::new();
    for cause in err.chain() {
        let text = cause.to_string();
        if out.ends_with(&text) {
            continue;
        }
        let mut rest = text.as_str();
        if let Some((head, tail)) = text.split_once(": ") {
            let before = out.len().saturating_sub(head.len());
            if !head.is_empty()
                && out.ends_with(head)
                && (before == 0 || out[..before].ends_with(' '))
            {
                rest = tail;
            }
        }
        if !out.is_empty() {
            out.push_str(": ");
        }
        out.push_str(rest);
    }
    out
}

fn main() -> ExitCode {
    keep_freed_memory();
    install_panic_hook();
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Demo(args) => cmd::demo::run(args),
        Command::Pbo(c) => cmd::pbo::run(c),
        Command::Mln(c) => cmd::mln::run(c),
        Command::Osm(c) => cmd::osm::run(c),
        Command::Cloud(c) => cmd::cloud::run(c),
        Command::Sim(c) => cmd::sim::run(c),
        Command::Streets(a) => cmd::streets::run(a),
        Command::Localize(a) => cmd::localize::run(*a),
        Command::Map(c) => cmd::srtree::run_map(c),
        Command::Relations(c) => cmd::srtree::run_relations(c),
        Command::Bench(c) => urbansem_bench::run(c),
        Command::Shard(c) => cmd::shard::run(c),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(err) => {
            eprintln!("error: {}", error_message(&err));
            if err.downcast_ref::<cmd::UsageError>().is_some() {
                eprintln!("(see `urbansem help` or `urbansem <command> --help`)");
                ExitCode::from(EXIT_USAGE)
            } else {
                ExitCode::from(EXIT_RUNTIME)
            }
        }
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::expect_used)]
    use super::error_message;
    use anyhow::Context;

    #[test]
    fn a_cause_already_in_its_error_message_is_printed_once() {
        let io = std::io::Error::new(std::io::ErrorKind::NotFound, "no such file");
        let osm = geodata::osm::OsmError::Io {
            path: "m.osm".into(),
            source: io,
        };
        let err = Err::<(), _>(osm).context("loading the map").unwrap_err();
        assert_eq!(
            error_message(&err),
            "loading the map: m.osm: cannot read OSM file: no such file"
        );
        // A context that ends with the path the cause starts with names it once.
        let io = std::io::Error::new(std::io::ErrorKind::NotFound, "no such file");
        let osm = geodata::osm::OsmError::Io {
            path: "m.osm".into(),
            source: io,
        };
        let err = Err::<(), _>(osm)
            .context("loading the map m.osm")
            .unwrap_err();
        assert_eq!(
            error_message(&err),
            "loading the map m.osm: cannot read OSM file: no such file"
        );
        // Not when the context merely ends with the same letters.
        let err = Err::<(), _>(std::io::Error::other("x.osm: bad"))
            .context("loading max.osm")
            .unwrap_err();
        assert_eq!(error_message(&err), "loading max.osm: x.osm: bad");
        // A cause that is not in the message above it is still printed.
        let err = Err::<(), _>(std::io::Error::other("disk full"))
            .context("writing out.json")
            .unwrap_err();
        assert_eq!(error_message(&err), "writing out.json: disk full");
    }
}
