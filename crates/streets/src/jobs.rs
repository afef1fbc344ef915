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
    let real = load_sequence(
        dataset,
        map,
        &options.geometry.corridor,
        &truth_options,
        progress,
    )
    .context(|| {
        format!(
            "reading the sequence {} with the map {}",
            dataset.display(),
            map.display()
        )
    })?;
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
