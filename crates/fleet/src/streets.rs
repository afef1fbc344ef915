//! The streets job as shards: street geometry of a whole map from one registered cloud, one
//! shard per street tile, merged bit for bit equal to `StreetModel::estimate` on the whole map.
//!
//! The plan ([`plan_streets`]) cuts the map into square tiles of its local frame
//! ([`streets::tiles::plan_tiles`]) and keeps one shard per tile owning a drivable segment,
//! with the tile's owned segments written into the plan. A shard ([`tile_lines`]) loads the
//! model, the map and the cloud (each checked against the plan's size and CRC-32) and runs
//! [`StreetModel::estimate_tile`]: the owned segments' estimates, computed on the whole
//! coupling component of each (its halo, however far it reaches), so inference is exact at
//! tile borders. Its result is one JSON line, the tile's [`TileEstimates`]. The merge
//! ([`merge_parts`]) runs [`merge_tiles`] over every shard's line and writes the GeoJSON
//! `urbansem streets estimate` writes.
//!
//! The cloud must already be in the map's local frame (the default `--cloud-frame local`
//! of `streets estimate`).

use crate::plan::{absolute, tile_stages, Job, JobOptions, Plan, Shard, PLAN_FORMAT, PLAN_VERSION};
use crate::{invalid, io_err, Result};
use geodata::cloud::PointCloud;
use geodata::osm::OsmMap;
use localize::tiles::FileRef;
use serde_json::Value;
use std::path::{Path, PathBuf};
use streets::model::{Estimates, StreetModel};
use streets::tiles::{merge_tiles, plan_tiles, TileEstimates};

/// The stage name of the streets job's shards (with a driving model: its second stage).
pub const STAGE: &str = "tiles";
/// The stage name of the driving-area tiles that come first for a with-sidewalk model with
/// sidewalk margins.
pub const DRIVING_STAGE: &str = "driving";

/// The merged answer of a streets plan (`shard merge --out result.geojson`).
#[derive(Debug, Clone, PartialEq)]
pub struct StreetsMerge {
    /// The plan.
    pub plan: String,
    /// The whole map's estimates, equal to `StreetModel::estimate`.
    pub estimates: Estimates,
    /// The WGS84 GeoJSON FeatureCollection `streets estimate` writes for them (validated).
    pub geojson: Value,
    /// Shards merged.
    pub shards: usize,
    /// Seconds of the merge.
    pub seconds: f64,
}

/// Plans the streets job: the cloud `cloud` (in the local frame of `map`) through the model
/// `model`, one shard per `tile_m` street tile owning a drivable segment, results into `out`.
///
/// A with-sidewalk model with sidewalk margins ([`StreetModel::wants_driving_area`]) needs
/// `driving_model`, a driving-area model: its tiles are a first stage (`driving`), and every
/// with-sidewalk tile reads their merge, as `urbansem streets estimate` estimates the driving
/// area of the whole cloud first. A driving model for any other model is an error.
pub fn plan_streets(
    map: &Path,
    cloud: &Path,
    model: &Path,
    driving_model: Option<&Path>,
    out: &Path,
    tile_m: f64,
) -> Result<Plan> {
    let map_abs = absolute(map)?;
    let cloud_abs = absolute(cloud)?;
    let model_abs = absolute(model)?;
    let model_ref = FileRef::of(&model_abs, &model_abs.to_string_lossy())?;
    let bytes = std::fs::read(&model_abs).map_err(|e| io_err(&model_abs, e))?;
    let street_model = StreetModel::from_json(&bytes, &model_abs)?;
    let driving_ref = match driving_model {
        None if street_model.wants_driving_area() => {
            // Its prior needs the driving area of the same cloud estimated first.
            return Err(invalid(
                &model_abs,
                "a with-sidewalk model with sidewalk margins centres its priors on a driving-area estimate: plan it with a driving-area model (`--driving-model`)".into(),
            ));
        }
        None => None,
        Some(d) => {
            let d_abs = absolute(d)?;
            let d_bytes = std::fs::read(&d_abs).map_err(|e| io_err(&d_abs, e))?;
            let target = StreetModel::from_json(&d_bytes, &d_abs)?.target;
            if let Some(message) = street_model.driving_model_mismatch(target) {
                return Err(invalid(
                    &d_abs,
                    format!("as the driving model of {}: {message}", model_abs.display()),
                ));
            }
            Some(FileRef::of(&d_abs, &d_abs.to_string_lossy())?)
        }
    };
    let map_ref = FileRef::of(&map_abs, &map_abs.to_string_lossy())?;
    let osm = OsmMap::load(&map_abs)?;
    streets::model::drivable_segments(&osm, &map_abs.to_string_lossy())?;
    let street_tiles = plan_tiles(&osm, tile_m)?;
    let cloud_ref = FileRef::of(&cloud_abs, &cloud_abs.to_string_lossy())?;
    std::fs::create_dir_all(out).map_err(|e| io_err(out, e))?;
    let out_abs = absolute(out)?;
    // With a driving model: stage 0 the driving area, stage 1 the with-sidewalk estimate.
    let names: &[&str] = if driving_ref.is_some() {
        &[DRIVING_STAGE, STAGE]
    } else {
        &[STAGE]
    };
    let (stages, shards) = tile_stages(names, street_tiles.len(), [0, 1]);
    Ok(Plan {
        format: PLAN_FORMAT.into(),
        version: PLAN_VERSION,
        job: Job::Streets,
        map: map_ref,
        inputs: vec![cloud_ref],
        options: JobOptions::default(),
        batch_size: 1,
        out: out_abs.to_string_lossy().into_owned(),
        stages,
        shards,
        model: Some(model_ref),
        driving_model: driving_ref,
        tile_m: Some(tile_m),
        street_tiles,
        map_job: None,
        map_tiles: Vec::new(),
    })
}

/// The shards whose results a with-sidewalk shard of stage `stage` reads: the `driving`
/// stage's, when the plan has a driving model and `stage` is the last.
pub fn driving_shards(plan: &Plan, stage: usize) -> Option<Vec<usize>> {
    (plan.driving_model.is_some() && stage > 0).then(|| {
        plan.stages
            .first()
            .map_or_else(Vec::new, |s| s.shards.clone())
    })
}

/// The shards whose results make the answer: the last stage's (the with-sidewalk tiles when
/// the plan estimates the driving area first).
pub fn answer_shards(plan: &Plan) -> Vec<usize> {
    plan.stages
        .last()
        .map_or_else(Vec::new, |s| s.shards.clone())
}

/// The bytes of a file the plan names, checked against the size and CRC-32 it recorded.
pub(crate) fn checked_bytes(file: &FileRef, what: &str) -> Result<(PathBuf, Vec<u8>)> {
    let path = PathBuf::from(&file.path);
    let bytes = std::fs::read(&path).map_err(|e| io_err(&path, e))?;
    if bytes.len() as u64 != file.bytes || crc32fast::hash(&bytes) != file.crc32 {
        return Err(invalid(
            &path,
            format!(
                "the {what} changed since the plan was made ({} bytes, the plan recorded {}); make the plan again",
                bytes.len(),
                file.bytes
            ),
        ));
    }
    Ok((path, bytes))
}

/// The plan's model, checked against the plan.
fn plan_model(plan_path: &Path, plan: &Plan) -> Result<StreetModel> {
    let file = plan
        .model
        .as_ref()
        .ok_or_else(|| invalid(plan_path, "a streets plan without a model".into()))?;
    let (path, bytes) = checked_bytes(file, "street model")?;
    Ok(StreetModel::from_json(&bytes, &path)?)
}

/// The plan's driving-area model, checked against the plan.
fn plan_driving_model(file: &FileRef) -> Result<StreetModel> {
    let (path, bytes) = checked_bytes(file, "driving-area model")?;
    Ok(StreetModel::from_json(&bytes, &path)?)
}

/// The plan's map, checked against the plan.
fn plan_map(plan: &Plan) -> Result<OsmMap> {
    let (path, _) = checked_bytes(&plan.map, "map")?;
    Ok(OsmMap::load(&path)?)
}

/// The plan's cloud (its only input), checked against the plan.
fn plan_cloud(plan_path: &Path, plan: &Plan) -> Result<PointCloud> {
    let [file] = plan.inputs.as_slice() else {
        return Err(invalid(
            plan_path,
            format!(
                "a streets plan takes one cloud, this one lists {} inputs",
                plan.inputs.len()
            ),
        ));
    };
    let (path, _) = checked_bytes(file, "cloud")?;
    geodata::cloud::read_cloud(&path).map_err(|e| io_err(&path, e))
}

/// A streets shard's result lines: its tile's [`TileEstimates`] as one JSON line. A
/// with-sidewalk tile of a plan with a driving model takes `driving`, the first stage's
/// results (every tile's driving-area estimates; [`driving_shards`]).
pub fn tile_lines(
    plan_path: &Path,
    plan: &Plan,
    shard: &Shard,
    driving: Option<Vec<TileEstimates>>,
) -> Result<Vec<String>> {
    let tile = shard
        .tile
        .and_then(|k| plan.street_tiles.get(k))
        .ok_or_else(|| {
            invalid(
                plan_path,
                format!(
                    "shard {} names tile {:?}; the plan lists {} street tiles",
                    shard.id,
                    shard.tile,
                    plan.street_tiles.len()
                ),
            )
        })?;
    let map = plan_map(plan)?;
    let cloud = plan_cloud(plan_path, plan)?;
    let cloud_name = plan.inputs.first().map_or("", |f| f.path.as_str());
    let estimates = match &plan.driving_model {
        Some(file) if shard.stage == 0 => {
            let driving = plan_driving_model(file)?;
            driving.estimate_tile(&map, &cloud, tile, &plan.map.path, cloud_name)?
        }
        Some(_) => {
            // The whole map's driving area: the merge of the first stage's tiles.
            let parts = driving.ok_or_else(|| {
                invalid(
                    plan_path,
                    format!(
                        "internal: with-sidewalk shard {} without the driving-area results",
                        shard.id
                    ),
                )
            })?;
            let driving = merge_tiles(parts)?;
            let model = plan_model(plan_path, plan)?;
            model.estimate_tile_given_driving_area(
                &map,
                &cloud,
                tile,
                &plan.map.path,
                &driving.segments,
            )?
        }
        None => {
            let model = plan_model(plan_path, plan)?;
            model.estimate_tile(&map, &cloud, tile, &plan.map.path, cloud_name)?
        }
    };
    let line = serde_json::to_string(&estimates).map_err(|e| io_err(plan_path, e))?;
    Ok(vec![line])
}

/// The merge of a streets plan from its shards' results (`parts`, one per tile): the whole
/// map's estimates and their GeoJSON, as `urbansem streets estimate` writes it.
pub fn merge_parts(
    plan_path: &Path,
    plan: &Plan,
    parts: Vec<TileEstimates>,
) -> Result<StreetsMerge> {
    let t = std::time::Instant::now();
    let model = plan_model(plan_path, plan)?;
    let map = plan_map(plan)?;
    let estimates = merge_tiles(parts)?;
    if estimates.segments.is_empty() {
        return Err(invalid(
            plan_path,
            format!(
                "no drivable segment of {} has usable bins in {} ({} shorter than a bin, {} unobserved): check that the cloud is in the map's local frame and covers its streets",
                plan.map.path,
                plan.inputs.first().map_or("", |f| f.path.as_str()),
                estimates.too_short,
                estimates.unobserved
            ),
        ));
    }
    let geojson = streets::geojson::feature_collection(&map, &estimates.segments, model.target);
    streets::geojson::validate(&geojson)
        .map_err(|e| invalid(plan_path, format!("internal: the merged GeoJSON: {e}")))?;
    Ok(StreetsMerge {
        plan: plan_path.display().to_string(),
        estimates,
        geojson,
        shards: answer_shards(plan).len(),
        seconds: t.elapsed().as_secs_f64(),
    })
}
