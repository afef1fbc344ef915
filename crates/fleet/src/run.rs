//! One shard, run anywhere: reads the plan, the inputs and earlier stages' results, writes
//! its result (JSON lines, no timings: byte-identical on every run) and then a completion
//! record with the result's size and CRC-32.
//!
//! **Idempotent.** A shard whose completion record matches the plan (CRC-32 of the plan
//! file) and whose result matches the record's size and CRC-32 is not run again. Both files
//! are written atomically (temporary file, then rename), the record after the result, so a
//! shard killed at any point leaves either no record (it runs again on retry, replacing any
//! result) or a complete pair; the merge reads only complete pairs and names any shard
//! without one.

use crate::plan::{Job, Plan};
use crate::{invalid, io_err, FleetError, Result};
use localize::candidates::{limit_of, Cap};
use localize::pipeline::{scan_segments, LocalizeOptions, ScanSegments};
use localize::sensor::{SensorGeometry, SensorReport};
use localize::tiles::{round_cap, search_tile, LoadedTile, Manifest, TileSearch};
use localize::Segment;
use rayon::prelude::*;
use serde::de::DeserializeOwned;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};
use std::time::Instant;

/// What one shard run did.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ShardOutcome {
    /// The shard's id.
    pub shard: usize,
    /// Its stage's name.
    pub stage: String,
    /// True when its result was already complete (nothing was run).
    pub skipped: bool,
    /// Records (lines) in its result.
    pub records: usize,
    /// Its result file.
    pub result: PathBuf,
    /// The result's size, bytes.
    pub bytes: u64,
    /// The result's CRC-32.
    pub crc32: u32,
    /// Seconds of the run.
    pub seconds: f64,
}

/// The completion record of a shard.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Done {
    /// CRC-32 of the plan file the shard ran for.
    pub plan_crc32: u32,
    /// The shard.
    pub shard: usize,
    /// Records in the result.
    pub records: usize,
    /// Size of the result, bytes.
    pub bytes: u64,
    /// CRC-32 of the result.
    pub crc32: u32,
}

/// The sensor a scan was processed as, in a result file.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct SensorRecord {
    /// Profile name.
    pub profile: usize,
    /// Whether it was detected from the scan.
    pub detected: bool,
    /// Mount height, metres.
    pub mount_height_m: f64,
    /// Lowest and highest beam elevation, degrees.
    pub vfov_deg: [f64; 2],
    /// Beams.
    pub beams: usize,
}

/// Stage `extract`: one scan's wall segments.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ExtractRecord {
    /// The scan's position among the plan's inputs.
    pub scan: usize,
    /// Its file name.
    pub name: String,
    /// Points read.
    pub points: usize,
    /// Wall segments `[ax, ay, bx, by]`, sensor frame.
    pub segments: Vec<[f64; 4]>,
    /// The sensor it was processed as.
    pub sensor: Option<SensorRecord>,
    /// Wall clearance, metres.
    pub clearance_m: f64,
    /// The scan's tilt from its walls and whether it was levelled (absent: off).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub level: Option<localize::level::Levelling>,
    /// Vertical-surface cells.
    pub vertical_cells: usize,
    /// Shortest segment kept, metres.
    pub min_length_m: f64,
}

impl ExtractRecord {
    /// The segments as the localizer takes them.
    pub fn segments(&self) -> Vec<Segment> {
        self.segments
            .iter()
            .map(|v| Segment::new([v[0], v[1]], [v[2], v[3]]))
            .collect()
    }

    /// The sensor the scan was processed as, as the library reports it.
    pub fn sensor_report(&self) -> Option<SensorReport> {
        self.sensor.and_then(|s| {
            geodata::sensors::SensorKind::ALL
                .get(s.profile)
                .map(|k| SensorReport {
                    profile: k.name(),
                    detected: s.detected,
                    geometry: SensorGeometry {
                        mount_height_m: s.mount_height_m,
                        vfov_deg: s.vfov_deg,
                        beams: s.beams,
                    },
                })
        })
    }

    /// Whether the scan's poses must head along a street under `options`' vehicle.
    pub fn along_streets(&self, options: &LocalizeOptions) -> bool {
        options.vehicle.along_streets(self.sensor_report().as_ref())
    }

    /// The extraction as the library reports it.
    pub fn scan_segments(&self) -> ScanSegments {
        ScanSegments {
            segments: self.segments(),
            sensor: self.sensor_report(),
            clearance_m: self.clearance_m,
            levelling: self.level,
            vertical_cells: self.vertical_cells,
            min_length_m: self.min_length_m,
            surfaces_s: 0.0,
            segments_s: 0.0,
        }
    }
}

/// Stage `minimum`: one scan's least cost in one tile's core.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct MinimumRecord {
    /// The scan.
    pub scan: usize,
    /// The tile.
    pub tile: usize,
    /// Its least cost (none: the scan has no segments or the tile no feasible pose).
    pub minimum: Option<u64>,
}

/// Stage `poses`: one scan's poses in one tile within the factor of its least cost.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PosesRecord {
    /// The scan.
    pub scan: usize,
    /// The tile's search.
    pub search: TileSearch,
}

/// Whether shard `id` has a complete result for this plan (`plan_crc32`).
pub fn is_done(plan: &Plan, plan_crc32: u32, id: usize) -> Option<Done> {
    let bytes = std::fs::read(plan.done_path(id)).ok()?;
    let done: Done = serde_json::from_slice(&bytes).ok()?;
    if done.plan_crc32 != plan_crc32 || done.shard != id {
        return None;
    }
    let result = std::fs::read(plan.result_path(id)).ok()?;
    (result.len() as u64 == done.bytes && crc32fast::hash(&result) == done.crc32).then_some(done)
}

/// The records of finished shards `ids`, in order; [`FleetError::NotReady`] naming those
/// without a complete result.
pub fn read_results<T: DeserializeOwned>(
    plan_path: &Path,
    plan: &Plan,
    plan_crc32: u32,
    needed_by: &str,
    ids: &[usize],
) -> Result<Vec<T>> {
    let missing: Vec<usize> = ids
        .iter()
        .copied()
        .filter(|&i| is_done(plan, plan_crc32, i).is_none())
        .collect();
    if !missing.is_empty() {
        let stage = plan
            .shards
            .get(missing[0])
            .and_then(|s| plan.stages.get(s.stage))
            .map_or_else(String::new, |s| s.name.clone());
        return Err(FleetError::NotReady {
            plan: plan_path.to_path_buf(),
            needed_by: needed_by.to_owned(),
            stage,
            missing,
        });
    }
    let mut out = Vec::new();
    for &i in ids {
        let path = plan.result_path(i);
        let text = std::fs::read_to_string(&path).map_err(|e| io_err(&path, e))?;
        for (n, line) in text.lines().enumerate() {
            out.push(
                serde_json::from_str(line)
                    .map_err(|e| invalid(&path, format!("line {}: {e}", n + 1)))?,
            );
        }
    }
    Ok(out)
}

/// Reads the plan's manifest, checking it is the one the plan was made with.
pub fn plan_manifest(plan: &Plan) -> Result<(PathBuf, Manifest)> {
    let path = PathBuf::from(&plan.map.path);
    let bytes = std::fs::read(&path).map_err(|e| io_err(&path, e))?;
    if bytes.len() as u64 != plan.map.bytes || crc32fast::hash(&bytes) != plan.map.crc32 {
        return Err(invalid(
            &path,
            "the tiled map changed since the plan was made; make the plan again".into(),
        ));
    }
    Ok((path.clone(), Manifest::read(&path)?))
}

/// Where a shard takes a tile from: `None` reads it from the manifest's folder; a function
/// gives it from elsewhere (e.g. bytes shared through a distributed object store).
pub type TileSource<'a> = Option<&'a dyn Fn(usize) -> Result<LoadedTile>>;

/// Runs shard `id` of the plan at `plan_path` unless it is complete already.
pub fn run_shard(plan_path: &Path, id: usize, tiles: TileSource<'_>) -> Result<ShardOutcome> {
    let t = Instant::now();
    let (plan, plan_crc) = Plan::read(plan_path)?;
    let shard = plan.shard(id, plan_path)?.clone();
    let stage = plan.stages[shard.stage].name.clone();
    let result = plan.result_path(id);
    if let Some(done) = is_done(&plan, plan_crc, id) {
        return Ok(ShardOutcome {
            shard: id,
            stage,
            skipped: true,
            records: done.records,
            result,
            bytes: done.bytes,
            crc32: done.crc32,
            seconds: t.elapsed().as_secs_f64(),
        });
    }
    if plan.job == Job::Streets {
        let driving = match crate::streets::driving_shards(&plan, shard.stage) {
            Some(ids) => Some(read_results(
                plan_path,
                &plan,
                plan_crc,
                &format!("shard {id}"),
                &ids,
            )?),
            None => None,
        };
        let lines = crate::streets::tile_lines(plan_path, &plan, &shard, driving)?;
        return write_result(&plan, plan_crc, id, stage, &lines, t);
    }
    if plan.job == Job::Map {
        let lines = crate::map::tile_lines(plan_path, &plan, &shard)?;
        return write_result(&plan, plan_crc, id, stage, &lines, t);
    }
    let (manifest_path, manifest) = plan_manifest(&plan)?;
    let options = plan.options.localize_options(manifest.grid_m, plan_path)?;
    let load = |k: usize| -> Result<LoadedTile> {
        match tiles {
            Some(f) => f(k),
            None => Ok(LoadedTile::read(&manifest_path, &manifest, k)?),
        }
    };
    let lines: Vec<String> = match stage.as_str() {
        "extract" => extract(&plan, &shard, &options)?,
        name if name.starts_with("minimum") || name == "poses" => {
            let tile_index = shard.tile.ok_or_else(|| {
                invalid(
                    plan_path,
                    format!("shard {id} of stage {stage} has no tile"),
                )
            })?;
            let previous = plan.stage_shards(0, shard.batch);
            let extracted: Vec<ExtractRecord> = read_results(
                plan_path,
                &plan,
                plan_crc,
                &format!("shard {id}"),
                &previous,
            )?;
            // The minima of the earlier rounds of this batch (every tile).
            let minimum_stages: Vec<usize> = (1..shard.stage)
                .filter(|&k| plan.stages[k].name.starts_with("minimum"))
                .collect();
            let mut earlier: Vec<MinimumRecord> = Vec::new();
            for &k in &minimum_stages {
                let ids = plan.stage_shards(k, shard.batch);
                earlier.extend(read_results::<MinimumRecord>(
                    plan_path,
                    &plan,
                    plan_crc,
                    &format!("shard {id}"),
                    &ids,
                )?);
            }
            let best = |scan: usize| {
                earlier
                    .iter()
                    .filter(|m| m.scan == scan)
                    .filter_map(|m| m.minimum)
                    .min()
            };
            let round = minimum_stages.len();
            let caps: Vec<Option<Cap>> = extracted
                .iter()
                .map(|e| {
                    if stage.starts_with("minimum") {
                        // Found in an earlier round: nothing left to do; else this round's cap.
                        if best(e.scan).is_some() {
                            return None;
                        }
                        let cost = match plan.options.minimum_caps_m.get(round) {
                            Some(&d) => round_cap(&manifest, &e.segments(), d),
                            None => u64::MAX,
                        };
                        Some(Cap {
                            cost,
                            minimum_only: true,
                            ..Cap::NONE
                        })
                    } else {
                        best(e.scan).map(|b| Cap {
                            cost: limit_of(b, options.search.keep_factor),
                            minimum_only: false,
                            ..Cap::NONE
                        })
                    }
                })
                .collect();
            // A tile no scan of the batch still needs is not read (e.g. a later round once
            // every scan of the batch has its minimum).
            let wanted = extracted
                .iter()
                .zip(&caps)
                .any(|(e, cap)| cap.is_some() && !e.segments.is_empty());
            if !wanted {
                return write_result(&plan, plan_crc, id, stage, &[], t);
            }
            let tile = load(tile_index)?;
            // The scans in parallel (each search also splits its own work): a capped
            // search alone leaves cores idle between its best-first batches.
            let minimum_stage = stage.starts_with("minimum");
            let found: Vec<Option<String>> = extracted
                .par_iter()
                .zip(caps)
                .map(|(e, cap)| -> Result<Option<String>> {
                    let segments = e.segments();
                    let Some(cap) = cap.filter(|_| !segments.is_empty()) else {
                        return Ok(None);
                    };
                    let along = e.along_streets(&options);
                    let search = search_tile(&tile, tile_index, &segments, along, &options, cap)?;
                    let line = if minimum_stage {
                        serde_json::to_string(&MinimumRecord {
                            scan: e.scan,
                            tile: tile_index,
                            minimum: search.minimum,
                        })
                    } else if search.raw.is_empty() {
                        return Ok(None);
                    } else {
                        serde_json::to_string(&PosesRecord {
                            scan: e.scan,
                            search,
                        })
                    };
                    line.map(Some).map_err(|e| io_err(&result, e))
                })
                .collect::<Result<_>>()?;
            found.into_iter().flatten().collect()
        }
        other => {
            return Err(invalid(plan_path, format!("unknown stage {other:?}")));
        }
    };
    write_result(&plan, plan_crc, id, stage, &lines, t)
}

/// Writes a shard's result lines, then its completion record (both atomically).
fn write_result(
    plan: &Plan,
    plan_crc: u32,
    id: usize,
    stage: String,
    lines: &[String],
    t: Instant,
) -> Result<ShardOutcome> {
    let result = plan.result_path(id);
    let mut text = String::new();
    for l in lines {
        text.push_str(l);
        text.push('\n');
    }
    geodata::fsio::write_atomic(&result, text.as_bytes()).map_err(|e| io_err(&result, e))?;
    let done = Done {
        plan_crc32: plan_crc,
        shard: id,
        records: lines.len(),
        bytes: text.len() as u64,
        crc32: crc32fast::hash(text.as_bytes()),
    };
    let done_path = plan.done_path(id);
    let json = serde_json::to_vec(&done).map_err(|e| io_err(&done_path, e))?;
    geodata::fsio::write_atomic(&done_path, json).map_err(|e| io_err(&done_path, e))?;
    Ok(ShardOutcome {
        shard: id,
        stage,
        skipped: false,
        records: done.records,
        result,
        bytes: done.bytes,
        crc32: done.crc32,
        seconds: t.elapsed().as_secs_f64(),
    })
}

/// Stage `extract`: each scan of the shard's batch read (checked against the plan) and its
/// wall segments extracted.
fn extract(
    plan: &Plan,
    shard: &crate::plan::Shard,
    options: &LocalizeOptions,
) -> Result<Vec<String>> {
    // The scans in parallel; the lines stay in scan order.
    (shard.scans[0]..shard.scans[1])
        .into_par_iter()
        .map(|k| extract_one(plan, k, options))
        .collect()
}

/// One scan's [`ExtractRecord`] as a JSON line.
fn extract_one(plan: &Plan, k: usize, options: &LocalizeOptions) -> Result<String> {
    let input = plan.inputs.get(k).ok_or_else(|| {
        invalid(
            Path::new(&plan.out),
            format!("scan {k} of a shard; the plan lists {}", plan.inputs.len()),
        )
    })?;
    let path = PathBuf::from(&input.path);
    let bytes = std::fs::metadata(&path)
        .map_err(|e| io_err(&path, e))?
        .len();
    if bytes != input.bytes {
        return Err(invalid(
            &path,
            format!(
                "{bytes} bytes, the plan recorded {}: the scan changed since the plan was made",
                input.bytes
            ),
        ));
    }
    let cloud = geodata::cloud::read_cloud(&path).map_err(|e| io_err(&path, e))?;
    let e = scan_segments(options, &cloud.positions)?;
    let record = ExtractRecord {
        scan: k,
        name: path
            .file_name()
            .map_or_else(String::new, |n| n.to_string_lossy().into_owned()),
        points: cloud.len(),
        segments: e
            .segments
            .iter()
            .map(|s| [s.a[0], s.a[1], s.b[0], s.b[1]])
            .collect(),
        sensor: e.sensor.map(|s| SensorRecord {
            profile: geodata::sensors::SensorKind::ALL
                .iter()
                .position(|k| k.name() == s.profile)
                .unwrap_or(0),
            detected: s.detected,
            mount_height_m: s.geometry.mount_height_m,
            vfov_deg: s.geometry.vfov_deg,
            beams: s.geometry.beams,
        }),
        clearance_m: e.clearance_m,
        level: e.levelling,
        vertical_cells: e.vertical_cells,
        min_length_m: e.min_length_m,
    };
    serde_json::to_string(&record).map_err(|e| io_err(&path, e))
}
