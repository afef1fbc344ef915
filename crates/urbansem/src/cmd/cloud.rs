//! `urbansem cloud …` (skeleton: its owner fills it in this session).

use clap::Subcommand;

/// Subcommands of `urbansem cloud`.
#[derive(Subcommand)]
pub enum CloudCommand {}

/// Runs one `urbansem cloud` subcommand.
pub fn run(command: CloudCommand) -> anyhow::Result<()> {
    match command {}
}
