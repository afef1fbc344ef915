//! The bin classifier across sensors and datasets (issue 17): train on the labelled scans of
//! some sequences (simulated car LiDAR, MCD, KITTI-360, …), test on another's.
//!
//! Every scan is rasterised as in [`crate::kitti::scan_bins`] (0.2 m bins, 40 m × 40 m about
//! the levelled sensor, no colour) with [`FeatureOptions::normalise`] on by default: each
//! scan's geometric, intensity and density features are standardised by their median and
//! inter-quartile range over the scan's observed bins. Without it a classifier trained on
//! simulated HDL-64 scans finds almost no street on real KITTI-360 scans (recall 0.06–0.13:
//! real roads are rougher, cambered and differently reflective than the simulator's), with it
//! the same classifier reaches F1 ≈ 0.65 (README of this crate, "Classifier across datasets").

use crate::features::FeatureOptions;
use crate::kitti::{prf, scan_bins, LabelledBins, Prf};
use crate::model::{BinClassifier, ClassifierOptions, Target};
use crate::{Result, StreetsError};
use geodata::classes::Class;
use geodata::datasets::LidarSequence;
use rayon::prelude::*;
use serde::Serialize;
use std::time::Instant;

/// Labelled bins of one sequence with what they hold.
#[derive(Debug, Clone, Default)]
pub struct SequenceBins {
    /// Where the scans came from (the folder as given).
    pub name: String,
    /// Layout read (`kitti360`, `mcd`, `sim_localization`, …).
    pub layout: String,
    /// Scans read.
    pub scans: usize,
    /// The bins.
    pub bins: LabelledBins,
}

/// One sequence's bins as the report lists them.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SourceSummary {
    /// Where the scans came from.
    pub name: String,
    /// Layout read.
    pub layout: String,
    /// Scans read.
    pub scans: usize,
    /// Labelled ground bins.
    pub bins: usize,
    /// Share of the bins that are street (road, parking).
    pub street_share: f64,
    /// Share of the bins that are sidewalk.
    pub sidewalk_share: f64,
}

impl SequenceBins {
    /// The summary the report lists.
    pub fn summary(&self) -> SourceSummary {
        let n = self.bins.len().max(1) as f64;
        let share = |c: Class| self.bins.truth.iter().filter(|&&t| t == c).count() as f64 / n;
        SourceSummary {
            name: self.name.clone(),
            layout: self.layout.clone(),
            scans: self.scans,
            bins: self.bins.len(),
            street_share: share(Class::Street),
            sidewalk_share: share(Class::Sidewalk),
        }
    }
}

/// Labelled bins of up to `max_scans` evenly spaced scans of a labelled sequence (0: all).
pub fn sequence_bins(
    seq: &dyn LidarSequence,
    name: &str,
    max_scans: usize,
    features: &FeatureOptions,
) -> Result<SequenceBins> {
    let err = |message: String| StreetsError::Dataset {
        path: seq.dir().to_path_buf(),
        message,
    };
    if !seq.labelled() {
        return Err(err(
            "the sequence has no per-point labels; the classifier needs labelled scans".into(),
        ));
    }
    let frames = seq.frames().map_err(|e| err(e.to_string()))?;
    if frames.is_empty() {
        return Err(err("the sequence has no scans".into()));
    }
    let take = if max_scans == 0 {
        frames.len()
    } else {
        max_scans.min(frames.len())
    };
    // Evenly spaced: scan i of `take` is frame ⌊i·len/take⌋.
    let chosen: Vec<u64> = (0..take).map(|i| frames[i * frames.len() / take]).collect();
    let per_scan: Vec<Result<LabelledBins>> = chosen
        .par_iter()
        .map(|&f| {
            let scan = seq.load_scan(f).map_err(|e| err(e.to_string()))?;
            if scan.cloud.label.is_none() {
                return Err(err(format!("scan {} has no labels", scan.path.display())));
            }
            Ok(scan_bins(&scan, features))
        })
        .collect();
    let mut bins = LabelledBins::default();
    for b in per_scan {
        let b = b?;
        bins.x.extend(b.x);
        bins.truth.extend(b.truth);
    }
    Ok(SequenceBins {
        name: name.to_owned(),
        layout: seq.name().to_owned(),
        scans: take,
        bins,
    })
}

/// One target's scores on the test sequence.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct TransferScore {
    /// Precision.
    pub precision: f64,
    /// Recall.
    pub recall: f64,
    /// F1.
    pub f1: f64,
    /// Positive (street) bins among the training bins.
    pub train_positives: usize,
    /// Positive bins among the test bins (0: the scores say nothing).
    pub test_positives: usize,
}

/// `urbansem streets transfer --json`: trained on some sequences, tested on another.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct TransferReport {
    /// The training sequences.
    pub train: Vec<SourceSummary>,
    /// The test sequence.
    pub test: SourceSummary,
    /// Whether the features were standardised per scan.
    pub normalised: bool,
    /// Driving area only; `None` (JSON `null`) when the sampled training bins hold one class.
    pub driving_area: Option<TransferScore>,
    /// Driving area and sidewalk; `None` when the sampled training bins hold one class.
    pub with_sidewalk: Option<TransferScore>,
    /// Seconds spent training and testing (both targets).
    pub seconds: f64,
}

/// Options of [`transfer`].
#[derive(Debug, Clone)]
pub struct TransferOptions {
    /// Scans per training sequence, evenly spaced (0: all).
    pub scans_per_source: usize,
    /// Scans of the test sequence, evenly spaced (0: all).
    pub test_scans: usize,
    /// Standardise the features per scan ([`FeatureOptions::normalise`]).
    pub normalise: bool,
    /// The bin classifier's options.
    pub classifier: ClassifierOptions,
}

/// A labelled sequence with the name the report gives it.
pub type NamedSequence = (String, Box<dyn LidarSequence>);

/// `urbansem streets transfer`: reads the training and test sequences' labelled bins (no
/// colour; standardised per scan unless told otherwise), trains on the former and scores on
/// the latter.
pub fn transfer(
    train: &[NamedSequence],
    test: &NamedSequence,
    options: &TransferOptions,
) -> Result<TransferReport> {
    let features = FeatureOptions {
        colour: false,
        normalise: options.normalise,
        ..Default::default()
    };
    let sources = train
        .iter()
        .map(|(name, seq)| sequence_bins(seq.as_ref(), name, options.scans_per_source, &features))
        .collect::<Result<Vec<_>>>()?;
    let test_bins = sequence_bins(test.1.as_ref(), &test.0, options.test_scans, &features)?;
    transfer_eval(&sources, &test_bins, options.normalise, &options.classifier)
}

/// Trains the bin classifier on the training sequences' bins (one seeded subset of their
/// union, [`ClassifierOptions::max_train_bins`]) and scores both targets on the test bins.
pub fn transfer_eval(
    train: &[SequenceBins],
    test: &SequenceBins,
    normalised: bool,
    options: &ClassifierOptions,
) -> Result<TransferReport> {
    let t = Instant::now();
    let mut x: Vec<f32> = Vec::new();
    let mut truth: Vec<Class> = Vec::new();
    for s in train {
        x.extend_from_slice(&s.bins.x);
        truth.extend_from_slice(&s.bins.truth);
    }
    if truth.is_empty() || test.bins.is_empty() {
        return Err(StreetsError::Dataset {
            path: test.name.clone().into(),
            message: "no labelled ground bins to train or test on".into(),
        });
    }
    let score = |target: Target| -> Result<TransferScore> {
        let y: Vec<bool> = truth.iter().map(|&c| target.positive(c)).collect();
        let clf = BinClassifier::train(&x, &y, options)?;
        let pred = clf.predict(&test.bins.x)?;
        let want: Vec<bool> = test
            .bins
            .truth
            .iter()
            .map(|&c| target.positive(c))
            .collect();
        let Prf {
            precision,
            recall,
            f1,
        } = prf(&pred, &want);
        Ok(TransferScore {
            precision,
            recall,
            f1,
            train_positives: y.iter().filter(|&&v| v).count(),
            test_positives: want.iter().filter(|&&v| v).count(),
        })
    };
    // A target whose training subset holds one class (a campus sequence with no street) is
    // `None` and the other is still scored; when neither can be learnt, the driving area's
    // one-class error.
    let untrained_as_none = |r: Result<TransferScore>| match r {
        Err(StreetsError::OneClass { .. }) => Ok(None),
        r => r.map(Some),
    };
    let (driving_area, with_sidewalk) =
        match (score(Target::DrivingArea), score(Target::WithSidewalk)) {
            (Err(e @ StreetsError::OneClass { .. }), Err(StreetsError::OneClass { .. })) => {
                return Err(e)
            }
            (da, ws) => (untrained_as_none(da)?, untrained_as_none(ws)?),
        };
    Ok(TransferReport {
        train: train.iter().map(SequenceBins::summary).collect(),
        test: test.summary(),
        normalised,
        driving_area,
        with_sidewalk,
        seconds: t.elapsed().as_secs_f64(),
    })
}

impl TransferReport {
    /// The sources and one line of scores per target.
    pub fn text(&self) -> String {
        let line = |s: &SourceSummary| {
            format!(
                "{} ({}, {} scans, {} bins, street {:.2}, sidewalk {:.2})",
                s.name, s.layout, s.scans, s.bins, s.street_share, s.sidewalk_share
            )
        };
        let mut out = String::from("trained on:\n");
        for s in &self.train {
            out += &format!("  {}\n", line(s));
        }
        out += &format!(
            "tested on {}\nfeatures {}\n",
            line(&self.test),
            if self.normalised {
                "standardised per scan"
            } else {
                "raw"
            }
        );
        for (key, s) in [
            ("driving_area", &self.driving_area),
            ("with_sidewalk", &self.with_sidewalk),
        ] {
            let Some(s) = s else {
                out += &format!("  {key:<14} not trained: the training bins hold one class only\n");
                continue;
            };
            let note = if s.test_positives == 0 {
                "  (no positive test bins: the scores say nothing)"
            } else {
                ""
            };
            out += &format!(
                "  {key:<14} P {:.3} R {:.3} F1 {:.3}{note}\n",
                s.precision, s.recall, s.f1
            );
        }
        out
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::expect_used)]
    use super::*;
    use crate::features::FEATURE_DIMS;

    /// Bins of the given classes; the first feature separates the classes.
    fn bins(name: &str, classes: &[Class]) -> SequenceBins {
        let mut x = Vec::new();
        for (i, &c) in classes.iter().enumerate() {
            let mut row = vec![0.0f32; FEATURE_DIMS];
            row[0] = match c {
                Class::Street => -1.0,
                Class::Sidewalk => 0.0,
                _ => 1.0,
            } + (i % 7) as f32 * 0.01;
            x.extend(row);
        }
        SequenceBins {
            name: name.into(),
            layout: "test".into(),
            scans: 1,
            bins: LabelledBins {
                x,
                truth: classes.to_vec(),
            },
        }
    }

    #[test]
    fn a_target_the_training_bins_cannot_teach_is_reported_untrained() {
        let options = ClassifierOptions {
            calibration_bins: 0,
            ..Default::default()
        };
        let mixed = [Class::Street, Class::Sidewalk, Class::Building].repeat(40);
        let test = bins("test", &mixed);
        // A campus: sidewalk and buildings, no street.
        let campus = bins("campus", &[Class::Sidewalk, Class::Building].repeat(40));
        let r = transfer_eval(&[campus], &test, true, &options).unwrap();
        assert_eq!(r.driving_area, None);
        let ws = r.with_sidewalk.unwrap();
        assert!(ws.f1 > 0.9, "{ws:?}");
        assert!(r.text().contains("not trained"), "{}", r.text());
        // Both targets trained on mixed bins.
        let r = transfer_eval(&[bins("mixed", &mixed)], &test, true, &options).unwrap();
        assert!(r.driving_area.unwrap().f1 > 0.9 && r.with_sidewalk.is_some());
        // Nothing to learn for either target: the one-class error.
        let walls = bins("walls", &[Class::Building; 30]);
        let err = transfer_eval(&[walls], &test, true, &options).unwrap_err();
        assert!(matches!(err, StreetsError::OneClass { .. }), "{err}");
    }
}
