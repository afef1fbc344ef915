//! Real labelled sequences as `streets` datasets: the scans registered by their poses into
//! the map's local frame, and each segment's true geometry derived from the labelled points
//! (issue 17, the Table 4.1 analogue on real scans).
//!
//! # How the truth is derived
//! A segment's corridor (the same 40 m × 0.2 m bins and intersection/neighbour masks as the
//! estimation) is cut into slices of [`TruthOptions::slice_m`] along the segment. In a slice,
//! each 0.2 m column across the street is
//! - *street* when at least [`TruthOptions::min_points`] of its labelled points are of the
//!   target's classes (road and parking; plus sidewalk for the second target) and they are at
//!   least as many as the boundary points,
//! - *boundary* when at least `min_points` points are of a class that ends the street: for the
//!   driving area sidewalk (kerbs included), terrain, building or other (walls, fences…); for
//!   the driving area with sidewalk terrain, building and other,
//! - *unknown* otherwise: no points, masked, or only cars, trees, poles, bicycles or
//!   unlabelled points (a parked car hides the road under it but does not end it).
//!
//! From the street column nearest the OSM centre line (within [`TruthOptions::search_m`]) the
//! slice walks outwards on both sides through street and unknown columns; an edge is
//! *observed* where a boundary column follows the last street column within
//! [`TruthOptions::max_gap_m`], and the edge lies at that street column's outer border. A
//! slice whose two edges are observed gives (left, right). The segment's truth is the median
//! left and median right edge over those slices: offset = their mean, width = their
//! difference. A segment is too poorly observed to have a truth when fewer than
//! [`TruthOptions::min_slices`] slices, or fewer than [`TruthOptions::min_fraction`] of its
//! unmasked slices, have both edges.

use crate::corridor::{map_corridors, Corridor, CorridorOptions};
use crate::dataset::{SegmentTruth, StreetsDataset};
use crate::eval::{EvalReport, SegmentGeometry};
use crate::model::Target;
use crate::{Result, StreetsError};
use geodata::classes::Class;
use geodata::cloud::PointCloud;
use geodata::osm::OsmMap;
use serde::Serialize;
use std::path::{Path, PathBuf};

/// Options of the truth derivation.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct TruthOptions {
    /// Slice length along the segment, metres.
    pub slice_m: f64,
    /// Labelled points a column needs to count as street or boundary.
    pub min_points: usize,
    /// Farthest the first street column may lie from the OSM centre line, metres.
    pub search_m: f64,
    /// Longest run of unknown columns between the last street column and the boundary,
    /// metres (a parked car is about 2 m wide).
    pub max_gap_m: f64,
    /// Slices with both edges a segment needs for a truth.
    pub min_slices: usize,
    /// Share of the segment's unmasked slices that must have both edges.
    pub min_fraction: f64,
}

impl Default for TruthOptions {
    fn default() -> Self {
        TruthOptions {
            slice_m: 1.0,
            min_points: 2,
            search_m: 8.0,
            max_gap_m: 3.0,
            min_slices: 5,
            min_fraction: 0.25,
        }
    }
}

/// A derived (offset, width) of one target with its support.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct DerivedGeometry {
    /// Offset of the centre from the OSM centre line, left of a→b positive, metres.
    pub offset_m: f64,
    /// Width, metres.
    pub width_m: f64,
    /// Slices with both edges observed.
    pub slices: usize,
}

/// How well one segment was observed, and its derived truth per target.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SegmentObservation {
    /// Segment index in the map.
    pub segment: usize,
    /// Slices with at least one unmasked bin.
    pub slices: usize,
    /// Labelled points in the segment's unmasked bins.
    pub points: usize,
    /// Driving-area truth (`None`: too poorly observed).
    pub driving_area: Option<DerivedGeometry>,
    /// Driving area with sidewalk (`None`: too poorly observed).
    pub with_sidewalk: Option<DerivedGeometry>,
}

/// Column state in a slice.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Column {
    Street,
    Boundary,
    Unknown,
}

/// Whether a class is street (`Some(true)`), ends the street (`Some(false)`) or says nothing
/// about where the street ends (`None`), for a target.
fn role(target: Target, class: Class) -> Option<bool> {
    match class {
        Class::Street => Some(true),
        Class::Sidewalk => Some(target == Target::WithSidewalk),
        Class::Grass | Class::Building | Class::Other => Some(false),
        Class::Car | Class::Tree | Class::Pole | Class::Bicycle | Class::Unlabelled => None,
    }
}

/// The edges (left u, right u) of one slice, when both are observed.
fn slice_edges(columns: &[Column], bin_m: f64, options: &TruthOptions) -> Option<(f64, f64)> {
    let cols = columns.len();
    let half = 0.5 * cols as f64 * bin_m;
    let centre = cols as f64 / 2.0;
    let reach = (options.search_m / bin_m).round() as usize;
    // The street column nearest the centre line.
    let start = (0..cols)
        .filter(|&c| columns[c] == Column::Street)
        .min_by(|&a, &b| {
            ((a as f64 + 0.5) - centre)
                .abs()
                .total_cmp(&((b as f64 + 0.5) - centre).abs())
        })
        .filter(|&c| ((c as f64 + 0.5) - centre).abs() <= reach as f64)?;
    let gap = (options.max_gap_m / bin_m).round() as usize;
    let walk = |order: &mut dyn Iterator<Item = usize>| -> Option<usize> {
        let mut last = start;
        let mut since = 0usize;
        for c in order {
            match columns[c] {
                Column::Street => {
                    last = c;
                    since = 0;
                }
                Column::Boundary => return Some(last),
                Column::Unknown => {
                    since += 1;
                    if since > gap {
                        return None;
                    }
                }
            }
        }
        None
    };
    let left = walk(&mut (start + 1..cols))?;
    let right = walk(&mut (0..start).rev())?;
    Some((
        -half + (left + 1) as f64 * bin_m,
        -half + right as f64 * bin_m,
    ))
}

/// The median of the values (the mean of the middle two for an even count; NaN for none);
/// sorts them in place.
pub fn median(v: &mut [f64]) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    v.sort_by(f64::total_cmp);
    let n = v.len();
    if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    }
}

/// Derives one segment's truth from its corridor and the cloud's labels.
fn observe(c: &Corridor, labels: &[u8], options: &TruthOptions) -> SegmentObservation {
    let grid = &c.grid;
    let rows_per_slice = ((options.slice_m / grid.bin_m).round() as usize).max(1);
    let cols = grid.cols;
    let mut slices = 0;
    let mut points = 0;
    let mut edges: [Vec<(f64, f64)>; 2] = [Vec::new(), Vec::new()];
    // Per column of a slice: counts of street and boundary points for both targets.
    let mut counts = vec![[[0usize; 2]; 2]; cols];
    let mut row0 = 0;
    while row0 < grid.rows {
        let rows = row0..(row0 + rows_per_slice).min(grid.rows);
        counts.iter_mut().for_each(|c| *c = [[0; 2]; 2]);
        let mut any = false;
        for row in rows {
            for (col, count) in counts.iter_mut().enumerate() {
                let k = row * cols + col;
                if c.masked[k] {
                    continue;
                }
                for &id in grid.points(k) {
                    let Some(class) = labels.get(id as usize).and_then(|&l| Class::from_id(l))
                    else {
                        continue;
                    };
                    any = true;
                    points += 1;
                    for (t, target) in [Target::DrivingArea, Target::WithSidewalk]
                        .into_iter()
                        .enumerate()
                    {
                        match role(target, class) {
                            Some(true) => count[t][0] += 1,
                            Some(false) => count[t][1] += 1,
                            None => {}
                        }
                    }
                }
            }
        }
        row0 += rows_per_slice;
        if !any {
            continue;
        }
        slices += 1;
        for (t, found) in edges.iter_mut().enumerate() {
            let columns: Vec<Column> = counts
                .iter()
                .map(|c| {
                    let (street, boundary) = (c[t][0], c[t][1]);
                    if street >= options.min_points && street >= boundary {
                        Column::Street
                    } else if boundary >= options.min_points {
                        Column::Boundary
                    } else {
                        Column::Unknown
                    }
                })
                .collect();
            if let Some(e) = slice_edges(&columns, grid.bin_m, options) {
                found.push(e);
            }
        }
    }
    let needed = options
        .min_slices
        .max((options.min_fraction * slices as f64).ceil() as usize);
    let derive = |found: &[(f64, f64)]| -> Option<DerivedGeometry> {
        if found.len() < needed.max(1) {
            return None;
        }
        let mut left: Vec<f64> = found.iter().map(|e| e.0).collect();
        let mut right: Vec<f64> = found.iter().map(|e| e.1).collect();
        let (l, r) = (median(&mut left), median(&mut right));
        Some(DerivedGeometry {
            offset_m: 0.5 * (l + r),
            width_m: l - r,
            slices: found.len(),
        })
    };
    SegmentObservation {
        segment: c.segment,
        slices,
        points,
        driving_area: derive(&edges[0]),
        with_sidewalk: derive(&edges[1]),
    }
}

/// Each drivable segment's observation and derived truth (one entry per segment of the map;
/// non-drivable and corridor-less segments get an empty observation).
pub fn derive_truth(
    map: &OsmMap,
    cloud: &PointCloud,
    corridor: &CorridorOptions,
    options: &TruthOptions,
) -> Vec<SegmentObservation> {
    let segs = &map.streets.segments;
    let empty = |s: usize| SegmentObservation {
        segment: s,
        slices: 0,
        points: 0,
        driving_area: None,
        with_sidewalk: None,
    };
    let Some(labels) = cloud.label.as_deref() else {
        return (0..segs.len()).map(empty).collect();
    };
    let drivable: Vec<usize> = (0..segs.len())
        .filter(|&s| geodata::osm::tags::is_drivable(&segs[s].highway))
        .collect();
    let observed = map_corridors(
        segs,
        &drivable,
        &map.streets.intersections,
        &cloud.positions,
        corridor,
        |c| observe(&c, labels, options),
    );
    let mut out: Vec<SegmentObservation> = (0..segs.len()).map(empty).collect();
    for (&s, o) in drivable.iter().zip(observed) {
        if let Some(o) = o {
            out[s] = o;
        }
    }
    out
}

/// The dataset truth of the observations: a segment has a truth (`observed`) when its
/// driving area was derived; the sidewalk width is half the difference of the two targets'
/// widths and the outer strip's own offset is kept (`outer_offset_m`); a segment whose outer
/// strip was not derived has no with-sidewalk truth (`outer_observed` false).
pub fn truths(map: &OsmMap, observations: &[SegmentObservation]) -> Vec<SegmentTruth> {
    observations
        .iter()
        .map(|o| {
            let drivable =
                geodata::osm::tags::is_drivable(&map.streets.segments[o.segment].highway);
            match o.driving_area {
                Some(d) => {
                    let outer = o.with_sidewalk.filter(|w| w.width_m >= d.width_m);
                    SegmentTruth {
                        segment: o.segment,
                        offset_m: d.offset_m,
                        width_m: d.width_m,
                        sidewalk_m: outer.map_or(0.0, |w| 0.5 * (w.width_m - d.width_m)),
                        outer_offset_m: outer.map(|w| w.offset_m),
                        outer_observed: outer.is_some(),
                        drivable,
                        observed: true,
                        points: o.points,
                    }
                }
                None => SegmentTruth {
                    segment: o.segment,
                    offset_m: 0.0,
                    width_m: 0.0,
                    sidewalk_m: 0.0,
                    outer_offset_m: None,
                    outer_observed: false,
                    drivable,
                    observed: false,
                    points: o.points,
                },
            }
        })
        .collect()
}

pub use geodata::datasets::SequenceKind;

/// The layout of `dir` ([`SequenceKind::of`]), or an error naming the folder.
pub fn detect_kind(dir: &Path) -> Result<SequenceKind> {
    SequenceKind::of(dir).ok_or_else(|| StreetsError::Dataset {
        path: dir.to_path_buf(),
        message: "not a labelled sequence: expected velodyne_points/ (KITTI-360) or \
                  lidar_bin/ (MCD) with gt_labels/ and poses"
            .into(),
    })
}

/// A real labelled sequence registered into a map's frame, with derived truth.
pub struct RealDataset {
    /// The dataset (map, registered cloud, truth per segment) as `streets eval` takes it.
    pub dataset: StreetsDataset,
    /// The layout read.
    pub kind: SequenceKind,
    /// Scans read.
    pub scans: usize,
    /// Sensor positions in the map's local frame, one per pose from the first to the last
    /// scan.
    pub trajectory: Vec<[f64; 2]>,
    /// Observation and derived truth per segment.
    pub observations: Vec<SegmentObservation>,
    /// Drivable segments the drive passes ([`drives_along`]).
    pub passed: Vec<usize>,
}

/// Farthest the trajectory may be from a point of a segment's centre line for the drive to
/// pass that point, metres.
pub const PASS_DISTANCE_M: f64 = 10.0;

/// Whether a drive passes the segment a→b: the trajectory (scan positions joined in order)
/// comes within [`PASS_DISTANCE_M`] of at least half of the points of its centre line
/// (sampled every metre). A street crossed at an intersection is not passed; one driven
/// along is, even between two scans far apart.
pub fn drives_along(trajectory: &[[f64; 2]], a: [f64; 2], b: [f64; 2]) -> bool {
    use geodata::osm::geometry::point_segment_distance;
    let len = (b[0] - a[0]).hypot(b[1] - a[1]);
    let n = (len.ceil() as usize).max(1);
    let near = (0..=n)
        .filter(|&i| {
            let f = i as f64 / n as f64;
            let p = [a[0] + f * (b[0] - a[0]), a[1] + f * (b[1] - a[1])];
            match trajectory {
                [] => false,
                [q] => (p[0] - q[0]).hypot(p[1] - q[1]) <= PASS_DISTANCE_M,
                _ => trajectory
                    .windows(2)
                    .any(|w| point_segment_distance(p, w[0], w[1]) <= PASS_DISTANCE_M),
            }
        })
        .count();
    2 * near > n
}

fn dataset_error(dir: &Path, e: geodata::datasets::DatasetError) -> StreetsError {
    StreetsError::Dataset {
        path: dir.to_path_buf(),
        message: e.to_string(),
    }
}

/// Reads every scan of a labelled sequence into the map's frame; `progress(done, total)`
/// after each scan.
pub fn load_sequence(
    dir: &Path,
    map_path: &Path,
    corridor: &CorridorOptions,
    options: &TruthOptions,
    progress: &dyn Fn(usize, usize),
) -> Result<RealDataset> {
    let kind = detect_kind(dir)?;
    let map = OsmMap::load(map_path)?;
    if map.streets.segments.is_empty() {
        return Err(StreetsError::NoStreets {
            path: map_path.display().to_string(),
        });
    }
    let seq = kind.open(dir).map_err(|e| dataset_error(dir, e))?;
    let frames = seq.frames().map_err(|e| dataset_error(dir, e))?;
    let mut parts: Vec<PointCloud> = Vec::with_capacity(frames.len());
    // The drive: every pose between the first and the last scan (the pose files of both
    // layouts hold the frames between the labelled scans too).
    let span = frames[0]..=frames[frames.len() - 1];
    let georef = seq.georeference();
    let trajectory: Vec<[f64; 2]> = seq
        .pose_frames()
        .map_err(|e| dataset_error(dir, e))?
        .into_iter()
        .filter(|f| span.contains(f))
        .map(|f| {
            let w = seq
                .world_from_sensor(f)
                .map_err(|e| dataset_error(dir, e))?;
            let l = geodata::datasets::local_from_world_pose(&georef, &w, &map.frame);
            Ok([l.translation.vector.x, l.translation.vector.y])
        })
        .collect::<Result<_>>()?;
    for (i, &f) in frames.iter().enumerate() {
        let scan = seq.load_scan(f).map_err(|e| dataset_error(dir, e))?;
        if scan.cloud.label.is_none() {
            return Err(StreetsError::NoLabels {
                path: format!("{} (frame {f}: no gt_labels file)", scan.path.display()),
            });
        }
        let mut cloud = scan.cloud_in_local(&map.frame);
        // Only the labels travel on: intensity scales differ between sensors, and the
        // registered cloud keeps what the features read.
        cloud.raw_label = None;
        parts.push(cloud);
        progress(i + 1, frames.len());
    }
    let cloud = PointCloud::concat(parts.iter());
    drop(parts);
    let observations = derive_truth(&map, &cloud, corridor, options);
    let segs = &map.streets.segments;
    let passed: Vec<usize> = (0..segs.len())
        .filter(|&s| geodata::osm::tags::is_drivable(&segs[s].highway))
        .filter(|&s| drives_along(&trajectory, segs[s].a, segs[s].b))
        .collect();
    if passed.is_empty() {
        let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
        for p in &trajectory {
            for k in 0..2 {
                lo[k] = lo[k].min(p[k]);
                hi[k] = hi[k].max(p[k]);
            }
        }
        return Err(StreetsError::Dataset {
            path: dir.to_path_buf(),
            message: format!(
                "the drive does not pass any street of {}: scan positions x {:.0}..{:.0}, y {:.0}..{:.0} m in the map's frame (does the map cover the sequence?)",
                map_path.display(),
                lo[0],
                hi[0],
                lo[1],
                hi[1]
            ),
        });
    }
    let segments = truths(&map, &observations);
    Ok(RealDataset {
        dataset: StreetsDataset {
            dir: dir.to_path_buf(),
            map_path: PathBuf::from(map_path),
            map,
            cloud,
            segments,
            route_m: None,
        },
        kind,
        scans: frames.len(),
        trajectory,
        observations,
        passed,
    })
}

/// One passed segment's observation, derived truth and (after the evaluation) estimate
/// (`streets eval-real --segments-out`).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SegmentRow<'a> {
    /// Segment index in the map.
    pub segment: usize,
    /// Length, metres.
    pub length_m: f64,
    /// OSM highway tag.
    pub highway: &'a str,
    /// What the labelled points show.
    pub observation: &'a SegmentObservation,
    /// The full model's estimate and the truth, once evaluated.
    pub estimate: Option<&'a SegmentGeometry>,
}

impl RealDataset {
    /// The rows of the segments the drive passes (`geometries`: the evaluation's, if any).
    pub fn segment_rows<'a>(
        &'a self,
        geometries: Option<&'a [SegmentGeometry]>,
    ) -> Vec<SegmentRow<'a>> {
        let segs = &self.dataset.map.streets.segments;
        self.observations
            .iter()
            .filter(|o| self.passed.contains(&o.segment))
            .map(|o| SegmentRow {
                segment: o.segment,
                length_m: segs[o.segment].length_m,
                highway: &segs[o.segment].highway,
                observation: o,
                estimate: geometries.and_then(|g| g.iter().find(|s| s.segment == o.segment)),
            })
            .collect()
    }

    /// Passed segments with a derived truth; an error when fewer than `folds` have one.
    pub fn check_evaluable(
        &self,
        dataset: &Path,
        map: &Path,
        folds: usize,
        truth: &TruthOptions,
    ) -> Result<usize> {
        let with_truth = self
            .passed
            .iter()
            .filter(|&&s| self.dataset.segments[s].observed)
            .count();
        if with_truth < folds {
            return Err(StreetsError::TooFewTruths {
                dataset: dataset.to_path_buf(),
                map: map.to_path_buf(),
                passed: self.passed.len(),
                with_truth,
                min_slices: truth.min_slices,
                folds,
            });
        }
        Ok(with_truth)
    }
}

/// How many of the segments a drive passes have a truth and an estimate.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Coverage {
    /// Drivable segments the drive passes.
    pub passed: usize,
    /// Of them, with labelled points outside the intersection masks.
    pub estimable: usize,
    /// Of them, with a derived driving-area truth.
    pub with_truth: usize,
    /// Of them, also with a sidewalk truth.
    pub with_sidewalk_truth: usize,
    /// Of them, with a full-model estimate.
    pub with_estimate: usize,
    /// `with_estimate / with_truth`.
    pub estimate_share_of_truth: f64,
    /// `with_truth / passed`.
    pub truth_share_of_passed: f64,
    /// `with_truth / estimable`.
    pub truth_share_of_estimable: f64,
    /// Length of the passed segments, metres.
    pub passed_m: f64,
    /// Length of those with a truth, metres.
    pub with_truth_m: f64,
}

/// The derived truth's options and the spread of its widths.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct TruthSummary {
    /// Options of the derivation.
    pub options: TruthOptions,
    /// Narrowest true driving area, metres.
    pub width_m_min: f64,
    /// Median true driving area, metres.
    pub width_m_median: f64,
    /// Widest true driving area, metres.
    pub width_m_max: f64,
}

/// The sequence read.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct SequenceSummary {
    /// Its layout.
    pub kind: SequenceKind,
    /// Scans read.
    pub scans: usize,
    /// Points registered.
    pub points: usize,
}

/// The Table 4.1 analogue on a real sequence (`streets eval-real --json`): the evaluation
/// with the coverage, the truth's spread and the sequence read.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct RealEvalReport {
    /// The evaluation, as `streets eval` reports it.
    #[serde(flatten)]
    pub report: EvalReport,
    /// Segments with a truth and an estimate.
    pub coverage: Coverage,
    /// The derived truth.
    pub truth: TruthSummary,
    /// The sequence.
    pub dataset: SequenceSummary,
}

impl RealEvalReport {
    /// The report of `report`, an evaluation of `real` with a truth derived under `truth`.
    pub fn new(real: &RealDataset, report: EvalReport, truth: TruthOptions) -> Self {
        let segs = &real.dataset.map.streets.segments;
        let truths = &real.dataset.segments;
        let passed = &real.passed;
        let with_truth = passed.iter().filter(|&&s| truths[s].observed).count();
        let estimated: std::collections::BTreeSet<usize> = report
            .geometries
            .get("driving_area")
            .map(|g| g.iter().map(|s| s.segment).collect())
            .unwrap_or_default();
        let with_outer = passed
            .iter()
            .filter(|&&s| truths[s].observed && truths[s].outer_observed)
            .count();
        let with_estimate = passed.iter().filter(|&&s| estimated.contains(&s)).count();
        // Segments with labelled points outside the intersection masks: a segment lying
        // wholly within 10 m of intersections has no bins of its own, for any method.
        let estimable = passed
            .iter()
            .filter(|&&s| real.observations[s].slices > 0)
            .count();
        let passed_m: f64 = passed.iter().map(|&s| segs[s].length_m).sum();
        let with_truth_m: f64 = passed
            .iter()
            .filter(|&&s| truths[s].observed)
            .map(|&s| segs[s].length_m)
            .sum();
        let mut widths: Vec<f64> = passed
            .iter()
            .filter(|&&s| truths[s].observed)
            .map(|&s| truths[s].width_m)
            .collect();
        let width_m_min = widths.iter().copied().fold(f64::INFINITY, f64::min);
        let width_m_max = widths.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        let width_m_median = median(&mut widths);
        RealEvalReport {
            report,
            coverage: Coverage {
                passed: passed.len(),
                estimable,
                with_truth,
                with_sidewalk_truth: with_outer,
                with_estimate,
                estimate_share_of_truth: with_estimate as f64 / with_truth.max(1) as f64,
                truth_share_of_passed: with_truth as f64 / passed.len().max(1) as f64,
                truth_share_of_estimable: with_truth as f64 / estimable.max(1) as f64,
                passed_m,
                with_truth_m,
            },
            truth: TruthSummary {
                options: truth,
                width_m_min,
                width_m_median,
                width_m_max,
            },
            dataset: SequenceSummary {
                kind: real.kind,
                scans: real.scans,
                points: real.dataset.cloud.len(),
            },
        }
    }
}

impl RealEvalReport {
    /// The sequence read, the coverage, the true widths, then the evaluation's table and
    /// details (`dataset`: the sequence folder, `map`: the OSM file).
    pub fn text(&self, dataset: &Path, map: &Path) -> String {
        let (c, t, d) = (&self.coverage, &self.truth, &self.dataset);
        format!(
            "{:?} sequence {}: {} scans, {} points registered into {}\n\
             coverage: the drive passes {} drivable segments ({:.0} m), {} of them with bins outside the intersection masks; {} have a derived truth ({:.0} m; {} also with sidewalk), {} an estimate\n\
             true driving-area widths: median {:.1} m (min {:.1}, max {:.1})\n\
             {}\n\
             {}\n",
            d.kind,
            dataset.display(),
            d.scans,
            d.points,
            map.display(),
            c.passed,
            c.passed_m,
            c.estimable,
            c.with_truth,
            c.with_truth_m,
            c.with_sidewalk_truth,
            c.with_estimate,
            t.width_m_median,
            t.width_m_min,
            t.width_m_max,
            self.report.table_text(),
            self.report.details_text()
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use Column::{Boundary as B, Street as S, Unknown as U};

    /// Columns of 1 m (bin 1 m) across a 20 m corridor: index 10 is just left of the line.
    fn edges(cols: &[Column]) -> Option<(f64, f64)> {
        let options = TruthOptions {
            max_gap_m: 3.0,
            search_m: 4.0,
            ..TruthOptions::default()
        };
        slice_edges(cols, 1.0, &options)
    }

    fn row(
        street: std::ops::Range<usize>,
        fill: Column,
        left_b: usize,
        right_b: usize,
    ) -> Vec<Column> {
        let mut v = vec![fill; 20];
        for c in street {
            v[c] = S;
        }
        v[left_b] = B;
        v[right_b] = B;
        v
    }

    #[test]
    fn edges_lie_at_the_outer_borders_of_the_last_street_columns() {
        // Street columns 7..13 (u −3 … +3), bounded on both sides.
        assert_eq!(edges(&row(7..13, U, 13, 6)), Some((3.0, -3.0)));
    }

    #[test]
    fn a_parked_car_gap_does_not_end_the_street_but_a_long_gap_hides_the_edge() {
        // Street 7..13, a 2-column unknown gap (a car), street again at 15, then the kerb.
        let mut v = row(7..13, U, 16, 6);
        v[15] = S;
        assert_eq!(edges(&v), Some((6.0, -3.0)));
        // The kerb 5 columns after the last street column: the edge is not observed.
        assert_eq!(edges(&row(7..13, U, 18, 6)), None);
        // No kerb at all on the left.
        let mut v = row(7..13, U, 13, 6);
        v[13] = U;
        assert_eq!(edges(&v), None);
    }

    #[test]
    fn no_street_near_the_centre_line_means_no_edges() {
        assert_eq!(edges(&row(0..3, U, 3, 4)), None);
        assert_eq!(edges(&[U; 20]), None);
    }
}
