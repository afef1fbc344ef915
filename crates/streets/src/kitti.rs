//! The bin classifier on real data: KITTI-360 scans with per-point labels, rasterised into
//! the same 0.2 m bins and features as the corridors (40 m × 40 m around the sensor, the
//! scan levelled by its pose's rotation), trained on some scans and tested on others.

use crate::features::{bin_features, FeatureOptions, FEATURE_DIMS};
use crate::grid::BinGrid;
use crate::model::{BinClassifier, ClassifierOptions, Target};
use crate::{Result, StreetsError};
use geodata::classes::Class;
use geodata::datasets::kitti360::Kitti360Sequence;
use geodata::datasets::Scan;
use nalgebra::{Isometry3, Translation3};
use rayon::prelude::*;
use std::path::Path;

/// Feature rows of labelled bins with their true classes.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct LabelledBins {
    /// Row-major features (`len × FEATURE_DIMS`).
    pub x: Vec<f32>,
    /// True class per bin.
    pub truth: Vec<Class>,
}

impl LabelledBins {
    /// Number of bins.
    pub fn len(&self) -> usize {
        self.truth.len()
    }

    /// Whether there are no bins.
    pub fn is_empty(&self) -> bool {
        self.truth.is_empty()
    }

    fn extend(&mut self, other: LabelledBins) {
        self.x.extend(other.x);
        self.truth.extend(other.truth);
    }
}

/// Per-bin precision, recall and F1.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct Prf {
    /// Precision.
    pub precision: f64,
    /// Recall.
    pub recall: f64,
    /// F1.
    pub f1: f64,
}

/// Per-bin scores of binary predictions: the target class's, and both classes' averaged.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct ClassScores {
    /// The target class's precision, recall and F1.
    pub target: Prf,
    /// Both classes (target, not target) averaged, each weighted by its bins: how the
    /// thesis' Table 4.1 reports them.
    pub weighted: Prf,
    /// Both classes averaged, each weighing the same.
    pub macro_avg: Prf,
    /// Share of the bins labelled correctly.
    pub accuracy: f64,
    /// Share of the bins whose true class is the target.
    pub positive_share: f64,
}

impl ClassScores {
    /// Scores from the counts of true and false positives and negatives.
    pub fn from_counts(tp: u64, fp: u64, fn_: u64, tn: u64) -> ClassScores {
        let pos = Prf::from_counts(tp, fp, fn_);
        // The other class: its true positives are the true negatives.
        let neg = Prf::from_counts(tn, fn_, fp);
        let (n1, n0) = ((tp + fn_) as f64, (tn + fp) as f64);
        let n = (n1 + n0).max(1.0);
        let average = |w1: f64, w0: f64| Prf {
            precision: (w1 * pos.precision + w0 * neg.precision) / (w1 + w0),
            recall: (w1 * pos.recall + w0 * neg.recall) / (w1 + w0),
            f1: (w1 * pos.f1 + w0 * neg.f1) / (w1 + w0),
        };
        ClassScores {
            target: pos,
            weighted: if n1 + n0 > 0.0 {
                average(n1, n0)
            } else {
                average(1.0, 1.0)
            },
            macro_avg: average(1.0, 1.0),
            accuracy: (tp + tn) as f64 / n,
            positive_share: n1 / n,
        }
    }

    /// Scores of predictions against truths.
    pub fn of(predicted: &[bool], truth: &[bool]) -> ClassScores {
        let mut c = [[0u64; 2]; 2];
        for (&p, &t) in predicted.iter().zip(truth) {
            c[usize::from(p)][usize::from(t)] += 1;
        }
        ClassScores::from_counts(c[1][1], c[1][0], c[0][1], c[0][0])
    }
}

/// Precision/recall/F1 of predictions against truths.
pub fn prf(predicted: &[bool], truth: &[bool]) -> Prf {
    ClassScores::of(predicted, truth).target
}

impl Prf {
    /// Precision, recall and F1 of one class from its true positives, false positives and
    /// false negatives (0 where undefined).
    pub fn from_counts(tp: u64, fp: u64, fn_: u64) -> Prf {
        let precision = tp as f64 / (tp + fp).max(1) as f64;
        let recall = tp as f64 / (tp + fn_).max(1) as f64;
        let f1 = if precision + recall > 0.0 {
            2.0 * precision * recall / (precision + recall)
        } else {
            0.0
        };
        Prf {
            precision,
            recall,
            f1,
        }
    }
}

/// Labelled bins of one scan: 200 × 200 bins of 0.2 m centred on the sensor.
pub fn scan_bins(scan: &Scan, options: &FeatureOptions) -> LabelledBins {
    let mut cloud = scan.cloud.clone();
    let level = Isometry3::from_parts(Translation3::identity(), scan.world_from_sensor.rotation);
    cloud.transform(&level);
    let (n, bin) = (200usize, 0.2);
    let half = 0.5 * n as f64 * bin;
    let pairs: Vec<(u32, u32)> = cloud
        .positions
        .iter()
        .enumerate()
        .filter_map(|(i, p)| {
            let (cx, cy) = ((p[0] + half) / bin, (p[1] + half) / bin);
            (cx >= 0.0 && cy >= 0.0 && cx < n as f64 && cy < n as f64)
                .then(|| ((cy as usize * n + cx as usize) as u32, i as u32))
        })
        .collect();
    let grid = BinGrid::from_pairs(n, n, bin, &pairs);
    let f = bin_features(&grid, &cloud, [0.0; 3], options);
    let mut out = LabelledBins::default();
    for k in 0..grid.len() {
        if let (true, Some(c)) = (f.observed[k], f.truth[k]) {
            out.x.extend_from_slice(f.row(k));
            out.truth.push(c);
        }
    }
    out
}

/// Training bins from the first `train_scans` scans and test bins from the next
/// `test_scans` (0: all the rest) of a KITTI-360 sequence folder.
pub fn train_test_bins(
    dir: &Path,
    train_scans: usize,
    test_scans: usize,
) -> Result<(LabelledBins, LabelledBins)> {
    let err = |e: geodata::datasets::DatasetError| StreetsError::Dataset {
        path: dir.to_path_buf(),
        message: e.to_string(),
    };
    let seq = Kitti360Sequence::open(dir).map_err(err)?;
    let frames = seq.frames().map_err(err)?;
    if frames.len() < train_scans + 1 {
        return Err(StreetsError::Dataset {
            path: dir.to_path_buf(),
            message: format!(
                "{} scans, need more than the {train_scans} training scans",
                frames.len()
            ),
        });
    }
    let end = if test_scans == 0 {
        frames.len()
    } else {
        (train_scans + test_scans).min(frames.len())
    };
    let options = FeatureOptions::default();
    let per_scan: Vec<Result<LabelledBins>> = frames[..end]
        .par_iter()
        .map(|&f| Ok(scan_bins(&seq.load_scan(f).map_err(err)?, &options)))
        .collect();
    let mut train = LabelledBins::default();
    let mut test = LabelledBins::default();
    for (k, b) in per_scan.into_iter().enumerate() {
        if k < train_scans {
            train.extend(b?);
        } else {
            test.extend(b?);
        }
    }
    Ok((train, test))
}

/// Trains on `x`/`y` and scores on the test bins for a target.
pub fn train_xy_and_test(
    x: &[f32],
    y: &[bool],
    test: &LabelledBins,
    target: Target,
    options: &ClassifierOptions,
) -> Result<Prf> {
    let clf = BinClassifier::train(x, y, options)?;
    let pred = clf.predict(&test.x)?;
    let truth: Vec<bool> = test.truth.iter().map(|&c| target.positive(c)).collect();
    Ok(prf(&pred, &truth))
}

/// Trains on labelled bins and scores on the test bins for a target.
pub fn train_and_test(
    train: &LabelledBins,
    test: &LabelledBins,
    target: Target,
    options: &ClassifierOptions,
) -> Result<Prf> {
    debug_assert_eq!(train.x.len(), train.len() * FEATURE_DIMS);
    let y: Vec<bool> = train.truth.iter().map(|&c| target.positive(c)).collect();
    train_xy_and_test(&train.x, &y, test, target, options)
}

/// The bin classifier for one target on the KITTI-360 test scans (`streets kitti --json`).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct KittiTargetReport {
    /// Precision.
    pub precision: f64,
    /// Recall.
    pub recall: f64,
    /// F1.
    pub f1: f64,
    /// Training bins.
    pub train_bins: usize,
    /// Test bins.
    pub test_bins: usize,
    /// Seconds spent training and testing.
    pub seconds: f64,
    /// Scores of the classifier trained on a simulated dataset instead.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub sim_to_kitti: Option<Prf>,
}

/// The bin classifier for both targets on KITTI-360 scans (`streets kitti --json`).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct KittiReport {
    /// Driving area only.
    pub driving_area: KittiTargetReport,
    /// Driving area and sidewalk.
    pub with_sidewalk: KittiTargetReport,
    /// Seconds spent computing the bins' features.
    pub features_seconds: f64,
}

/// Trains on the training scans' bins (and, given `sim`, on a simulated dataset's bins
/// without colour) and scores both targets on the test scans' bins.
pub fn evaluate_bins(
    train: &LabelledBins,
    test: &LabelledBins,
    sim: Option<&crate::dataset::StreetsDataset>,
    options: &ClassifierOptions,
    features_seconds: f64,
) -> Result<KittiReport> {
    let score = |target: Target| -> Result<KittiTargetReport> {
        let t = std::time::Instant::now();
        let r = train_and_test(train, test, target, options)?;
        let sim_to_kitti = match sim {
            None => None,
            Some(ds) => {
                let geometry = crate::model::GeometryOptions {
                    features: FeatureOptions {
                        colour: false,
                        ..Default::default()
                    },
                    ..crate::model::GeometryOptions::default()
                };
                let bins = crate::model::dataset_bins(ds, &geometry, target);
                Some(train_xy_and_test(
                    &bins.features,
                    &bins.labels,
                    test,
                    target,
                    options,
                )?)
            }
        };
        Ok(KittiTargetReport {
            precision: r.precision,
            recall: r.recall,
            f1: r.f1,
            train_bins: train.len(),
            test_bins: test.len(),
            seconds: t.elapsed().as_secs_f64(),
            sim_to_kitti,
        })
    };
    Ok(KittiReport {
        driving_area: score(Target::DrivingArea)?,
        with_sidewalk: score(Target::WithSidewalk)?,
        features_seconds,
    })
}

impl KittiReport {
    /// The bin counts and one line of scores per target (`data`: the sequence folder).
    pub fn text(&self, data: &Path) -> String {
        let mut s = format!(
            "KITTI-360 {}: {} training bins, {} test bins (thesis raw F1: driving area 0.81, with sidewalk 0.85)\n",
            data.display(),
            self.driving_area.train_bins,
            self.driving_area.test_bins
        );
        for (key, e) in [
            ("driving_area", &self.driving_area),
            ("with_sidewalk", &self.with_sidewalk),
        ] {
            let sim = match e.sim_to_kitti {
                Some(r) => format!(
                    "   | trained on simulation: P {:.3} R {:.3} F1 {:.3}",
                    r.precision, r.recall, r.f1
                ),
                None => String::new(),
            };
            s += &format!(
                "  {key:<14} P {:.3} R {:.3} F1 {:.3}{sim}\n",
                e.precision, e.recall, e.f1
            );
        }
        s
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    fn target(sim: Option<Prf>) -> KittiTargetReport {
        KittiTargetReport {
            precision: 0.5,
            recall: 0.25,
            f1: 1.0 / 3.0,
            train_bins: 10,
            test_bins: 20,
            seconds: 0.0,
            sim_to_kitti: sim,
        }
    }

    #[test]
    fn the_simulation_column_appears_only_when_trained_on_simulation() {
        let sim = Prf {
            precision: 1.0,
            recall: 0.5,
            f1: 2.0 / 3.0,
        };
        let report = KittiReport {
            driving_area: target(None),
            with_sidewalk: target(Some(sim)),
            features_seconds: 0.0,
        };
        assert_eq!(
            report.text(Path::new("seq")),
            "KITTI-360 seq: 10 training bins, 20 test bins (thesis raw F1: driving area 0.81, with sidewalk 0.85)\n\
             \x20 driving_area   P 0.500 R 0.250 F1 0.333\n\
             \x20 with_sidewalk  P 0.500 R 0.250 F1 0.333   | trained on simulation: P 1.000 R 0.500 F1 0.667\n"
        );
        let json = serde_json::to_value(report).unwrap();
        assert!(json["driving_area"].get("sim_to_kitti").is_none());
        assert_eq!(json["with_sidewalk"]["sim_to_kitti"]["precision"], 1.0);
    }
}
