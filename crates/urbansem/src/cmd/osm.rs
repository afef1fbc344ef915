//! `urbansem osm …`: statistics of OpenStreetMap files.

use anyhow::Context;
use clap::Subcommand;
use geodata::osm::info::OsmInfo;
use geodata::osm::OsmMap;
use std::path::PathBuf;
use std::time::Instant;

/// Subcommands of `urbansem osm`.
#[derive(Subcommand)]
pub enum OsmCommand {
    /// Parse an .osm / .osm.pbf file and print its buildings, highways and street network.
    Info {
        /// The map file (.osm XML or .osm.pbf).
        map: PathBuf,
        /// Print one JSON object instead of a readable summary.
        #[arg(long)]
        json: bool,
    },
}

/// Runs one `urbansem osm` subcommand.
pub fn run(command: OsmCommand) -> anyhow::Result<()> {
    match command {
        OsmCommand::Info { map, json } => info(&map, json),
    }
}

fn info(path: &PathBuf, json: bool) -> anyhow::Result<()> {
    let start = Instant::now();
    let map = OsmMap::load(path).context("loading the map")?;
    let info = OsmInfo::new(path, &map, start.elapsed().as_secs_f64());
    if json {
        super::print_json(&info)?;
    } else {
        print!("{}", info.text());
    }
    // The process ends here: freeing every outline and segment one by one would only cost time.
    std::mem::forget(map);
    Ok(())
}
