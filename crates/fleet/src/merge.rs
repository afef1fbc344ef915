//! The merge: every shard's result combined into the job's answer — for localization one row
//! per scan, the rows of `localize track --json`; for streets the whole map's estimates and
//! their GeoJSON ([`merge_job`] takes either).

use crate::plan::{Job, Plan};
use crate::run::{plan_manifest, read_results, ExtractRecord, PosesRecord};
use crate::streets::StreetsMerge;
use crate::Result;
use localize::report::TrackRow;
use localize::tiles::{finish_tiled, owner_crops, place_in, TilePlace, TileSearch};
use serde::Serialize;
use std::collections::BTreeMap;
use std::path::Path;
use std::time::Instant;

/// The merged answer of a localization plan (`shard merge --out result.json`).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct LocalizeMerge {
    /// The plan.
    pub plan: String,
    /// One row per scan, in input order.
    pub scans: Vec<TrackRow>,
    /// Shards merged.
    pub shards: usize,
    /// Seconds of the merge.
    pub seconds: f64,
}

/// The merged answer of a plan, by its job.
#[derive(Debug, Clone, PartialEq)]
pub enum Merged {
    /// A localization plan's rows.
    Localize(LocalizeMerge),
    /// A streets plan's estimates and GeoJSON.
    Streets(StreetsMerge),
    /// A map plan's tiles and GeoJSON.
    Map(crate::map::MapMerge),
}

/// Merges the results of every shard of the plan at `plan_path`, whatever its job.
pub fn merge_job(plan_path: &Path) -> Result<Merged> {
    let (plan, plan_crc) = Plan::read(plan_path)?;
    match plan.job {
        Job::Localize => merge(plan_path).map(Merged::Localize),
        Job::Streets => {
            let ids = crate::streets::answer_shards(&plan);
            let parts = read_results(plan_path, &plan, plan_crc, "the merge", &ids)?;
            crate::streets::merge_parts(plan_path, &plan, parts).map(Merged::Streets)
        }
        Job::Map => {
            let ids: Vec<usize> = plan.shards.iter().map(|s| s.id).collect();
            let parts = read_results(plan_path, &plan, plan_crc, "the merge", &ids)?;
            crate::map::merge_parts(plan_path, &plan, parts).map(Merged::Map)
        }
    }
}

/// Merges the results of every shard of the localization plan at `plan_path` (all must be
/// complete); [`merge_job`] merges a plan of any job.
pub fn merge(plan_path: &Path) -> Result<LocalizeMerge> {
    let t = Instant::now();
    let (plan, plan_crc) = Plan::read(plan_path)?;
    if plan.job != Job::Localize {
        return Err(crate::invalid(
            plan_path,
            format!(
                "a {:?} plan, not a localization plan: merge it with `merge_job`",
                plan.job
            ),
        ));
    }
    let (manifest_path, manifest) = plan_manifest(&plan)?;
    let options = plan.options.localize_options(manifest.grid_m, plan_path)?;
    let all = |stage: usize| -> Vec<usize> {
        plan.shards
            .iter()
            .filter(|s| s.stage == stage)
            .map(|s| s.id)
            .collect()
    };
    let merging = "the merge";
    let extracted: Vec<ExtractRecord> = read_results(plan_path, &plan, plan_crc, merging, &all(0))?;
    let poses: Vec<PosesRecord> = read_results(
        plan_path,
        &plan,
        plan_crc,
        merging,
        &all(plan.stages.len() - 1),
    )?;
    let mut by_scan: BTreeMap<usize, Vec<TileSearch>> = BTreeMap::new();
    for p in poses {
        by_scan.entry(p.scan).or_default().push(p.search);
    }
    for v in by_scan.values_mut() {
        v.sort_by_key(|s| s.tile);
    }
    // The crops of every tile owning a candidate of some scan, loaded once.
    let crops = owner_crops(
        &manifest_path,
        &manifest,
        by_scan.values().map(|s| &s[..]),
        &options,
    )?;
    let places: Vec<(usize, TilePlace<'_>)> =
        crops.iter().map(|(k, c)| (*k, TilePlace::new(c))).collect();
    let place_of = |k: usize| place_in(&places, k);
    let frame_map = &crops[0].1;
    let empty = Vec::new();
    let mut scans = Vec::with_capacity(extracted.len());
    for e in &extracted {
        let searches = by_scan.get(&e.scan).unwrap_or(&empty);
        let segments = e.segments();
        let ex = e.scan_segments();
        let along = e.along_streets(&options);
        let mut result = finish_tiled(&manifest, searches, &segments, along, &options, &place_of);
        result.record_scan(&ex, e.points);
        scans.push(TrackRow::new(
            frame_map,
            &e.name,
            &result,
            &ex,
            plan.options.top,
        ));
    }
    Ok(LocalizeMerge {
        plan: plan_path.display().to_string(),
        scans,
        shards: plan.shards.len(),
        seconds: t.elapsed().as_secs_f64(),
    })
}
