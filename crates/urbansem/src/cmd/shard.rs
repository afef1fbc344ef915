//! `urbansem shard …`: a fleet job as engine-neutral shards (plan, run one, merge).

use anyhow::Context;
use clap::{Subcommand, ValueEnum};
use fleet::merge::Merged;
use fleet::plan::{plan_localize, JobOptions};
use fleet::streets::plan_streets;
use std::path::{Path, PathBuf};

/// Jobs a plan can hold.
#[derive(Clone, Copy, ValueEnum)]
pub enum JobArg {
    /// Localize a folder of gravity-levelled scans on a tiled map.
    Localize,
    /// Street geometry (offset and width per segment) of a map from one cloud, per street tile.
    Streets,
    /// Semantic maps (`.srt`) of labelled clouds in the map's local frame, per map tile.
    Map,
}

/// Subcommands of `urbansem shard`.
#[derive(Subcommand)]
pub enum ShardCommand {
    /// Split a job into shards and write the plan: for localization, stages of scan batches ×
    /// tiles (`extract`, `minimum`, `poses`) whose shards run in any order within a stage;
    /// for streets, one stage (`tiles`) of a shard per street tile (a with-sidewalk model
    /// with sidewalk margins: first a `driving` stage of driving-area tiles); for maps, one
    /// stage (`map-tiles`) of a shard per map tile.
    Plan {
        /// The job.
        #[arg(long, value_enum)]
        job: JobArg,
        /// The map: for localization the tiled map's manifest (from `localize index
        /// --tile-m`), for streets and maps the OSM map (.osm or .osm.pbf) whose local frame
        /// the clouds are in.
        #[arg(long)]
        map: PathBuf,
        /// The inputs: for localization a folder of gravity-levelled scans (every cloud
        /// file), for streets one registered cloud in the map's local frame, for maps a folder
        /// of labelled clouds (or one) in the map's local frame.
        #[arg(long)]
        inputs: PathBuf,
        /// The street model from `urbansem streets train` (streets only; default: the shipped
        /// model, written into the results folder so that the plan can check it like any file).
        #[arg(long)]
        model: Option<PathBuf>,
        /// The driving-area model that centres a with-sidewalk model's priors (streets only;
        /// default for a with-sidewalk model with sidewalk margins: the shipped driving-area
        /// model, written into the results folder), as `streets estimate --driving-model`.
        #[arg(long)]
        driving_model: Option<PathBuf>,
        /// Street area to estimate with the shipped models (streets only; with --model: must
        /// be the model's) [default: driving-area, or the --model's].
        #[arg(long, value_enum)]
        target: Option<super::streets::TargetArg>,
        /// Side of the tiles, metres (streets: default 500; maps: default 100, a whole number
        /// of cells).
        #[arg(long)]
        tile_m: Option<f64>,
        /// Cell size of the maps, metres (maps only).
        #[arg(long, default_value_t = 0.1)]
        resolution: f64,
        /// The plan file to write.
        #[arg(long)]
        out: PathBuf,
        /// Folder of the shards' results (default: the plan's name with `.d`).
        #[arg(long)]
        results: Option<PathBuf>,
        /// Scans per shard.
        #[arg(long, default_value_t = 8)]
        batch: usize,
        /// Candidates listed per scan.
        #[arg(long, default_value_t = 5)]
        top: usize,
        /// Cost that ranks the candidates.
        #[arg(long, value_enum, default_value_t = super::localize::CostArg::default_rank())]
        cost: super::localize::CostArg,
        /// Localization: sensor profile (`auto`, `terrestrial`, `hdl64`, `vlp16`, `os1-64`,
        /// `os1-128`).
        #[arg(long, default_value = "auto")]
        sensor: String,
        /// Localization: levelling of tilted scans by their walls, as `localize --level`.
        #[arg(long, value_enum, default_value = "off")]
        level: super::localize::LevelArg,
        /// Localization: what carries the sensor, as `localize --vehicle`.
        #[arg(long, value_enum, default_value = "auto")]
        vehicle: super::localize::VehicleArg,
        /// Localization: yaw step of the search, degrees.
        #[arg(long, default_value_t = 0.5)]
        yaw_step_deg: f64,
        /// Localization: the d_DCM caps of the `minimum` rounds, metres, increasing (a last
        /// round without a cap follows).
        #[arg(long, value_delimiter = ',', default_values_t = localize::tiles::MINIMUM_CAPS_M)]
        minimum_caps_m: Vec<f64>,
        /// Print one JSON object.
        #[arg(long)]
        json: bool,
    },
    /// Run one shard (a no-op when its result is complete) and write its result file.
    Run {
        /// The plan.
        plan: PathBuf,
        /// The shard's id (0 … shards − 1; e.g. a Slurm array or Kubernetes job index).
        #[arg(long)]
        shard: usize,
        /// Print one JSON object.
        #[arg(long)]
        json: bool,
    },
    /// Combine every shard's result (all must be complete) into the job's answer.
    Merge {
        /// The plan.
        plan: PathBuf,
        /// The answer to write (for localization JSON `{"scans": [...]}`, the rows of
        /// `localize track --json`; for streets the GeoJSON `streets estimate` writes).
        #[arg(long)]
        out: PathBuf,
    },
}

/// Runs one `urbansem shard` subcommand.
pub fn run(command: ShardCommand) -> anyhow::Result<()> {
    match command {
        ShardCommand::Plan {
            job,
            map,
            inputs,
            model,
            driving_model,
            target,
            tile_m,
            resolution,
            out,
            results,
            batch,
            top,
            cost,
            sensor,
            level,
            vehicle,
            yaw_step_deg,
            minimum_caps_m,
            json,
        } => {
            if batch == 0 {
                super::usage!("--batch 0: expected at least 1 scan per shard");
            }
            let results = results.unwrap_or_else(|| out.with_extension("d"));
            let plan = match (job, model) {
                (JobArg::Localize, _) => {
                    if !(yaw_step_deg.is_finite() && yaw_step_deg > 0.0) {
                        super::usage!("--yaw-step-deg {yaw_step_deg}: expected degrees > 0");
                    }
                    let options = JobOptions {
                        top,
                        cost: cost.kind().name().into(),
                        sensor,
                        yaw_step_deg,
                        minimum_caps_m,
                        level: level.name().into(),
                        vehicle: vehicle.vehicle().name().into(),
                    };
                    let known = geodata::sensors::SensorKind::ALL.map(|k| k.name());
                    if options.sensor != "auto" && !known.contains(&options.sensor.as_str()) {
                        super::usage!(
                            "--sensor {}: expected auto or one of {}",
                            options.sensor,
                            known.join(", ")
                        );
                    }
                    plan_localize(&map, &inputs, &results, batch, options)?
                }
                (JobArg::Streets, model) => {
                    let tile_m = tile_m.unwrap_or(500.0);
                    if !(tile_m.is_finite() && tile_m > 0.0) {
                        super::usage!("--tile-m {tile_m}: expected a tile side > 0 metres");
                    }
                    let target = target.map(streets::model::Target::from);
                    let model = match model {
                        Some(model) => model,
                        None if target == Some(streets::model::Target::WithSidewalk) => {
                            shipped_street_model_file(
                                &results,
                                "default-with-sidewalk-model.json",
                                streets::model::WITH_SIDEWALK_MODEL_JSON,
                                ("model", "with-sidewalk model"),
                            )?
                        }
                        None => shipped_street_model_file(
                            &results,
                            "default-street-model.json",
                            streets::model::DEFAULT_MODEL_JSON,
                            ("model", "model"),
                        )?,
                    };
                    let bytes = std::fs::read(&model)
                        .with_context(|| format!("reading the model {}", model.display()))?;
                    let street_model = streets::model::StreetModel::from_json(&bytes, &model)?;
                    if let Some(t) = target.filter(|&t| t != street_model.target) {
                        super::usage!(
                            "--target {} but the model {} is a {} model",
                            t.key().replace('_', "-"),
                            model.display(),
                            street_model.target.key().replace('_', "-")
                        );
                    }
                    let wants = street_model.wants_driving_area();
                    let driving_model = match driving_model {
                        Some(d) => Some(d),
                        None if wants => Some(shipped_street_model_file(
                            &results,
                            "default-driving-model.json",
                            streets::model::DEFAULT_MODEL_JSON,
                            ("driving-model", "driving-area model"),
                        )?),
                        None => None,
                    };
                    plan_streets(
                        &map,
                        &inputs,
                        &model,
                        driving_model.as_deref(),
                        &results,
                        tile_m,
                    )?
                }
                (JobArg::Map, _) => {
                    let tile_m = tile_m.unwrap_or(100.0);
                    if !(resolution.is_finite() && resolution > 0.0) {
                        super::usage!("--resolution {resolution}: expected a cell size > 0 metres");
                    }
                    let cells = tile_m / resolution;
                    if !(cells >= 1.0 && (cells - cells.round()).abs() < 1e-6) {
                        super::usage!("--tile-m {tile_m}: expected a whole number (≥ 1) of {resolution} m cells");
                    }
                    fleet::map::plan_map(&map, &inputs, &results, tile_m, resolution)?
                }
            };
            plan.write(&out)?;
            let summary = serde_json::json!({
                "plan": out.display().to_string(),
                "shards": plan.shards.len(),
                "stages": plan.stages.iter().map(|s| serde_json::json!({"name": s.name, "shards": s.shards.len()})).collect::<Vec<_>>(),
                "inputs": plan.inputs.len(),
                "results": plan.out,
            });
            if json {
                return super::print_json(&summary);
            }
            println!(
                "{}: {} shards in {} stages ({}) over {} inputs; results in {}",
                out.display(),
                plan.shards.len(),
                plan.stages.len(),
                plan.stages
                    .iter()
                    .map(|s| format!("{} {}", s.name, s.shards.len()))
                    .collect::<Vec<_>>()
                    .join(", "),
                plan.inputs.len(),
                plan.out
            );
            Ok(())
        }
        ShardCommand::Run { plan, shard, json } => {
            let outcome = fleet::run::run_shard(&plan, shard, None)?;
            if json {
                return super::print_json(&outcome);
            }
            println!(
                "shard {} ({}): {} records, {} bytes, CRC {:#010x}{} in {:.2} s",
                outcome.shard,
                outcome.stage,
                outcome.records,
                outcome.bytes,
                outcome.crc32,
                if outcome.skipped {
                    " (already complete, not run)"
                } else {
                    ""
                },
                outcome.seconds
            );
            Ok(())
        }
        ShardCommand::Merge { plan, out } => {
            let merged = match fleet::merge::merge_job(&plan)? {
                Merged::Localize(merged) => merged,
                Merged::Map(merged) => {
                    geodata::fsio::write_atomic(&out, serde_json::to_vec_pretty(&merged.geojson)?)
                        .map_err(|e| anyhow::anyhow!("writing {}: {e}", out.display()))?;
                    let cells: usize = merged.tiles.iter().map(|t| t.core_cells).sum();
                    let objects: usize = merged.tiles.iter().map(|t| t.objects.len()).sum();
                    println!(
                        "{}: {} tiles ({} cells, {} objects; the tiles' maps are beside the shard results) from {} shards in {:.2} s",
                        out.display(),
                        merged.tiles.len(),
                        cells,
                        objects,
                        merged.shards,
                        merged.seconds
                    );
                    return Ok(());
                }
                Merged::Streets(merged) => {
                    geodata::fsio::write_atomic(&out, serde_json::to_vec_pretty(&merged.geojson)?)
                        .map_err(|e| anyhow::anyhow!("writing {}: {e}", out.display()))?;
                    let est = &merged.estimates;
                    println!(
                        "{}: {} segments estimated ({} exact inference), {} shorter than a bin, {} without observed bins; from {} shards in {:.2} s",
                        out.display(),
                        est.segments.len(),
                        if est.exact { "tree," } else { "loopy," },
                        est.too_short,
                        est.unobserved,
                        merged.shards,
                        merged.seconds
                    );
                    return Ok(());
                }
            };
            let value = serde_json::to_value(&merged)?;
            geodata::fsio::write_atomic(&out, serde_json::to_vec_pretty(&value)?)
                .map_err(|e| anyhow::anyhow!("writing {}: {e}", out.display()))?;
            let found = merged.scans.iter().filter(|r| r.lat.is_some()).count();
            println!(
                "{}: {} scans ({} with a pose) from {} shards in {:.2} s",
                out.display(),
                merged.scans.len(),
                found,
                merged.shards,
                merged.seconds
            );
            Ok(())
        }
    }
}

/// Writes a shipped street model (`json`) into `results` as `name`, for a streets plan
/// without the option `--{flag}`, says so naming it `what`, and returns its path.
fn shipped_street_model_file(
    results: &Path,
    name: &str,
    json: &[u8],
    (flag, what): (&str, &str),
) -> anyhow::Result<PathBuf> {
    std::fs::create_dir_all(results).with_context(|| format!("creating {}", results.display()))?;
    let path = results.join(name);
    geodata::fsio::write_atomic(&path, json)
        .with_context(|| format!("writing {}", path.display()))?;
    eprintln!(
        "shard plan: no --{flag}, the streets job uses the shipped default {what} ({})",
        path.display()
    );
    Ok(path)
}
