//! The bin classifier on real KITTI-360 scans (`../shared/data/lidar/`): trained on some
//! scans, tested on others (thesis raw F1: driving area 0.81, with sidewalk 0.85). The full
//! numbers (12 training scans) come from `urbansem streets kitti`.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::path::PathBuf;
use streets::kitti::{train_and_test, train_test_bins};
use streets::model::{ClassifierOptions, Target};

fn kitti360_drive_0009() -> PathBuf {
    let p = PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/../../../shared/data"))
        .join("lidar/kitti360_2013_05_28_drive_0009");
    assert!(p.exists(), "missing shared data: {}", p.display());
    p
}

#[test]
fn kitti360_bin_classifier_generalises_to_other_scans() {
    let (train, test) = train_test_bins(&kitti360_drive_0009(), 3, 2).unwrap();
    assert!(
        train.len() > 20_000 && test.len() > 10_000,
        "{} / {}",
        train.len(),
        test.len()
    );
    let options = ClassifierOptions {
        max_train_bins: 1500,
        calibration_bins: 500,
        ..ClassifierOptions::default()
    };
    // Measured 2026-11-26 on this configuration (3 training scans, 2 test scans, 1 500
    // training bins; seeded): F1 0.650 driving area, 0.886 with sidewalk. Pinned 0.05 below.
    for (target, min_f1) in [(Target::DrivingArea, 0.60), (Target::WithSidewalk, 0.83)] {
        let r = train_and_test(&train, &test, target, &options).unwrap();
        eprintln!("{target:?}: {r:?}");
        assert!(r.f1 > min_f1, "{target:?}: {r:?}");
    }
}

#[test]
fn missing_kitti_folder_is_named() {
    let err = train_test_bins(&PathBuf::from("/nonexistent/kitti"), 1, 1).unwrap_err();
    assert!(err.to_string().contains("/nonexistent/kitti"), "{err}");
}
