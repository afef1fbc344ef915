//! `urbansem osm …` (skeleton: its owner fills it in this session).

use clap::Subcommand;

/// Subcommands of `urbansem osm`.
#[derive(Subcommand)]
pub enum OsmCommand {}

/// Runs one `urbansem osm` subcommand.
pub fn run(command: OsmCommand) -> anyhow::Result<()> {
    match command {}
}
