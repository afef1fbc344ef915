//! `urbansem sim …`: procedural cities, simulated labelled scan datasets, simulator speed.

use anyhow::Context;
use clap::{Subcommand, ValueEnum};
use geosim::city::{generate_city_with_stats, CityOptions};
use geosim::job::{write_dataset, DatasetJob};
use indicatif::{ProgressBar, ProgressStyle};
use std::path::PathBuf;

/// Which dataset `urbansem sim dataset` writes.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum DatasetKind {
    /// Scans at random sidewalk poses with their true poses (truth.json).
    Localization,
    /// Scans along a route registered into one cloud, true offset and width per segment.
    Streets,
    /// Viewpoint scenes with objects, true boxes and true On/LeftOf/Behind relations.
    Relations,
}

impl From<DatasetKind> for geosim::job::DatasetKind {
    fn from(k: DatasetKind) -> Self {
        match k {
            DatasetKind::Localization => Self::Localization,
            DatasetKind::Streets => Self::Streets,
            DatasetKind::Relations => Self::Relations,
        }
    }
}

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
    /// Simulate a labelled dataset with exact ground truth (PLY + JSON) from an OSM map.
    Dataset {
        /// Kind of dataset.
        #[arg(long, value_enum)]
        kind: DatasetKind,
        /// OSM map (.osm or .osm.pbf); default: the embedded default city, written into OUT.
        #[arg(long)]
        map: Option<PathBuf>,
        /// Output folder.
        #[arg(long)]
        out: PathBuf,
        /// Seed of every random step (same seed, byte-identical dataset).
        #[arg(long, default_value_t = 1)]
        seed: u64,
        /// Number of scans (localization) or scenes (relations); streets: largest number of scans.
        #[arg(long)]
        scans: Option<usize>,
        /// Turn the OSM map-error model off (localization has it on by default).
        #[arg(long)]
        no_map_error: bool,
        /// Turn the OSM map-error model on (streets and relations have it off by default).
        #[arg(long, conflicts_with = "no_map_error")]
        map_error: bool,
        /// Azimuth step of the scanner, degrees.
        #[arg(long)]
        h_step_deg: Option<f64>,
        /// Elevation step of the scanner, degrees.
        #[arg(long)]
        v_step_deg: Option<f64>,
        /// Range limit of the scanner, metres.
        #[arg(long)]
        range_m: Option<f64>,
        /// Streets: length of the route, metres.
        #[arg(long, default_value_t = 2500.0)]
        route_m: f64,
        /// Distance between scans along the route, metres (streets: 20; localization with a
        /// car-mounted sensor: 10).
        #[arg(long)]
        spacing_m: Option<f64>,
        /// Localization: the sensor model simulated (beams, azimuth step, range, mount);
        /// car-mounted models scan from the road along a drive, `terrestrial` from sidewalks.
        #[arg(long, default_value = "terrestrial", value_parser = ["terrestrial", "hdl64", "vlp16", "os1-64", "os1-128"])]
        sensor: String,
        /// Relations: rate at which the annotator flips a relation label.
        #[arg(long, default_value_t = 0.0)]
        annotator_noise: f64,
        /// Relations: number of training scenes (the first ones).
        #[arg(long, default_value_t = 48)]
        train: usize,
    },
    /// Measure the simulator's ray-casting speed (rays per second) on a map.
    Bench {
        /// OSM map; default: the embedded default city.
        #[arg(long)]
        map: Option<PathBuf>,
        /// Number of scans to time.
        #[arg(long, default_value_t = 8)]
        scans: usize,
        /// Seed.
        #[arg(long, default_value_t = 1)]
        seed: u64,
        /// Print one JSON object.
        #[arg(long)]
        json: bool,
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
            geodata::fsio::write_atomic(&out, xml)
                .with_context(|| format!("writing {}", out.display()))?;
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
        SimCommand::Dataset {
            kind,
            map,
            out,
            seed,
            scans,
            no_map_error,
            map_error,
            h_step_deg,
            v_step_deg,
            range_m,
            route_m,
            spacing_m,
            sensor,
            annotator_noise,
            train,
        } => {
            let Some(sensor_kind) = geodata::sensors::SensorKind::from_name(&sensor) else {
                super::usage!("--sensor {sensor}: unknown sensor model");
            };
            if sensor_kind.on_car() && kind != DatasetKind::Localization {
                super::usage!(
                    "--sensor {sensor}: car-mounted sensors are simulated for localization datasets only"
                );
            }
            let job = DatasetJob {
                kind: kind.into(),
                map,
                out,
                seed,
                scans,
                map_error: (no_map_error || map_error).then_some(map_error),
                h_step_deg,
                v_step_deg,
                range_m,
                route_m,
                spacing_m,
                sensor: sensor_kind,
                annotator_noise,
                train,
            };
            let bar = ProgressBar::new(0);
            bar.set_style(
                ProgressStyle::with_template("{bar:30} {pos}/{len} scans [{elapsed}<{eta}]")
                    .unwrap_or_else(|_| ProgressStyle::default_bar()),
            );
            let report = write_dataset(&job, &|done, total| {
                bar.set_length(total as u64);
                bar.set_position(done as u64);
            })?;
            bar.finish_and_clear();
            println!("{}", report.text());
            Ok(())
        }
        SimCommand::Bench {
            map,
            scans,
            seed,
            json,
        } => urbansem_bench::sim::bench_sim(map.as_deref(), scans, seed, json),
    }
}
