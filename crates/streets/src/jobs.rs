//! The evaluations of `urbansem streets` as library calls: load, evaluate, write the
//! per-segment file, return the report (the binary prints it, Python returns it).

use crate::dataset::StreetsDataset;
use crate::eval::{evaluate, EvalOptions, EvalReport, SegmentGeometry};
use crate::kitti::{evaluate_bins, train_test_bins, KittiReport};
use crate::model::ClassifierOptions;
use crate::real::{load_sequence, RealEvalReport, TruthOptions};
use crate::Result;
use geodata::context::WithContext;
use std::path::Path;
use std::time::Instant;

/// Writes `value` as pretty JSON to `path`.
fn write_json(path: &Path, value: &impl serde::Serialize) -> Result<()> {
    let bytes =
        serde_json::to_vec_pretty(value).context(|| format!("serialising {}", path.display()))?;
    geodata::fsio::write_atomic(path, bytes).context(|| format!("writing {}", path.display()))?;
    Ok(())
}

/// Loads a simulated streets dataset with its name in the error.
pub fn load_dataset(dir: &Path) -> Result<StreetsDataset> {
    Ok(StreetsDataset::load(dir)
        .context(|| format!("loading the streets dataset {}", dir.display()))?)
}

/// `streets eval`: the Table 4.1 evaluation of a simulated dataset; the per-segment
/// geometries also written to `segments_out` when given.
pub fn eval_dataset(
    dataset: &Path,
    options: &EvalOptions,
    segments_out: Option<&Path>,
) -> Result<EvalReport> {
    let t = Instant::now();
    let ds = load_dataset(dataset)?;
    let load_s = t.elapsed().as_secs_f64();
    let mut report =
        evaluate(&ds, options).context(|| format!("evaluating {}", dataset.display()))?;
    report.seconds.insert("load".into(), load_s);
    if let Some(p) = segments_out {
        write_json(p, &report.geometries)?;
    }
    Ok(report)
}

/// [`load_sequence`] with the sequence and the map named in its error.
fn load_real(
    dataset: &Path,
    map: &Path,
    corridor: &crate::corridor::CorridorOptions,
    truth: &TruthOptions,
    progress: &dyn Fn(usize, usize),
) -> Result<crate::real::RealDataset> {
    Ok(
        load_sequence(dataset, map, corridor, truth, progress).context(|| {
            format!(
                "reading the sequence {} with the map {}",
                dataset.display(),
                map.display()
            )
        })?,
    )
}

/// `streets eval-real`: a labelled real sequence registered by its poses on `map`, the truth
/// derived from its labels, and the Table 4.1 evaluation; the per-segment rows (truth, and
/// estimate once evaluated) written to `segments_out` when given — before the evaluation too,
/// so that a sequence too poorly observed to evaluate can still be inspected.
pub fn eval_real(
    dataset: &Path,
    map: &Path,
    options: &EvalOptions,
    segments_out: Option<&Path>,
    progress: &dyn Fn(usize, usize),
) -> Result<RealEvalReport> {
    let truth_options = TruthOptions::default();
    let t = Instant::now();
    let real = load_real(
        dataset,
        map,
        &options.geometry.corridor,
        &truth_options,
        progress,
    )?;
    let load_s = t.elapsed().as_secs_f64();
    let write_segments = |geometries: Option<&Vec<SegmentGeometry>>| match segments_out {
        Some(p) => write_json(p, &real.segment_rows(geometries.map(Vec::as_slice))),
        None => Ok(()),
    };
    write_segments(None)?;
    real.check_evaluable(dataset, map, options.folds, &truth_options)?;
    let mut report = evaluate(&real.dataset, options)
        .context(|| format!("evaluating {} on {}", dataset.display(), map.display()))?;
    report.seconds.insert("load_and_truth".into(), load_s);
    write_segments(report.geometries.get("driving_area"))?;
    Ok(RealEvalReport::new(&real, report, truth_options))
}

/// `streets kitti`: the bin classifier trained on the first `train_scans` KITTI-360 scans
/// (and a simulated dataset when given) and scored on the next `test_scans`.
pub fn kitti_eval(
    data: &Path,
    train_scans: usize,
    test_scans: usize,
    sim_dataset: Option<&Path>,
    classifier: &ClassifierOptions,
) -> Result<KittiReport> {
    let t = Instant::now();
    let (train, test) = train_test_bins(data, train_scans, test_scans)
        .context(|| format!("reading KITTI-360 scans from {}", data.display()))?;
    let features_s = t.elapsed().as_secs_f64();
    let sim = sim_dataset.map(load_dataset).transpose()?;
    evaluate_bins(&train, &test, sim.as_ref(), classifier, features_s)
}

/// One passed segment of [`ModelRealReport`].
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct ModelRealRow {
    /// Segment index in the map.
    pub segment: usize,
    /// Centre-line length, metres.
    pub length_m: f64,
    /// Derived true (offset, width), metres; `None`: too poorly observed.
    pub truth_m: Option<(f64, f64)>,
    /// The model's (offset, width), metres; `None`: no usable bins.
    pub estimate_m: Option<(f64, f64)>,
}

/// `streets eval-real --model`: a trained model scored on a labelled real sequence without
/// training on it.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct ModelRealReport {
    /// What the model calls street.
    pub target: crate::model::Target,
    /// Drivable segments the drive passes.
    pub passed: usize,
    /// Passed segments with a derived truth.
    pub with_truth: usize,
    /// Passed segments with a truth and an estimate.
    pub covered: usize,
    /// The bin classifier on the labelled usable bins of the passed segments' corridors (the
    /// "raw" row of Table 4.1).
    pub raw: crate::kitti::Prf,
    /// The same bins' precision, recall and F1 of both classes averaged, weighted by their
    /// bins (as the thesis' Table 4.1 counts them).
    pub raw_weighted: crate::kitti::Prf,
    /// Labelled usable bins scored in `raw`.
    pub raw_bins: usize,
    /// Length-weighted RMSE of the width over the covered segments, metres.
    pub rmse_w: Option<f64>,
    /// Length-weighted RMSE of the offset over the covered segments, metres.
    pub rmse_d: Option<f64>,
    /// Every passed segment.
    pub segments: Vec<ModelRealRow>,
    /// With sidewalk: whether each segment's prior was centred on a driving-area estimate
    /// of the same cloud plus the model's sidewalk margins.
    pub driving_area_prior: bool,
    /// The bin classifier beside the true strips' edges of the segments with a truth, by
    /// band and true class ([`crate::eval::EdgeBand`]).
    pub edges: Vec<crate::eval::EdgeBand>,
    /// Wall time of reading and registering the sequence and of the estimate, seconds.
    pub seconds: std::collections::BTreeMap<String, f64>,
}

/// `streets eval-real --model`: the sequence registered on `map` with its truth derived as
/// for `eval-real`, then `model` estimates every segment from the registered cloud (as
/// `streets estimate` does) and is compared with the truth of the passed segments.
///
/// `self_calibrate` > 0: [`crate::model::StreetModel::estimate_self_calibrated`] with at most
/// that many rounds instead of the plain estimate.
pub fn eval_real_model(
    dataset: &Path,
    map: &Path,
    model: &crate::model::StreetModel,
    driving: Option<&crate::model::StreetModel>,
    self_calibrate: usize,
    progress: &dyn Fn(usize, usize),
) -> Result<ModelRealReport> {
    let truth_options = TruthOptions::default();
    let t = Instant::now();
    let real = load_real(
        dataset,
        map,
        &model.geometry.corridor,
        &truth_options,
        progress,
    )?;
    let mut seconds = std::collections::BTreeMap::new();
    seconds.insert("load_and_truth".to_string(), t.elapsed().as_secs_f64());
    let truths: Vec<Option<(f64, f64)>> = real
        .passed
        .iter()
        .map(|&s| {
            real.observations
                .iter()
                .find(|o| o.segment == s)
                .and_then(|o| match model.target {
                    crate::model::Target::DrivingArea => o.driving_area,
                    crate::model::Target::WithSidewalk => o.with_sidewalk,
                })
                .map(|g| (g.offset_m, g.width_m))
        })
        .collect();
    score_model(
        &real.dataset,
        &real.passed,
        &truths,
        (model, driving),
        self_calibrate,
        (&map.display().to_string(), &dataset.display().to_string()),
        seconds,
    )
}

/// `streets eval --model`: a trained model on a simulated `streets` dataset without training
/// on it; the segments scored are the observed drivable ones, with the simulator's truth.
pub fn eval_dataset_model(
    dir: &Path,
    model: &crate::model::StreetModel,
    driving: Option<&crate::model::StreetModel>,
    self_calibrate: usize,
) -> Result<ModelRealReport> {
    let t = Instant::now();
    let ds = load_dataset(dir)?;
    let mut seconds = std::collections::BTreeMap::new();
    seconds.insert("load".to_string(), t.elapsed().as_secs_f64());
    let which: Vec<usize> = (0..ds.segments.len())
        .filter(|&s| ds.segments[s].drivable && ds.segments[s].observed)
        .collect();
    let truths: Vec<Option<(f64, f64)>> = which
        .iter()
        .map(|&s| {
            let t = &ds.segments[s];
            Some(match model.target {
                crate::model::Target::DrivingArea => (t.offset_m, t.width_m),
                crate::model::Target::WithSidewalk => (
                    t.outer_offset_m.unwrap_or(t.offset_m),
                    t.width_m + 2.0 * t.sidewalk_m,
                ),
            })
        })
        .collect();
    let name = dir.display().to_string();
    score_model(
        &ds,
        &which,
        &truths,
        (model, driving),
        self_calibrate,
        (&ds.map_path.display().to_string(), &name),
        seconds,
    )
}

/// Estimates `ds` with `model` (self-calibrated when `self_calibrate` > 0) and scores the
/// segments `which` against `truths` (one per segment; `None`: no truth). `names`: (map,
/// cloud) for messages. A with-sidewalk model with sidewalk margins and a driving-area
/// model: the driving area is estimated first and centres the with-sidewalk priors, as
/// `streets estimate` does.
fn score_model(
    ds: &StreetsDataset,
    which: &[usize],
    truths: &[Option<(f64, f64)>],
    (model, driving): (
        &crate::model::StreetModel,
        Option<&crate::model::StreetModel>,
    ),
    self_calibrate: usize,
    names: (&str, &str),
    mut seconds: std::collections::BTreeMap<String, f64>,
) -> Result<ModelRealReport> {
    let t = Instant::now();
    let (map_name, cloud_name) = names;
    let (osm, cloud) = (&ds.map, &ds.cloud);
    let driving_area_prior =
        driving.is_some_and(|d| model.driving_model_mismatch(d.target).is_none());
    let est =
        model.estimate_with_driving(driving, osm, cloud, (map_name, cloud_name), self_calibrate)?;
    seconds.insert("estimate".to_string(), t.elapsed().as_secs_f64());
    let (mut predicted, mut truth) = (Vec::new(), Vec::new());
    let bins = crate::model::segment_bins(osm, cloud, which, &model.geometry);
    let grid = model.geometry.theta_grid();
    let mut edges = crate::eval::EdgeCounts::default();
    for (b, segment_truth) in bins.iter().zip(truths) {
        let Some(b) = b else { continue };
        let usable: Vec<usize> = b.usable().collect();
        let labels = model.classifier.predict(&b.usable_rows())?;
        for (&k, &p) in usable.iter().zip(&labels) {
            if let Some(c) = b.features.truth[k] {
                predicted.push(p);
                truth.push(model.target.positive(c));
            }
        }
        if let Some(t) = segment_truth {
            edges.add(b, *t, &labels, &grid);
        }
    }
    let segs = &osm.streets.segments;
    let mut rows = Vec::new();
    let (mut w2, mut d2, mut len) = (0.0, 0.0, 0.0);
    for (&s, &truth) in which.iter().zip(truths) {
        let estimate = est
            .segments
            .iter()
            .find(|e| e.segment == s)
            .map(|e| (e.offset_m, e.width_m));
        if let (Some(tr), Some(es)) = (truth, estimate) {
            let l = segs[s].length_m;
            w2 += l * (es.1 - tr.1).powi(2);
            d2 += l * (es.0 - tr.0).powi(2);
            len += l;
        }
        rows.push(ModelRealRow {
            segment: s,
            length_m: segs[s].length_m,
            truth_m: truth,
            estimate_m: estimate,
        });
    }
    let covered = rows
        .iter()
        .filter(|r| r.truth_m.is_some() && r.estimate_m.is_some())
        .count();
    let raw = crate::kitti::ClassScores::of(&predicted, &truth);
    Ok(ModelRealReport {
        target: model.target,
        passed: which.len(),
        with_truth: rows.iter().filter(|r| r.truth_m.is_some()).count(),
        covered,
        raw: raw.target,
        raw_weighted: raw.weighted,
        raw_bins: truth.len(),
        rmse_w: (len > 0.0).then(|| (w2 / len).sqrt()),
        rmse_d: (len > 0.0).then(|| (d2 / len).sqrt()),
        segments: rows,
        driving_area_prior,
        edges: edges.bands(),
        seconds,
    })
}
