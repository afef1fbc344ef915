//! `urbansem sim …` (skeleton: its owner fills it in this session).

use clap::Subcommand;

/// Subcommands of `urbansem sim`.
#[derive(Subcommand)]
pub enum SimCommand {}

/// Runs one `urbansem sim` subcommand.
pub fn run(command: SimCommand) -> anyhow::Result<()> {
    match command {}
}
