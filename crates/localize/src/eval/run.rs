//! The `localize eval` job: every scan of a simulated `localization` dataset or of a real MCD
//! sequence localized on its map (optionally among distractors, optionally in track mode),
//! ranked by each requested method, with figures, summed up in an [`EvalReport`].

use super::report::{
    DistractorsReport, EvalReport, EvalSetup, MapFacts, RankMethod, ScanOutcome, TrackSetup,
};
use super::{check_overlap, map_bounds, real_scans, real_sequence, EvalScan, SimDataset};
use crate::distractors::{embed_among_distractors, DistractorOptions};
use crate::figure::result_svg;
use crate::hashing::{CornerIndex, HashingOptions};
use crate::index::load_map_or_index;
use crate::jobs::write_file;
use crate::pipeline::{Localization, LocalizeOptions, Localizer};
use crate::track::{drifted_odometry, TrackOptions};
use crate::{LocalizeError, Pose2, Result, WithContext};
use geodata::datasets::SequenceKind;
use geodata::osm::OsmMap;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// What to evaluate and how.
#[derive(Debug, Clone)]
pub struct EvalJob {
    /// A simulated `localization` dataset folder or a real sequence folder (MCD, KITTI-360,
    /// KITTI raw: the scans with their dataset poses as truth).
    pub dataset: PathBuf,
    /// The map (OSM file or `.uloc` index); a simulated dataset's own map when `None`.
    pub map: Option<PathBuf>,
    /// The ranking methods to report.
    pub methods: Vec<RankMethod>,
    /// The localizer's options.
    pub options: LocalizeOptions,
    /// Embed the map among distractor buildings of this other map.
    pub distractors: Option<(PathBuf, DistractorOptions)>,
    /// Evaluate only the first scans (of those `select` keeps).
    pub limit: Option<usize>,
    /// Evaluate only the scans whose position in file-name order is `offset` modulo `every`
    /// (`(every, offset)`; e.g. the scans a `localize facade-map --hold-out-every` left out).
    pub select: Option<(usize, usize)>,
    /// Track mode: windows of scans tied by drifted odometry.
    pub track: Option<TrackSetup>,
    /// Write one SVG per scan and `curves.svg` here.
    pub figures: Option<PathBuf>,
}

/// The map a job runs on: the job's, or the simulated dataset's own.
fn job_map(job: &EvalJob, sim: Option<&SimDataset>) -> Result<PathBuf> {
    match (&job.map, sim) {
        (Some(m), _) => Ok(m.clone()),
        (None, Some(d)) => Ok(d.map_path.clone()),
        (None, None) => Err(LocalizeError::Dataset {
            path: job.dataset.clone(),
            message: "a real sequence; give the map of the place it was recorded (an OSM file with buildings, or its .uloc index)".into(),
        }),
    }
}

/// The map, embedded among distractors when the job asks for them.
fn composed_map(
    job: &EvalJob,
    map: OsmMap,
    map_path: &Path,
) -> Result<(OsmMap, Option<DistractorsReport>)> {
    let Some((other_path, options)) = &job.distractors else {
        return Ok((map, None));
    };
    let other = OsmMap::load(other_path)
        .context_with(|| format!("loading the distractor map {}", other_path.display()))?;
    let (composed, summary) =
        embed_among_distractors(&map, &other, options).context_with(|| {
            format!(
                "embedding {} among distractors from {}",
                map_path.display(),
                other_path.display()
            )
        })?;
    let report = DistractorsReport::new(&other_path.display().to_string(), options, summary);
    Ok((composed, Some(report)))
}

/// Runs the evaluation; `on_scan` sees each scan's outcome as soon as it is known, and on a
/// tiled map `progress` each tile of each round ([`run_eval_tiled`]).
pub fn run_eval(
    job: &EvalJob,
    on_scan: &mut dyn FnMut(&ScanOutcome),
    progress: &mut dyn FnMut(crate::tiles::BatchStep<'_>),
) -> Result<EvalReport> {
    let real = real_sequence(&job.dataset);
    let sim = if real.is_some() {
        None
    } else {
        Some(
            SimDataset::open(&job.dataset)
                .context_with(|| format!("opening the dataset {}", job.dataset.display()))?,
        )
    };
    let map_path = job_map(job, sim.as_ref())?;
    if crate::tiles::is_manifest(&map_path) {
        return run_eval_tiled(job, sim.as_ref(), &map_path, on_scan, progress);
    }
    let t = Instant::now();
    let (map, prepared) = load_map_or_index(&map_path)?;
    if prepared.is_some() && job.distractors.is_some() {
        return Err(LocalizeError::DistractorsNeedOsmMap { path: map_path });
    }
    if map.buildings.is_empty() {
        return Err(LocalizeError::Dataset {
            path: map_path,
            message: "the map has no building outlines, and localization matches walls against them (a map of streets only?)".into(),
        });
    }
    let (map, distractors) = composed_map(job, map, &map_path)?;
    let load_map_s = t.elapsed().as_secs_f64();
    let localizer = Localizer::prepared_or_new(&map, prepared, job.options.clone(), &map_path)?;
    let t = Instant::now();
    let hashing_index = CornerIndex::new(&map, &HashingOptions::default());
    let hashing_index_s = t.elapsed().as_secs_f64();
    let mcd = real_eval_scans(job, real, &map, &map_path, map_bounds(&map))?;
    let picked = picked_scans(job, sim.as_ref().map_or(mcd.len(), |d| d.truth.len()))?;
    let count = picked.len();
    if let Some(dir) = &job.figures {
        std::fs::create_dir_all(dir).map_err(|source| LocalizeError::Io {
            action: "creating",
            path: dir.clone(),
            source,
        })?;
    }
    let load = |k: usize| load_scan(job, sim.as_ref(), &mcd, picked[k]);
    let track_results = match &job.track {
        Some(setup) => Some(track_results(&localizer, setup, count, &load)?),
        None => None,
    };
    let mut records: Vec<ScanOutcome> = Vec::new();
    for i in 0..count {
        let scan = load(i)?;
        let result = match &track_results {
            Some(results) => results[i].clone(),
            None => localizer
                .localize_points(&scan.points)
                .context_with(|| format!("localizing {}", scan.name))?,
        };
        let t = Instant::now();
        let hashing: Vec<Pose2> = if job.methods.contains(&RankMethod::Hashing) {
            hashing_index
                .localize(&result.segments)
                .into_iter()
                .map(|(p, _)| p)
                .collect()
        } else {
            Vec::new()
        };
        let hashing_s = t.elapsed().as_secs_f64();
        if let Some(dir) = &job.figures {
            let path = dir.join(format!("{}.svg", scan.name.trim_end_matches(".ply")));
            let svg = result_svg(&localizer, &result, Some(scan.truth), 90.0);
            write_file(&path, svg)?;
        }
        let rec = ScanOutcome::new(scan.name.clone(), scan.truth, result, hashing, hashing_s);
        on_scan(&rec);
        records.push(rec);
    }
    let report = EvalReport::new(
        EvalSetup {
            dataset: job.dataset.display().to_string(),
            map: map_path.display().to_string(),
            methods: job.methods.clone(),
            facts: MapFacts::of_localizer(&localizer),
            load_map_seconds: load_map_s,
            hashing_index_seconds: hashing_index_s,
            distractors,
            track: job.track,
        },
        &records,
    );
    if let Some(dir) = &job.figures {
        write_file(&dir.join("curves.svg"), report.curves_svg())?;
    }
    Ok(report)
}

/// Track mode: every scan's walls first, then each window searched as one.
fn track_results(
    localizer: &Localizer<'_>,
    setup: &TrackSetup,
    count: usize,
    load: &dyn Fn(usize) -> Result<EvalScan>,
) -> Result<Vec<Localization>> {
    let mut truths = Vec::with_capacity(count);
    let mut extracted = Vec::with_capacity(count);
    for i in 0..count {
        let scan = load(i)?;
        truths.push(scan.truth);
        extracted.push(
            localizer
                .scan_segments(&scan.points)
                .context_with(|| format!("extracting walls from {}", scan.name))?,
        );
    }
    let yaw_rad_per_m = setup.odometry_yaw_drift_deg.to_radians() / 50.0;
    let odometry = match setup.odometry_random_seed {
        None => drifted_odometry(&truths, setup.odometry_drift, yaw_rad_per_m),
        Some(seed) => crate::track::randomly_drifted_odometry(
            &truths,
            setup.odometry_drift,
            yaw_rad_per_m,
            seed,
        ),
    };
    let options = TrackOptions {
        window: setup.window,
        history_m: setup.history_m,
        smooth: setup.smooth,
        refine_poses: setup.pose_graph,
        ..Default::default()
    };
    localizer.localize_track(&extracted, &odometry, &options)
}

/// The scans of a real sequence of layout `real` (none for a simulated dataset), truth in
/// `frame_map`'s frame, refused unless one of them lies near `bounds` (the searched map's
/// box).
fn real_eval_scans(
    job: &EvalJob,
    real: Option<SequenceKind>,
    frame_map: &OsmMap,
    map_path: &Path,
    bounds: Option<[f64; 4]>,
) -> Result<Vec<EvalScan>> {
    let Some(kind) = real else {
        return Ok(Vec::new());
    };
    let scans = real_scans(&job.dataset, kind, frame_map, 1).context_with(|| {
        format!(
            "reading the {} scans in {}",
            kind.name(),
            job.dataset.display()
        )
    })?;
    check_overlap(&job.dataset, map_path, &scans, bounds, 200.0)?;
    Ok(scans)
}

/// The indices of the scans the job evaluates among `total`: those `select` keeps, at most
/// `limit` of them.
fn picked_scans(job: &EvalJob, total: usize) -> Result<Vec<usize>> {
    crate::facade_map::check_every_nth("scan selection (every, offset)", job.select)?;
    let picked: Vec<usize> = (0..total)
        .filter(|&i| job.select.is_none() || crate::facade_map::held_out(job.select, i))
        .take(job.limit.unwrap_or(usize::MAX))
        .collect();
    if picked.is_empty() && total > 0 {
        return Err(LocalizeError::Dataset {
            path: job.dataset.clone(),
            message: format!("the scan selection keeps none of its {total} scans"),
        });
    }
    Ok(picked)
}

/// Scan `i` of the job: from the simulated dataset, or of the real scans read up front.
fn load_scan(
    job: &EvalJob,
    sim: Option<&SimDataset>,
    real: &[EvalScan],
    i: usize,
) -> Result<EvalScan> {
    match sim {
        Some(d) => d
            .load(i)
            .context_with(|| format!("loading scan {i} of {}", job.dataset.display())),
        None => real.get(i).cloned().ok_or_else(|| LocalizeError::Dataset {
            path: job.dataset.clone(),
            message: format!("real scan {i} missing"),
        }),
    }
}

/// Why a tiled map cannot run a job's option, if one is asked for.
pub fn tiled_refusal(job: &EvalJob) -> Option<&'static str> {
    if job.distractors.is_some() {
        Some("distractors are added to one OSM map, not to a tiled map")
    } else if job.track.is_some() {
        Some("track mode runs on one map or .uloc index, not on a tiled map")
    } else if job.methods.contains(&RankMethod::Hashing) {
        Some("the hashing baseline indexes one whole map, not a tiled map")
    } else if job.figures.is_some() {
        Some("figures are drawn on one map, not on a tiled map")
    } else {
        None
    }
}

/// The evaluation on a tiled map (`map_path`, a manifest of `localize index --tile-m`): every
/// scan's walls first, then all scans searched together tile by tile
/// ([`crate::tiles::localize_tiled_batch`]: each tile read once per round, not once per
/// scan); `progress` sees each tile of each round.
pub fn run_eval_tiled(
    job: &EvalJob,
    sim: Option<&SimDataset>,
    map_path: &Path,
    on_scan: &mut dyn FnMut(&ScanOutcome),
    progress: &mut dyn FnMut(crate::tiles::BatchStep<'_>),
) -> Result<EvalReport> {
    use crate::tiles::{localize_tiled_batch, Manifest, MINIMUM_CAPS_M};
    if let Some(why) = tiled_refusal(job) {
        return Err(LocalizeError::Dataset {
            path: map_path.to_path_buf(),
            message: why.into(),
        });
    }
    let t = Instant::now();
    let manifest = Manifest::read(map_path)?;
    if let Some(d) = sim {
        // The truth is in the frame of the map the dataset was simulated on.
        let simulated_on = crate::tiles::FileRef::of(&d.map_path, "")?;
        if (simulated_on.bytes, simulated_on.crc32) != (manifest.map.bytes, manifest.map.crc32) {
            return Err(LocalizeError::Dataset {
                path: map_path.to_path_buf(),
                message: format!(
                    "tiled from {}, but {} was simulated on {} (another file): its true poses are in that map's frame",
                    manifest.map.path,
                    job.dataset.display(),
                    d.map_path.display()
                ),
            });
        }
    }
    let frame = crate::tiles::read_crop(&crate::tiles::resolve(
        map_path,
        &manifest
            .tiles
            .first()
            .ok_or_else(|| LocalizeError::Dataset {
                path: map_path.to_path_buf(),
                message: "the manifest lists no tile".into(),
            })?
            .crop,
    ))?;
    let load_map_s = t.elapsed().as_secs_f64();
    let cores = manifest.tiles.iter().map(|t| t.core_m).reduce(|a, b| {
        [
            a[0].min(b[0]),
            a[1].min(b[1]),
            a[2].max(b[2]),
            a[3].max(b[3]),
        ]
    });
    let real = sim.is_none().then(|| real_sequence(&job.dataset)).flatten();
    let mcd = real_eval_scans(job, real, &frame, map_path, cores)?;
    let picked = picked_scans(job, sim.map_or(mcd.len(), |d| d.truth.len()))?;
    let count = picked.len();
    let mut scans = Vec::with_capacity(count);
    let mut extracted = Vec::with_capacity(count);
    for &i in &picked {
        let scan = load_scan(job, sim, &mcd, i)?;
        let e = crate::pipeline::scan_segments(&job.options, &scan.points)
            .context_with(|| format!("extracting walls from {}", scan.name))?;
        extracted.push((e, scan.points.len()));
        scans.push((scan.name, scan.truth));
    }
    let segments: Vec<Vec<crate::Segment>> =
        extracted.iter().map(|(e, _)| e.segments.clone()).collect();
    let along: Vec<bool> = extracted
        .iter()
        .map(|(e, _)| job.options.vehicle.along_streets(e.sensor.as_ref()))
        .collect();
    let batch = localize_tiled_batch(
        map_path,
        &segments,
        &along,
        &job.options,
        &MINIMUM_CAPS_M,
        None,
        progress,
    )?;
    let exact = batch.exact.iter().filter(|&&e| e).count();
    let mut records = Vec::with_capacity(count);
    for (((name, truth), (e, points)), mut result) in
        scans.into_iter().zip(extracted).zip(batch.results)
    {
        result.seconds.total = result.seconds.search;
        result.record_scan(&e, points);
        let rec = ScanOutcome::new(name, truth, result, Vec::new(), 0.0);
        on_scan(&rec);
        records.push(rec);
    }
    let mut report = EvalReport::new(
        EvalSetup {
            dataset: job.dataset.display().to_string(),
            map: map_path.display().to_string(),
            methods: job.methods.clone(),
            facts: MapFacts::of_manifest(&manifest),
            load_map_seconds: load_map_s,
            hashing_index_seconds: 0.0,
            distractors: None,
            track: None,
        },
        &records,
    );
    report.tiled_exact_scans = Some(exact);
    Ok(report)
}
