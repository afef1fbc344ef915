//! `urbansem sim …`: procedural cities, simulated labelled scan datasets, simulator speed.

use anyhow::Context;
use clap::{Subcommand, ValueEnum};
use geodata::osm::OsmMap;
use geosim::city::{generate_city, generate_city_with_stats, CityOptions};
use geosim::dataset::{
    write_localization, write_relations, write_streets, DatasetSummary, LocalizationOptions,
    RelationsOptions, StreetsOptions,
};
use geosim::scene::{MapErrorOptions, SceneOptions};
use geosim::sensor::SensorOptions;
use indicatif::{ProgressBar, ProgressStyle};
use std::path::{Path, PathBuf};
use std::time::Instant;

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
            std::fs::create_dir_all(&out)
                .with_context(|| format!("creating the output folder {}", out.display()))?;
            let (map, map_path) = load_or_default(map.as_deref(), &out)?;
            let tune = |mut sensor: SensorOptions| {
                if let Some(h) = h_step_deg {
                    sensor.h_step_deg = h;
                }
                if let Some(v) = v_step_deg {
                    sensor.v_step_deg = v;
                }
                if let Some(r) = range_m {
                    sensor.range_max_m = r;
                }
                sensor
            };
            let scene_with = |on_by_default: bool| SceneOptions {
                map_error: if (on_by_default && !no_map_error) || map_error {
                    MapErrorOptions::osm_like()
                } else {
                    MapErrorOptions::none()
                },
                ..SceneOptions::default()
            };
            let bar = ProgressBar::new(0);
            bar.set_style(
                ProgressStyle::with_template("{bar:30} {pos}/{len} scans [{elapsed}<{eta}]")
                    .unwrap_or_else(|_| ProgressStyle::default_bar()),
            );
            let progress = |done: usize, total: usize| {
                bar.set_length(total as u64);
                bar.set_position(done as u64);
            };
            let started = Instant::now();
            let summary: DatasetSummary = match kind {
                DatasetKind::Localization => {
                    let defaults = LocalizationOptions::for_sensor(sensor_kind);
                    let options = LocalizationOptions {
                        scans: scans.unwrap_or(defaults.scans),
                        scene: scene_with(true),
                        sensor: tune(defaults.sensor.clone()),
                        spacing_m: spacing_m.unwrap_or(defaults.spacing_m),
                        ..defaults
                    };
                    write_localization(&map, &map_path, &out, &options, seed, &progress)
                }
                DatasetKind::Streets => {
                    let defaults = StreetsOptions::default();
                    let options = StreetsOptions {
                        route_m,
                        spacing_m: spacing_m.unwrap_or(defaults.spacing_m),
                        max_scans: scans.unwrap_or(0),
                        scene: scene_with(false),
                        sensor: tune(defaults.sensor.clone()),
                        ..defaults
                    };
                    write_streets(&map, &map_path, &out, &options, seed, &progress)
                }
                DatasetKind::Relations => {
                    let defaults = RelationsOptions::default();
                    let options = RelationsOptions {
                        scenes: scans.unwrap_or(defaults.scenes),
                        train,
                        annotator_noise,
                        scene: scene_with(false),
                        sensor: tune(defaults.sensor.clone()),
                        ..defaults
                    };
                    write_relations(&map, &map_path, &out, &options, seed, &progress)
                }
            }
            .with_context(|| format!("simulating the {kind:?} dataset into {}", out.display()))?;
            bar.finish_and_clear();
            println!(
                "{}: {:?} dataset, {} scans, {} points, {:.1} M rays in {:.1} s ({:.2} M rays/s), total {:.1} s",
                out.display(),
                kind,
                summary.scans,
                summary.points,
                summary.rays as f64 / 1e6,
                summary.cast_seconds,
                summary.rays as f64 / summary.cast_seconds.max(1e-9) / 1e6,
                started.elapsed().as_secs_f64()
            );
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

/// Loads the map, or writes the embedded default city into `out` and loads that.
fn load_or_default(map: Option<&Path>, out: &Path) -> anyhow::Result<(OsmMap, String)> {
    match map {
        Some(path) => Ok((
            OsmMap::load(path).with_context(|| format!("loading the map {}", path.display()))?,
            path.display().to_string(),
        )),
        None => {
            let xml = generate_city(&CityOptions::default(), 1)
                .context("generating the embedded default city")?;
            let path = out.join("city.osm");
            geodata::fsio::write_atomic(&path, &xml)
                .with_context(|| format!("writing {}", path.display()))?;
            // Recorded relative to the dataset folder: the dataset can move, and the same
            // command writes the same dataset.json wherever OUT is.
            Ok((
                OsmMap::from_xml_str(&xml).context("parsing the embedded default city")?,
                "city.osm".to_owned(),
            ))
        }
    }
}
