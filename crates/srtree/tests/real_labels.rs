//! Dirichlet label choice against majority vote on a subset of the real labelled scans.

#![allow(clippy::unwrap_used, clippy::expect_used)]

use srtree::label_eval::{evaluate_labels, LabelEvalOptions};
use srtree::scans::{combined_cloud, load_sequences, Sequence};
use std::path::PathBuf;

fn lidar_dir() -> PathBuf {
    let p = PathBuf::from(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../../shared/data/lidar"
    ));
    assert!(p.exists(), "missing shared data: {}", p.display());
    p
}

/// KITTI-360 `2013_05_28_drive_0009` and MCD `kth_day_06`, twelve scans each.
fn twelve_scans_each() -> Vec<Sequence> {
    load_sequences(&lidar_dir(), Some(12)).unwrap()
}

#[test]
fn label_agreement_on_a_subset_is_sane() {
    let seqs = twelve_scans_each();
    assert_eq!(seqs.len(), 2);
    assert!(seqs.iter().all(|s| s.scans.len() == 12));
    let ev = evaluate_labels(&seqs, &LabelEvalOptions::default()).unwrap();
    let t = ev.total;
    assert!(t.cells > 1_000, "{t:?}");
    assert!(t.mixed_cells > 10 && t.mixed_cells < t.cells / 5, "{t:?}");
    // Both choices are right on most cells and agree on every pure cell.
    assert!(t.majority_rate() > 0.8 && t.dirichlet_rate() > 0.8, "{t:?}");
    let pure = t.cells - t.mixed_cells;
    let pure_d = t.dirichlet_agree - t.dirichlet_agree_mixed;
    let pure_m = t.majority_agree - t.majority_agree_mixed;
    assert_eq!(pure_d, pure_m);
    assert!(pure_d as f64 > 0.9 * pure as f64, "{t:?}");
    // Mixed cells are hard for both, but neither is reduced to guessing.
    assert!(
        t.majority_rate_mixed() > 0.3 && t.dirichlet_rate_mixed() > 0.3,
        "{t:?}"
    );
    let per_sequence: usize = ev.sequences.iter().map(|(_, s)| s.cells).sum();
    assert_eq!(per_sequence, t.cells);
}

#[test]
fn scans_are_registered_into_one_frame() {
    let seqs = twelve_scans_each();
    for s in &seqs {
        // The first sensor is the sequence origin; the others moved along the trajectory.
        assert!(s.scans[0].origin_m.iter().all(|v| v.abs() < 1e-6));
        assert!(s
            .scans
            .iter()
            .skip(1)
            .any(|x| x.origin_m[0].hypot(x.origin_m[1]) > 1.0));
    }
    let (cloud, ranges) = combined_cloud(&seqs);
    assert_eq!(
        cloud.len(),
        seqs.iter().map(Sequence::points).sum::<usize>()
    );
    assert_eq!(ranges.len(), 24);
    assert_eq!(ranges.last().map(|r| r.2), Some(cloud.len()));
}

#[test]
fn a_missing_folder_is_named() {
    let e = load_sequences(std::path::Path::new("/nonexistent/lidar"), None).unwrap_err();
    assert!(e.to_string().contains("/nonexistent/lidar"), "{e}");
}
