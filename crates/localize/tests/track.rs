//! Track mode (issue 15) on real scans: MCD `kth_day_06` scans on the KTH campus map, tied by
//! odometry with the drift `localize eval --track` assumes.

#![allow(clippy::unwrap_used, clippy::expect_used)]

use geodata::osm::OsmMap;
use localize::eval::{mcd_scans, Accuracy};
use localize::pipeline::{LocalizeOptions, Localizer};
use localize::track::{
    drifted_odometry, TrackOptions, ODOMETRY_SCALE_DRIFT, ODOMETRY_YAW_DRIFT_DEG_PER_50M,
};
use std::path::PathBuf;

fn data_file(rel: &str) -> PathBuf {
    let p = PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/../../../shared/data")).join(rel);
    assert!(p.exists(), "missing shared data: {}", p.display());
    p
}

/// A scan without walls in the middle of a track (an open square, a blinded sensor) is placed
/// by coasting: the previous scan's states moved by the odometry stay states, so the truth's
/// chain runs through it and the scans after it keep their place. Without coasting that scan
/// has no candidate at all.
#[test]
fn a_scan_without_walls_is_placed_by_the_odometry() {
    let map = OsmMap::load(data_file("osm/kth_campus_stockholm.osm")).unwrap();
    let localizer = Localizer::new(&map, LocalizeOptions::default()).unwrap();
    let scans = mcd_scans(&data_file("lidar/mcd_kth_day_06"), &map, 3).unwrap();
    assert!(scans.len() >= 7, "{} scans", scans.len());
    let truths: Vec<_> = scans.iter().map(|s| s.truth).collect();
    let odometry = drifted_odometry(
        &truths,
        ODOMETRY_SCALE_DRIFT,
        ODOMETRY_YAW_DRIFT_DEG_PER_50M.to_radians() / 50.0,
    );
    let mut extracted: Vec<_> = scans
        .iter()
        .map(|s| localizer.scan_segments(&s.points).unwrap())
        .collect();
    let blind = 5;
    extracted[blind].segments.clear();
    let strict = Accuracy {
        max_m: 2.0,
        max_rad: 3f64.to_radians(),
    };
    let top1_ok = |r: &localize::pipeline::Localization, i: usize| {
        r.candidates
            .first()
            .is_some_and(|c| strict.accepts(&c.pose, &truths[i]))
    };

    let coasting = localizer
        .localize_track(&extracted, &odometry, &TrackOptions::default())
        .unwrap();
    for (i, r) in coasting.iter().enumerate() {
        let err = r.candidates.first().map(|c| {
            (
                c.pose.distance_to(&truths[i]),
                c.pose.yaw_error_to(&truths[i]),
            )
        });
        println!(
            "scan {i}: {} candidates, top-1 error {err:?}",
            r.candidates.len()
        );
    }
    assert!(top1_ok(&coasting[blind], blind));
    assert!(coasting[blind]
        .message
        .as_deref()
        .is_some_and(|m| m.contains("odometry")));
    // Every scan after the first is placed (MCD alone finds 30 of 30).
    let placed = (1..scans.len())
        .filter(|&i| top1_ok(&coasting[i], i))
        .count();
    assert_eq!(placed, scans.len() - 1);

    let without = localizer
        .localize_track(
            &extracted,
            &odometry,
            &TrackOptions {
                coast: false,
                ..Default::default()
            },
        )
        .unwrap();
    assert!(without[blind].candidates.is_empty());

    // A prediction the refinement leaves in place is one state, not two (here every
    // refinement keeps its start: no move is accepted).
    let mut options = LocalizeOptions::default();
    options.refine.max_shift_m = 0.0;
    let stiff = Localizer::new(&map, options).unwrap();
    let results = stiff
        .localize_track(&extracted, &odometry, &TrackOptions::default())
        .unwrap();
    for (i, r) in results.iter().enumerate() {
        for (k, a) in r.candidates.iter().enumerate() {
            for b in &r.candidates[k + 1..] {
                assert!(
                    a.pose.distance_to(&b.pose) > 1e-3 || a.pose.yaw_error_to(&b.pose) > 1e-6,
                    "scan {i} lists {:?} twice",
                    a.pose
                );
            }
        }
    }
}
