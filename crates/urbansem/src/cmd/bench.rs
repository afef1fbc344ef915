//! `urbansem bench …` (skeleton: its owner fills it in this session).

use clap::Subcommand;

/// Subcommands of `urbansem bench`.
#[derive(Subcommand)]
pub enum BenchCommand {}

/// Runs one `urbansem bench` subcommand.
pub fn run(command: BenchCommand) -> anyhow::Result<()> {
    match command {}
}
