//! `urbansem sim …`: procedural cities (and, later, simulated labelled scans).

use anyhow::Context;
use clap::Subcommand;
use geodata::city::{generate_city_with_stats, CityOptions};
use std::path::PathBuf;

/// Subcommands of `urbansem sim`.
#[derive(Subcommand)]
pub enum SimCommand {
    /// Write a seeded procedural city as OSM XML (byte-identical for a seed).
    City {
        /// Random seed.
        #[arg(long, default_value_t = 1)]
        seed: u64,
        /// Output .osm file.
        #[arg(long)]
        out: PathBuf,
        /// Side length of the square city in metres.
        #[arg(long, default_value_t = 1000.0)]
        size_m: f64,
    },
}

/// Runs one `urbansem sim` subcommand.
pub fn run(command: SimCommand) -> anyhow::Result<()> {
    match command {
        SimCommand::City { seed, out, size_m } => {
            let options = CityOptions {
                size_m,
                ..CityOptions::default()
            };
            let (xml, stats) =
                generate_city_with_stats(&options, seed).context("generating the city")?;
            std::fs::write(&out, xml).with_context(|| format!("writing {}", out.display()))?;
            println!(
                "{}: {} nodes, {} highway ways ({} segments), {} building ways + {} courtyard multipolygons",
                out.display(),
                stats.nodes,
                stats.highway_ways,
                stats.segments,
                stats.building_ways,
                stats.building_relations
            );
            Ok(())
        }
    }
}
