//! `sim dataset` as one library call: which dataset, from which map, with which sensor and
//! map-error overrides, written into a folder ([`write_dataset`]).

use crate::city::{generate_city, CityError, CityOptions};
use crate::dataset::{
    write_localization, write_relations, write_streets, DatasetSummary, LocalizationOptions,
    RelationsOptions, StreetsOptions,
};
use crate::scene::{MapErrorOptions, SceneOptions};
use crate::sensor::SensorOptions;
use crate::SimError;
use geodata::osm::{OsmError, OsmMap};
use geodata::sensors::SensorKind;
use serde::Serialize;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// Which dataset [`write_dataset`] writes.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
pub enum DatasetKind {
    /// Scans at random sidewalk poses (or along a drive) with their true poses (truth.json).
    Localization,
    /// Scans along a route registered into one cloud, true offset and width per segment.
    Streets,
    /// Viewpoint scenes with objects, true boxes and true On/LeftOf/Behind relations.
    Relations,
}

/// A dataset to simulate: the kind, the map, the folder and the overrides of the kind's
/// default options (`None`: the kind's default).
#[derive(Clone, Debug)]
pub struct DatasetJob {
    /// Kind of dataset.
    pub kind: DatasetKind,
    /// OSM map; `None`: the embedded default city, written into `out` as `city.osm`.
    pub map: Option<PathBuf>,
    /// Output folder (created).
    pub out: PathBuf,
    /// Seed of every random step.
    pub seed: u64,
    /// Scans (localization), scenes (relations) or the largest number of scans (streets).
    pub scans: Option<usize>,
    /// The OSM map-error model on or off (default: on for localization, off otherwise).
    pub map_error: Option<bool>,
    /// Azimuth step of the scanner, degrees.
    pub h_step_deg: Option<f64>,
    /// Elevation step of the scanner, degrees.
    pub v_step_deg: Option<f64>,
    /// Range limit of the scanner, metres.
    pub range_m: Option<f64>,
    /// Streets: length of the route, metres.
    pub route_m: f64,
    /// Distance between scans along a route or drive, metres.
    pub spacing_m: Option<f64>,
    /// Localization: the sensor model (car-mounted models scan along a drive).
    pub sensor: SensorKind,
    /// Relations: rate at which the annotator flips a relation label.
    pub annotator_noise: f64,
    /// Relations: number of training scenes (the first ones).
    pub train: usize,
}

/// What [`write_dataset`] wrote.
#[derive(Clone, Debug, Serialize)]
pub struct DatasetReport {
    /// Output folder.
    pub out: PathBuf,
    /// Kind of dataset.
    pub kind: DatasetKind,
    /// Scans, rays and points.
    pub summary: DatasetSummary,
    /// Wall time of the whole job, seconds.
    pub seconds: f64,
}

impl DatasetReport {
    /// One line: folder, kind, scans, points, rays and speed.
    pub fn text(&self) -> String {
        let s = &self.summary;
        format!(
            "{}: {:?} dataset, {} scans, {} points, {:.1} M rays in {:.1} s ({:.2} M rays/s), total {:.1} s",
            self.out.display(),
            self.kind,
            s.scans,
            s.points,
            s.rays as f64 / 1e6,
            s.cast_seconds,
            s.rays as f64 / s.cast_seconds.max(1e-9) / 1e6,
            self.seconds
        )
    }
}

/// Why a dataset job failed.
#[derive(Debug, thiserror::Error)]
pub enum JobError {
    /// A car-mounted sensor was asked for a dataset other than localization.
    #[error("car-mounted sensors are simulated for localization datasets only")]
    CarSensorNeedsLocalization,
    /// The output folder could not be created.
    #[error("creating the output folder {}", path.display())]
    CreateFolder {
        /// The folder.
        path: PathBuf,
        /// Cause.
        #[source]
        source: std::io::Error,
    },
    /// The map could not be loaded.
    #[error("loading the map {}", path.display())]
    Map {
        /// The map file.
        path: PathBuf,
        /// Cause.
        #[source]
        source: Box<OsmError>,
    },
    /// The embedded default city could not be generated or parsed.
    #[error("generating the embedded default city")]
    DefaultCity(#[source] Box<dyn std::error::Error + Send + Sync>),
    /// The city could not be written into the folder.
    #[error("writing {}", path.display())]
    WriteCity {
        /// The file.
        path: PathBuf,
        /// Cause.
        #[source]
        source: std::io::Error,
    },
    /// Simulating or writing the dataset failed.
    #[error("simulating the {kind:?} dataset into {}", out.display())]
    Simulate {
        /// Kind of dataset.
        kind: DatasetKind,
        /// Output folder.
        out: PathBuf,
        /// Cause.
        #[source]
        source: SimError,
    },
}

impl From<CityError> for JobError {
    fn from(e: CityError) -> Self {
        JobError::DefaultCity(Box::new(e))
    }
}

/// Simulates the dataset `job` asks for into `job.out`; `progress(done, total)` after each scan.
pub fn write_dataset(
    job: &DatasetJob,
    progress: &(dyn Fn(usize, usize) + Sync),
) -> Result<DatasetReport, JobError> {
    if job.sensor.on_car() && job.kind != DatasetKind::Localization {
        return Err(JobError::CarSensorNeedsLocalization);
    }
    let out = &job.out;
    std::fs::create_dir_all(out).map_err(|source| JobError::CreateFolder {
        path: out.clone(),
        source,
    })?;
    let (map, map_path) = load_or_default(job.map.as_deref(), out)?;
    let tune = |mut sensor: SensorOptions| {
        if let Some(h) = job.h_step_deg {
            sensor.h_step_deg = h;
        }
        if let Some(v) = job.v_step_deg {
            sensor.v_step_deg = v;
        }
        if let Some(r) = job.range_m {
            sensor.range_max_m = r;
        }
        sensor
    };
    let scene_with = |on_by_default: bool| SceneOptions {
        map_error: if job.map_error.unwrap_or(on_by_default) {
            MapErrorOptions::osm_like()
        } else {
            MapErrorOptions::none()
        },
        ..SceneOptions::default()
    };
    let started = Instant::now();
    let (seed, spacing_m) = (job.seed, job.spacing_m);
    let summary = match job.kind {
        DatasetKind::Localization => {
            let defaults = LocalizationOptions::for_sensor(job.sensor);
            let options = LocalizationOptions {
                scans: job.scans.unwrap_or(defaults.scans),
                scene: scene_with(true),
                sensor: tune(defaults.sensor.clone()),
                spacing_m: spacing_m.unwrap_or(defaults.spacing_m),
                ..defaults
            };
            write_localization(&map, &map_path, out, &options, seed, progress)
        }
        DatasetKind::Streets => {
            let defaults = StreetsOptions::default();
            let options = StreetsOptions {
                route_m: job.route_m,
                spacing_m: spacing_m.unwrap_or(defaults.spacing_m),
                max_scans: job.scans.unwrap_or(0),
                scene: scene_with(false),
                sensor: tune(defaults.sensor.clone()),
                ..defaults
            };
            write_streets(&map, &map_path, out, &options, seed, progress)
        }
        DatasetKind::Relations => {
            let defaults = RelationsOptions::default();
            let options = RelationsOptions {
                scenes: job.scans.unwrap_or(defaults.scenes),
                train: job.train,
                annotator_noise: job.annotator_noise,
                scene: scene_with(false),
                sensor: tune(defaults.sensor.clone()),
                ..defaults
            };
            write_relations(&map, &map_path, out, &options, seed, progress)
        }
    }
    .map_err(|source| JobError::Simulate {
        kind: job.kind,
        out: out.clone(),
        source,
    })?;
    Ok(DatasetReport {
        out: out.clone(),
        kind: job.kind,
        summary,
        seconds: started.elapsed().as_secs_f64(),
    })
}

/// Loads the map, or writes the embedded default city into `out` and loads that; returns the
/// map and the path recorded in the dataset.
fn load_or_default(map: Option<&Path>, out: &Path) -> Result<(OsmMap, String), JobError> {
    match map {
        Some(path) => Ok((
            OsmMap::load(path).map_err(|source| JobError::Map {
                path: path.to_path_buf(),
                source: Box::new(source),
            })?,
            path.display().to_string(),
        )),
        None => {
            let xml = generate_city(&CityOptions::default(), 1)?;
            let path = out.join("city.osm");
            geodata::fsio::write_atomic(&path, &xml)
                .map_err(|source| JobError::WriteCity { path, source })?;
            // Recorded relative to the dataset folder: the dataset can move, and the same
            // command writes the same dataset.json wherever OUT is.
            let map = OsmMap::from_xml_str(&xml).map_err(|e| JobError::DefaultCity(Box::new(e)))?;
            Ok((map, "city.osm".to_owned()))
        }
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::expect_used)]
    use super::*;

    fn job(kind: DatasetKind, out: &Path) -> DatasetJob {
        DatasetJob {
            kind,
            map: None,
            out: out.to_path_buf(),
            seed: 3,
            scans: Some(1),
            map_error: None,
            h_step_deg: Some(4.0),
            v_step_deg: Some(4.0),
            range_m: None,
            route_m: 100.0,
            spacing_m: None,
            sensor: SensorKind::Terrestrial,
            annotator_noise: 0.0,
            train: 1,
        }
    }

    #[test]
    fn bad_jobs_are_clear_errors() {
        let dir = tempfile::tempdir().unwrap();
        let mut j = job(DatasetKind::Streets, dir.path());
        j.sensor = SensorKind::Hdl64;
        let err = write_dataset(&j, &|_, _| {}).unwrap_err();
        assert!(matches!(err, JobError::CarSensorNeedsLocalization), "{err}");
        let mut j = job(DatasetKind::Localization, dir.path());
        j.map = Some(dir.path().join("missing.osm"));
        let err = write_dataset(&j, &|_, _| {}).unwrap_err();
        assert!(err.to_string().contains("missing.osm"), "{err}");
    }

    #[test]
    fn default_city_dataset_is_written_with_its_map() {
        let dir = tempfile::tempdir().unwrap();
        let report =
            write_dataset(&job(DatasetKind::Localization, dir.path()), &|_, _| {}).unwrap();
        assert_eq!(report.summary.scans, 1);
        assert!(report.summary.points > 0);
        assert!(dir.path().join("city.osm").is_file());
        assert!(report.text().contains("Localization dataset, 1 scans"));
    }
}
