//! Extraction quality on labelled scans (real: KITTI-360, MCD; or a simulated `localization`
//! dataset of any sensor and city, read as a [`LidarSequence`]): how much of the extracted
//! wall segment length lies on building points, and how much of the seen façades a segment
//! covers.
//!
//! Each scan is levelled with its dataset pose (roll and pitch removed, heading kept at zero:
//! the frame the localizer sees) and its points keep their classes (`gt_labels`). Measures,
//! in the ground plane, within the extraction's range ring:
//!
//! - **precision**: segments are sampled every 0.1 m; a sample is on a building when a
//!   building-labelled point lies in a 0.25 m cell within two cells of it (≤ 0.5–0.75 m);
//!   otherwise it is charged to the most frequent class of the other labelled points there
//!   (ground classes left out). Samples amid unlabelled points only (KITTI-360 leaves 10–40 %
//!   of the points above the sensor beyond 20 m unlabelled) cannot be judged: precision =
//!   on-building length / judged length (on-building + charged to a class), summed over the
//!   scans; `precision_all` counts the unjudged length as wrong.
//! - **recall**: the façade is the set of 0.5 m cells holding ≥ 3 building-labelled points; a
//!   cell is covered when the centroid of its building points is within 0.75 m of a segment;
//!   recall = covered cells / façade cells, summed over the scans.
//!
//! Cost per scan O(n) in the points plus O(c · s) for c façade cells and s segments.

use crate::segments::{extract_segments, SegmentOptions};
use crate::sensor::{extraction_options, resolve, SensorKind, SensorReport};
use crate::surfaces::{vertical_cells, SurfaceOptions};
use crate::{LocalizeError, Result, Segment};
use geodata::classes::Class;
use geodata::datasets::{LidarSequence, Scan};
use nalgebra::{Rotation3, Vector3};
use rayon::prelude::*;
use rustc_hash::{FxHashMap, FxHashSet};
use serde::Serialize;
use std::path::Path;

pub use geodata::datasets::SequenceKind;

/// One levelled real scan with a class per point.
#[derive(Debug, Clone)]
pub struct LabelledScan {
    /// Frame number, zero-padded as in the file name.
    pub name: String,
    /// Points in the gravity-levelled sensor frame (heading zero), metres.
    pub points: Vec<[f64; 3]>,
    /// Class of each point (`Unlabelled` when the scan has no labels).
    pub classes: Vec<Class>,
}

/// The points of a scan rotated by its pose's roll and pitch (the heading is kept at zero).
pub fn levelled(scan: &Scan) -> Vec<[f64; 3]> {
    let r = scan.world_from_sensor.rotation;
    let x = r * Vector3::x();
    let unturn = Rotation3::from_axis_angle(&Vector3::z_axis(), -x.y.atan2(x.x));
    let m = (unturn * r.to_rotation_matrix()).into_inner();
    scan.cloud
        .positions
        .iter()
        .map(|p| {
            let v = m * Vector3::new(p[0], p[1], p[2]);
            [v.x, v.y, v.z]
        })
        .collect()
}

/// A labelled real sequence folder (KITTI-360 or MCD), opened.
pub fn open_labelled(dir: &Path) -> Result<(SequenceKind, Box<dyn LidarSequence>)> {
    let not_labelled = || LocalizeError::Dataset {
        path: dir.to_path_buf(),
        message: "neither a KITTI-360 sequence (velodyne_points/) nor an MCD one (pose_inW.csv)"
            .into(),
    };
    let kind = SequenceKind::of(dir).ok_or_else(not_labelled)?;
    let seq = kind.open(dir)?;
    if !seq.labelled() {
        return Err(not_labelled());
    }
    Ok((kind, seq))
}

/// Every `stride`-th scan of a labelled sequence (KITTI-360 or MCD), levelled, with classes.
pub fn labelled_scans(dir: &Path, stride: usize) -> Result<(SequenceKind, Vec<LabelledScan>)> {
    let (kind, seq) = open_labelled(dir)?;
    Ok((kind, labelled_scans_of(seq.as_ref(), stride, false)?))
}

/// Every `stride`-th scan of a labelled sequence of any layout (a simulated `localization`
/// dataset included), with classes: levelled by its pose, or `as_recorded` in the sensor's
/// own frame (as a user's raw frames arrive).
pub fn labelled_scans_of(
    seq: &dyn LidarSequence,
    stride: usize,
    as_recorded: bool,
) -> Result<Vec<LabelledScan>> {
    if !seq.labelled() {
        return Err(LocalizeError::Dataset {
            path: seq.dir().to_path_buf(),
            message: format!("the {} sequence has no per-point labels", seq.name()),
        });
    }
    let frames: Vec<u64> = seq.frames()?.into_iter().step_by(stride.max(1)).collect();
    frames
        .par_iter()
        .map(|&f| {
            let scan = seq.load_scan(f)?;
            let classes = (0..scan.cloud.len()).map(|i| scan.cloud.class(i)).collect();
            Ok(LabelledScan {
                name: format!("{f:010}"),
                points: if as_recorded {
                    scan.cloud.positions.clone()
                } else {
                    levelled(&scan)
                },
                classes,
            })
        })
        .collect()
}

/// Extraction quality of one scan.
#[derive(Debug, Clone, Serialize)]
pub struct ScanScore {
    /// Frame number.
    pub scan: String,
    /// The sensor it was processed as.
    pub sensor: SensorReport,
    /// Wall clearance used, metres.
    pub clearance_m: f64,
    /// Vertical-surface cells.
    pub vertical_cells: usize,
    /// Segments extracted.
    pub segments: usize,
    /// Their total length, metres.
    pub segment_m: f64,
    /// Length of it on building points, metres.
    pub on_building_m: f64,
    /// Length off buildings by the class around it, metres (class name → metres).
    pub off_building_m: Vec<(&'static str, f64)>,
    /// Façade cells (0.5 m) seen in range.
    pub facade_cells: usize,
    /// Façade cells within 0.75 m of a segment.
    pub covered_cells: usize,
}

/// Extraction quality over a sequence.
#[derive(Debug, Clone, Serialize)]
pub struct ExtractEval {
    /// Layout of the sequence.
    pub kind: &'static str,
    /// Scans evaluated.
    pub scans: usize,
    /// Share of the judged segment length on building points.
    pub precision: f64,
    /// Share of all segment length on building points (unjudged length counted as wrong).
    pub precision_all: f64,
    /// Share of segment length amid unlabelled points only.
    pub unjudged: f64,
    /// Share of façade cells covered by a segment.
    pub recall: f64,
    /// Mean number of segments per scan.
    pub segments_per_scan: f64,
    /// Segment length off buildings by the class around it, summed, metres.
    pub off_building_m: Vec<(&'static str, f64)>,
    /// Sensor profiles the scans were processed as, with counts.
    pub profiles: Vec<(String, usize)>,
    /// Per-scan numbers.
    pub per_scan: Vec<ScanScore>,
}

/// Cell of the building-occupancy grid of the precision test, metres.
const OCC_CELL_M: f64 = 0.25;
/// Cells around a sample searched for a building point.
const OCC_REACH: i32 = 2;
/// Sampling step along a segment, metres.
const SAMPLE_M: f64 = 0.1;
/// Cell of the façade grid of the recall test, metres.
const FACADE_CELL_M: f64 = 0.5;
/// Fewest building points of a façade cell.
const FACADE_MIN_POINTS: usize = 3;
/// Largest distance from a façade cell's centroid to a covering segment, metres.
const COVER_M: f64 = 0.75;

/// Segment length and façade coverage of one scan.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct SegmentScore {
    /// Total segment length, metres.
    pub segment_m: f64,
    /// Length on building points, metres.
    pub on_building_m: f64,
    /// Length off buildings by the most frequent class of the labelled points around it
    /// (index = class id; `Unlabelled` also takes samples with no point near), metres.
    pub off_building_m: [f64; Class::COUNT],
    /// Façade cells.
    pub facade_cells: usize,
    /// Façade cells within 0.75 m of a segment.
    pub covered_cells: usize,
}

/// Scores extracted segments against a scan's building-labelled points within `[r_min, r_max]`.
pub fn score_segments(
    scan: &LabelledScan,
    segments: &[Segment],
    r_min: f64,
    r_max: f64,
) -> SegmentScore {
    let mut occupied: FxHashSet<[i32; 2]> = FxHashSet::default();
    let mut facade: FxHashMap<[i32; 2], (usize, [f64; 2])> = FxHashMap::default();
    let mut others: FxHashMap<[i32; 2], [u32; Class::COUNT]> = FxHashMap::default();
    for (p, c) in scan.points.iter().zip(&scan.classes) {
        let r = p[0].hypot(p[1]);
        if !p.iter().all(|v| v.is_finite()) {
            continue;
        }
        if *c != Class::Building {
            if !matches!(c, Class::Street | Class::Sidewalk | Class::Grass) {
                let k = [
                    (p[0] / OCC_CELL_M).floor() as i32,
                    (p[1] / OCC_CELL_M).floor() as i32,
                ];
                others.entry(k).or_insert([0; Class::COUNT])[c.id() as usize] += 1;
            }
            continue;
        }
        occupied.insert([
            (p[0] / OCC_CELL_M).floor() as i32,
            (p[1] / OCC_CELL_M).floor() as i32,
        ]);
        if (r_min..=r_max).contains(&r) {
            let e = facade
                .entry([
                    (p[0] / FACADE_CELL_M).floor() as i32,
                    (p[1] / FACADE_CELL_M).floor() as i32,
                ])
                .or_insert((0, [0.0; 2]));
            e.0 += 1;
            e.1[0] += p[0];
            e.1[1] += p[1];
        }
    }
    let near_building = |q: [f64; 2]| {
        let k = [
            (q[0] / OCC_CELL_M).floor() as i32,
            (q[1] / OCC_CELL_M).floor() as i32,
        ];
        (-OCC_REACH..=OCC_REACH)
            .any(|dx| (-OCC_REACH..=OCC_REACH).any(|dy| occupied.contains(&[k[0] + dx, k[1] + dy])))
    };
    let near_class = |q: [f64; 2]| {
        let k = [
            (q[0] / OCC_CELL_M).floor() as i32,
            (q[1] / OCC_CELL_M).floor() as i32,
        ];
        let mut sum = [0u32; Class::COUNT];
        for dx in -OCC_REACH..=OCC_REACH {
            for dy in -OCC_REACH..=OCC_REACH {
                if let Some(c) = others.get(&[k[0] + dx, k[1] + dy]) {
                    for (s, n) in sum.iter_mut().zip(c) {
                        *s += n;
                    }
                }
            }
        }
        // Most points, lowest id on a tie; none near: Unlabelled (id 0).
        (0..Class::COUNT)
            .rev()
            .max_by_key(|&i| sum[i])
            .filter(|&i| sum[i] > 0)
            .unwrap_or(0)
    };
    let mut out = SegmentScore::default();
    for s in segments {
        let len = s.length();
        let n = (len / SAMPLE_M).ceil().max(1.0) as usize;
        let step = len / n as f64;
        for i in 0..n {
            let t = (i as f64 + 0.5) / n as f64;
            let q = [
                s.a[0] + t * (s.b[0] - s.a[0]),
                s.a[1] + t * (s.b[1] - s.a[1]),
            ];
            out.segment_m += step;
            if near_building(q) {
                out.on_building_m += step;
            } else {
                out.off_building_m[near_class(q)] += step;
            }
        }
    }
    for (n, sum) in facade.values() {
        if *n < FACADE_MIN_POINTS {
            continue;
        }
        out.facade_cells += 1;
        let c = [sum[0] / *n as f64, sum[1] / *n as f64];
        if segments.iter().any(|s| s.distance_to(c) <= COVER_M) {
            out.covered_cells += 1;
        }
    }
    out
}

/// Runs the extraction on every scan (sensor named or detected, options adjusted by
/// `adjust`) and scores it.
pub fn evaluate(
    kind: SequenceKind,
    scans: &[LabelledScan],
    sensor: Option<SensorKind>,
    adjust: &(dyn Fn(&mut SurfaceOptions, &mut SegmentOptions) + Sync),
) -> Result<ExtractEval> {
    evaluate_layout(kind.name(), scans, sensor, adjust)
}

/// [`evaluate`] for scans of a sequence whose layout is named `layout` (reported as `kind`).
pub fn evaluate_layout(
    layout: &'static str,
    scans: &[LabelledScan],
    sensor: Option<SensorKind>,
    adjust: &(dyn Fn(&mut SurfaceOptions, &mut SegmentOptions) + Sync),
) -> Result<ExtractEval> {
    let per_scan = scans
        .par_iter()
        .map(|scan| {
            let report = resolve(sensor, &scan.points);
            let (mut so, mut seg) = extraction_options(&report.geometry);
            adjust(&mut so, &mut seg);
            let cells = vertical_cells(&scan.points, &so)?;
            let segments = extract_segments(&cells, &seg);
            let score = score_segments(scan, &segments, so.min_range_m, so.max_range_m);
            Ok(ScanScore {
                scan: scan.name.clone(),
                sensor: report,
                clearance_m: so.clearance_m,
                vertical_cells: cells.len(),
                segments: segments.len(),
                segment_m: score.segment_m,
                on_building_m: score.on_building_m,
                off_building_m: off_by_name(&score.off_building_m),
                facade_cells: score.facade_cells,
                covered_cells: score.covered_cells,
            })
        })
        .collect::<Result<Vec<ScanScore>>>()?;
    let sum = |f: &dyn Fn(&ScanScore) -> f64| per_scan.iter().map(f).sum::<f64>();
    let segment_m = sum(&|s| s.segment_m);
    let facade = sum(&|s| s.facade_cells as f64);
    let on = sum(&|s| s.on_building_m);
    let ratio = |a: f64, b: f64| if b > 0.0 { a / b } else { 0.0 };
    let mut off = [0.0; Class::COUNT];
    for s in &per_scan {
        for (name, m) in &s.off_building_m {
            if let Some(c) = Class::ALL.iter().find(|c| c.name() == *name) {
                off[c.id() as usize] += m;
            }
        }
    }
    let unjudged = off[Class::Unlabelled.id() as usize];
    let mut profiles: Vec<(String, usize)> = Vec::new();
    for s in &per_scan {
        match profiles.iter_mut().find(|(p, _)| p == s.sensor.profile) {
            Some(e) => e.1 += 1,
            None => profiles.push((s.sensor.profile.to_string(), 1)),
        }
    }
    Ok(ExtractEval {
        kind: layout,
        scans: per_scan.len(),
        precision: ratio(on, segment_m - unjudged),
        precision_all: ratio(on, segment_m),
        unjudged: ratio(unjudged, segment_m),
        recall: if facade > 0.0 {
            sum(&|s| s.covered_cells as f64) / facade
        } else {
            0.0
        },
        segments_per_scan: sum(&|s| s.segments as f64) / per_scan.len().max(1) as f64,
        off_building_m: off_by_name(&off),
        profiles,
        per_scan,
    })
}

/// Non-zero entries as (class name, metres), largest first.
fn off_by_name(m: &[f64; Class::COUNT]) -> Vec<(&'static str, f64)> {
    let mut v: Vec<(&'static str, f64)> = Class::ALL
        .iter()
        .map(|c| (c.name(), m[c.id() as usize]))
        .filter(|(_, x)| *x > 0.0)
        .collect();
    v.sort_by(|a, b| b.1.total_cmp(&a.1));
    v
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn scores_a_segment_on_and_off_a_labelled_wall() {
        // A building wall x = 10, y ∈ [0, 10], z ∈ [0, 5], and a car-labelled wall x = -10.
        let mut scan = LabelledScan {
            name: "t".into(),
            points: Vec::new(),
            classes: Vec::new(),
        };
        for i in 0..100 {
            for k in 0..20 {
                let (y, z) = (i as f64 * 0.1, k as f64 * 0.25);
                scan.points.push([10.0, y, z]);
                scan.classes.push(Class::Building);
                scan.points.push([-10.0, y, z]);
                scan.classes.push(Class::Car);
            }
        }
        let on = Segment::new([10.0, 0.0], [10.0, 5.0]);
        let off = Segment::new([-10.0, 0.0], [-10.0, 5.0]);
        let s = score_segments(&scan, &[on, off], 1.0, 75.0);
        assert!((s.segment_m - 10.0).abs() < 1e-9);
        assert!((s.on_building_m - 5.0).abs() < 1e-9, "{s:?}");
        assert!(
            (s.off_building_m[Class::Car.id() as usize] - 5.0).abs() < 1e-9,
            "{s:?}"
        );
        assert_eq!(s.facade_cells, 20);
        assert!((10..=12).contains(&s.covered_cells), "{s:?}");
    }

    #[test]
    fn not_a_sequence_is_a_clear_error() {
        let err = labelled_scans(Path::new("/nonexistent/seq"), 1).unwrap_err();
        assert!(err.to_string().contains("/nonexistent/seq"), "{err}");
    }
}
