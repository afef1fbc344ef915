//! `urbansem demo`: every capability on the embedded default city; the stages and the report
//! are the `urbansem-demo` crate.

use clap::Args;
use indicatif::{ProgressBar, ProgressStyle};
use std::path::PathBuf;

/// Options of `urbansem demo`.
#[derive(Args)]
pub struct DemoArgs {
    /// Output folder for summary.json and index.html.
    #[arg(long, default_value = "demo-out")]
    pub out: PathBuf,
    /// Seed of every random step (same seed, same report numbers).
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
}

/// Runs the demo with a progress bar.
pub fn run(args: DemoArgs) -> anyhow::Result<()> {
    let bar = ProgressBar::new(0);
    bar.set_style(
        ProgressStyle::with_template("{bar:30} {pos}/{len} {msg} [{elapsed}]")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    let options = urbansem_demo::DemoArgs {
        out: args.out,
        seed: args.seed,
    };
    let outcome = urbansem_demo::run(&options, &|done, total, name| {
        bar.set_length(total as u64);
        bar.set_position(done as u64);
        bar.set_message(name.to_owned());
    })?;
    bar.finish_and_clear();
    println!(
        "demo finished in {:.1} s: {} and {}",
        outcome.seconds,
        outcome.summary_path.display(),
        outcome.html_path.display()
    );
    Ok(())
}
