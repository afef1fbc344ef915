//! `urbansem pbo …` (skeleton: its owner fills it in this session).

use clap::Subcommand;

/// Subcommands of `urbansem pbo`.
#[derive(Subcommand)]
pub enum PboCommand {}

/// Runs one `urbansem pbo` subcommand.
pub fn run(command: PboCommand) -> anyhow::Result<()> {
    match command {}
}
