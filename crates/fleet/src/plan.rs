//! The plan file (`plan.json`): the job, its map and inputs (with sizes and checksums), the
//! options, and the shards by stage.

use crate::{invalid, io_err, Result};
use localize::pipeline::LocalizeOptions;
use localize::rank::CostKind;
use localize::sensor::{SensorChoice, Vehicle};
use localize::tiles::{FileRef, Manifest};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// The plan's `format` value.
pub const PLAN_FORMAT: &str = "urbansem-shard-plan";
/// The plan version this build reads and writes.
pub const PLAN_VERSION: u32 = 1;

/// The jobs a plan can hold.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Job {
    /// Global localization of a folder of gravity-levelled scans on a tiled map.
    Localize,
    /// Street geometry of a map from one registered cloud, tile by tile (exact; see
    /// [`crate::streets`]).
    Streets,
    /// Semantic maps of labelled, registered clouds, tile by tile (see [`crate::map`]).
    Map,
}

/// The options of a localization job (the rest are the library's defaults).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct JobOptions {
    /// Candidates listed per scan.
    pub top: usize,
    /// The cost that ranks candidates (`dcm`, `forward`, `reverse`, `symmetric`).
    pub cost: String,
    /// Sensor profile (`auto` or a profile name).
    pub sensor: String,
    /// Yaw step of the search, degrees.
    pub yaw_step_deg: f64,
    /// The caps of the `minimum` rounds, as d_DCM in metres: round k searches each tile only
    /// below its cap, for the scans no earlier round found a pose for; a last round has no cap.
    #[serde(default = "default_caps")]
    pub minimum_caps_m: Vec<f64>,
    /// Levelling of tilted scans by their walls (`off` or `auto`, as `localize --level`).
    #[serde(default = "default_level")]
    pub level: String,
    /// What carries the sensor (`auto`, `car`, `free`, as `localize --vehicle`); plans
    /// written before the option read as `free`, the behaviour they were made with.
    #[serde(default = "vehicle_of_older_plans")]
    pub vehicle: String,
}

fn default_caps() -> Vec<f64> {
    localize::tiles::MINIMUM_CAPS_M.to_vec()
}

fn default_level() -> String {
    "off".into()
}

fn vehicle_of_older_plans() -> String {
    Vehicle::Free.name().into()
}

impl Default for JobOptions {
    fn default() -> Self {
        JobOptions {
            top: 5,
            cost: LocalizeOptions::default().rank_by.name().into(),
            sensor: "auto".into(),
            yaw_step_deg: LocalizeOptions::default().search.yaw_step_deg,
            minimum_caps_m: default_caps(),
            level: default_level(),
            vehicle: Vehicle::Auto.name().into(),
        }
    }
}

impl JobOptions {
    /// The localizer's options for a map of tensor grid `grid_m`.
    pub fn localize_options(&self, grid_m: f64, plan: &Path) -> Result<LocalizeOptions> {
        let mut o = LocalizeOptions::default();
        o.chamfer.grid_m = grid_m;
        o.search.yaw_step_deg = self.yaw_step_deg;
        o.rank_by = CostKind::ALL
            .into_iter()
            .find(|k| k.name() == self.cost)
            .ok_or_else(|| invalid(plan, format!("unknown cost {:?}", self.cost)))?;
        o.sensor = if self.sensor == "auto" {
            SensorChoice::Auto
        } else {
            SensorChoice::Named(
                geodata::sensors::SensorKind::ALL
                    .into_iter()
                    .find(|k| k.name() == self.sensor)
                    .ok_or_else(|| invalid(plan, format!("unknown sensor {:?}", self.sensor)))?,
            )
        };
        o.level = localize::level::options_named(&self.level)
            .map_err(|e| invalid(plan, format!("unknown level {:?}: {e}", self.level)))?;
        o.vehicle = Vehicle::from_name(&self.vehicle).ok_or_else(|| {
            invalid(
                plan,
                format!(
                    "unknown vehicle {:?}: expected auto, car or free",
                    self.vehicle
                ),
            )
        })?;
        Ok(o)
    }
}

/// A stage of a plan: its name and its shards.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Stage {
    /// `extract`, `minimum-{cap}m` (capped rounds), `minimum` (the last, uncapped) or `poses`.
    pub name: String,
    /// The ids of its shards.
    pub shards: Vec<usize>,
}

/// One shard: a batch of scans, and a tile for the tile stages.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Shard {
    /// Its id (its position in the plan).
    pub id: usize,
    /// Its stage (index into `stages`).
    pub stage: usize,
    /// Its batch of scans.
    pub batch: usize,
    /// Its scans: `[first, end)` of `inputs`.
    pub scans: [usize; 2],
    /// Its tile (position in the manifest), for the tile stages.
    pub tile: Option<usize>,
}

/// A plan (`plan.json`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Plan {
    /// Always [`PLAN_FORMAT`].
    pub format: String,
    /// Always [`PLAN_VERSION`].
    pub version: u32,
    /// The job.
    pub job: Job,
    /// The tiled map's manifest (absolute path) with its size and checksum.
    pub map: FileRef,
    /// The inputs (absolute paths), in file-name order.
    pub inputs: Vec<FileRef>,
    /// The job's options.
    pub options: JobOptions,
    /// Scans per batch.
    pub batch_size: usize,
    /// The folder of shard results (absolute path).
    pub out: String,
    /// The stages, in order.
    pub stages: Vec<Stage>,
    /// Every shard.
    pub shards: Vec<Shard>,
    /// The street model (streets job).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub model: Option<FileRef>,
    /// The driving-area model whose estimates centre a with-sidewalk model's priors (streets
    /// job; its tiles are the first stage).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub driving_model: Option<FileRef>,
    /// Side of the street tiles, metres (streets job).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub tile_m: Option<f64>,
    /// The street tiles with their owned segments, one per shard (streets job).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub street_tiles: Vec<streets::tiles::StreetTile>,
    /// The map-building options (map job).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub map_job: Option<MapJob>,
    /// The map tiles, one per shard (map job).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub map_tiles: Vec<MapTile>,
}

/// The options of a map-building job ([`crate::map`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct MapJob {
    /// Cell size of the maps, metres (the tile side, the plan's `tile_m`, is a whole number
    /// of cells).
    pub resolution_m: f64,
}

/// One tile of a map-building plan: its core and window as half-open cell-key ranges
/// `[x0, y0, x1, y1]`, its owned objects and the inputs touching its window.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct MapTile {
    /// The tile's grid position (core = `[x, x + 1) × [y, y + 1)` tile sides).
    pub grid: [i32; 2],
    /// The core's cell keys.
    pub core: [i32; 4],
    /// The cell keys the shard builds: the core and the boxes of its owned objects.
    pub window: [i32; 4],
    /// The instance ids of the objects the tile owns.
    pub objects: Vec<u32>,
    /// The inputs (positions in the plan) with a point in the window.
    pub inputs: Vec<usize>,
}

/// Cloud file extensions a localization job takes from its input folder.
const CLOUD_EXTENSIONS: [&str; 7] = ["ply", "pcd", "las", "laz", "bin", "xyz", "txt"];

/// The files of folder `dir` whose extension is one of `extensions` (any case), sorted by
/// name; an error naming `what` when there is none.
pub(crate) fn cloud_files(dir: &Path, extensions: &[&str], what: &str) -> Result<Vec<PathBuf>> {
    let mut files: Vec<PathBuf> = std::fs::read_dir(dir)
        .map_err(|e| io_err(dir, e))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| {
            p.is_file()
                && p.extension()
                    .and_then(|e| e.to_str())
                    .is_some_and(|e| extensions.contains(&e.to_ascii_lowercase().as_str()))
        })
        .collect();
    files.sort();
    if files.is_empty() {
        return Err(invalid(
            dir,
            format!("no {what} ({}) in the folder", extensions.join(", ")),
        ));
    }
    Ok(files)
}

/// The stages `names` of a job, one after another, each with a shard per tile over the
/// inputs `scans` (shard ids run on across the stages).
pub(crate) fn tile_stages(
    names: &[&str],
    tiles: usize,
    scans: [usize; 2],
) -> (Vec<Stage>, Vec<Shard>) {
    let mut stages = Vec::new();
    let mut shards = Vec::new();
    for (stage, name) in names.iter().enumerate() {
        let first = shards.len();
        shards.extend((0..tiles).map(|k| Shard {
            id: first + k,
            stage,
            batch: 0,
            scans,
            tile: Some(k),
        }));
        stages.push(Stage {
            name: (*name).into(),
            shards: (first..first + tiles).collect(),
        });
    }
    (stages, shards)
}

pub(crate) fn absolute(path: &Path) -> Result<PathBuf> {
    std::fs::canonicalize(path).map_err(|e| io_err(path, e))
}

/// Plans a localization job: the scans of `inputs` (every cloud file, by name) on the tiled
/// map `manifest`, `batch_size` scans per shard, results into `out`.
pub fn plan_localize(
    manifest: &Path,
    inputs: &Path,
    out: &Path,
    batch_size: usize,
    options: JobOptions,
) -> Result<Plan> {
    if !localize::tiles::is_manifest(manifest) {
        return Err(invalid(
            manifest,
            "a localization plan needs a tiled map: write one with `urbansem localize index --map M --tile-m 1000 --out DIR` and pass DIR/manifest.json".into(),
        ));
    }
    let caps = &options.minimum_caps_m;
    if caps.iter().any(|d| !(d.is_finite() && *d > 0.0)) || caps.windows(2).any(|w| w[0] >= w[1]) {
        return Err(invalid(
            manifest,
            format!("minimum caps {caps:?}: expected increasing positive d_DCM values in metres"),
        ));
    }
    let m = Manifest::read(manifest)?;
    let manifest = absolute(manifest)?;
    let files = cloud_files(inputs, &CLOUD_EXTENSIONS, "scan files")?;
    let batch_size = batch_size.max(1);
    let inputs = files
        .iter()
        .map(|p| {
            let abs = absolute(p)?;
            Ok(FileRef::of(&abs, &abs.to_string_lossy())?)
        })
        .collect::<Result<Vec<_>>>()?;
    std::fs::create_dir_all(out).map_err(|e| io_err(out, e))?;
    let out_abs = absolute(out)?;
    let batches = inputs.len().div_ceil(batch_size);
    let mut shards = Vec::new();
    let mut stages = Vec::new();
    let mut names = vec!["extract".to_owned()];
    for d in &options.minimum_caps_m {
        names.push(format!("minimum-{d}m"));
    }
    names.push("minimum".to_owned());
    names.push("poses".to_owned());
    for (stage, name) in names.into_iter().enumerate() {
        let mut ids = Vec::new();
        for batch in 0..batches {
            let scans = [
                batch * batch_size,
                ((batch + 1) * batch_size).min(inputs.len()),
            ];
            let tiles: Vec<Option<usize>> = if stage == 0 {
                vec![None]
            } else {
                (0..m.tiles.len()).map(Some).collect()
            };
            for tile in tiles {
                ids.push(shards.len());
                shards.push(Shard {
                    id: shards.len(),
                    stage,
                    batch,
                    scans,
                    tile,
                });
            }
        }
        stages.push(Stage { name, shards: ids });
    }
    Ok(Plan {
        format: PLAN_FORMAT.into(),
        version: PLAN_VERSION,
        job: Job::Localize,
        map: FileRef::of(&manifest, &manifest.to_string_lossy())?,
        inputs,
        options,
        batch_size,
        out: out_abs.to_string_lossy().into_owned(),
        stages,
        shards,
        model: None,
        driving_model: None,
        tile_m: None,
        street_tiles: Vec::new(),
        map_job: None,
        map_tiles: Vec::new(),
    })
}

impl Plan {
    /// Writes the plan (atomically).
    pub fn write(&self, path: &Path) -> Result<()> {
        let json = serde_json::to_vec_pretty(self).map_err(|e| io_err(path, e))?;
        geodata::fsio::write_atomic(path, json).map_err(|e| io_err(path, e))
    }

    /// Reads and checks a plan; returns it with the CRC-32 of its bytes.
    pub fn read(path: &Path) -> Result<(Plan, u32)> {
        let bytes = std::fs::read(path).map_err(|e| io_err(path, e))?;
        let plan: Plan = serde_json::from_slice(&bytes).map_err(|e| {
            invalid(
                path,
                format!(
                    "not a shard plan (line {}, column {}: {e}); write one with `urbansem shard plan`",
                    e.line(),
                    e.column()
                ),
            )
        })?;
        if plan.format != PLAN_FORMAT || plan.version != PLAN_VERSION {
            return Err(invalid(
                path,
                format!(
                    "format {:?} version {}; this build reads {PLAN_FORMAT:?} version {PLAN_VERSION}",
                    plan.format, plan.version
                ),
            ));
        }
        let n = plan.inputs.len();
        let ok = plan.shards.iter().enumerate().all(|(i, s)| {
            s.id == i && s.stage < plan.stages.len() && s.scans[0] <= s.scans[1] && s.scans[1] <= n
        });
        if !ok {
            return Err(invalid(
                path,
                "a shard's id, stage or scans are out of range".into(),
            ));
        }
        Ok((plan, crc32fast::hash(&bytes)))
    }

    /// The shard with id `id`.
    pub fn shard(&self, id: usize, path: &Path) -> Result<&Shard> {
        self.shards.get(id).ok_or_else(|| {
            invalid(
                path,
                format!(
                    "no shard {id}: the plan has {} (0–{})",
                    self.shards.len(),
                    self.shards.len().saturating_sub(1)
                ),
            )
        })
    }

    /// The result file of shard `id`.
    pub fn result_path(&self, id: usize) -> PathBuf {
        Path::new(&self.out).join(format!("shard-{id:06}.jsonl"))
    }

    /// The completion record of shard `id` (written after its result).
    pub fn done_path(&self, id: usize) -> PathBuf {
        Path::new(&self.out).join(format!("shard-{id:06}.done.json"))
    }

    /// The shards of stage `stage` for batch `batch`.
    pub fn stage_shards(&self, stage: usize, batch: usize) -> Vec<usize> {
        self.shards
            .iter()
            .filter(|s| s.stage == stage && s.batch == batch)
            .map(|s| s.id)
            .collect()
    }

    /// Shards per stage, in order.
    pub fn waves(&self) -> Vec<Vec<usize>> {
        self.stages.iter().map(|s| s.shards.clone()).collect()
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::expect_used)]
    use super::*;

    #[test]
    fn the_level_option_reaches_the_localizer_and_an_unknown_one_is_named() {
        let plan = Path::new("plan.json");
        let off = JobOptions::default().localize_options(0.5, plan).unwrap();
        assert_eq!(off.level, None);
        let auto = JobOptions {
            level: "auto".into(),
            ..JobOptions::default()
        };
        assert_eq!(
            auto.localize_options(0.5, plan).unwrap().level,
            Some(localize::level::LevelOptions::default())
        );
        let bad = JobOptions {
            level: "tilted".into(),
            ..JobOptions::default()
        };
        let err = bad.localize_options(0.5, plan).unwrap_err().to_string();
        assert!(err.contains("plan.json") && err.contains("tilted"), "{err}");
        // Plans written before the option read as `off`.
        let mut v = serde_json::to_value(JobOptions::default()).unwrap();
        v.as_object_mut().unwrap().remove("level");
        let back: JobOptions = serde_json::from_value(v).unwrap();
        assert_eq!(back.level, "off");
    }

    #[test]
    fn the_vehicle_option_reaches_the_localizer_and_older_plans_stay_free() {
        let plan = Path::new("plan.json");
        let o = JobOptions::default().localize_options(0.5, plan).unwrap();
        assert_eq!(o.vehicle, Vehicle::Auto);
        let car = JobOptions {
            vehicle: "car".into(),
            ..JobOptions::default()
        };
        assert_eq!(
            car.localize_options(0.5, plan).unwrap().vehicle,
            Vehicle::Car
        );
        let bad = JobOptions {
            vehicle: "bicycle".into(),
            ..JobOptions::default()
        };
        let err = bad.localize_options(0.5, plan).unwrap_err().to_string();
        assert!(
            err.contains("plan.json") && err.contains("bicycle"),
            "{err}"
        );
        let mut v = serde_json::to_value(JobOptions::default()).unwrap();
        v.as_object_mut().unwrap().remove("vehicle");
        let back: JobOptions = serde_json::from_value(v).unwrap();
        assert_eq!(back.vehicle, "free");
    }
}
