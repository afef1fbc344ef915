//! Segment corridors (thesis §4.4.2): the cloud within 20 m either side of a segment's centre
//! line, rasterised into 0.2 m bins in the segment frame, with bins within 10 m of an
//! intersection centre masked (§4.4.1).
//!
//! The segment frame has its origin at `p_{s,b}`, `t` along `p_{s,b} → p_{s,e}` and `u` to the
//! left; row `i` covers `t ∈ [i·bin, (i+1)·bin)`, column `j` covers
//! `u ∈ [−half + j·bin, −half + (j+1)·bin)`. Points are found through a uniform hash grid
//! over the cloud (built once, O(P)); each corridor then costs O(points near it), and
//! corridors are built in parallel over segments.

use crate::grid::BinGrid;
use geodata::osm::geometry::point_segment_distance;
use geodata::osm::model::{Intersection, StreetSegment};
use rayon::prelude::*;
use std::collections::HashMap;

/// Options of corridor extraction.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct CorridorOptions {
    /// Total corridor width, metres (thesis: 40).
    pub width_m: f64,
    /// Bin side, metres (thesis: 0.2).
    pub bin_m: f64,
    /// Bins closer than this to an intersection centre are masked, metres (thesis: 10).
    pub intersection_radius_m: f64,
    /// Also mask bins nearer to another drivable segment's centre line than to this one
    /// (an extension of the thesis' intersection mask: parallel carriageways and crossing
    /// streets beyond 10 m then do not enter this segment's potentials).
    pub mask_nearer_segments: bool,
}

impl Default for CorridorOptions {
    fn default() -> Self {
        CorridorOptions {
            width_m: 40.0,
            bin_m: 0.2,
            intersection_radius_m: 10.0,
            mask_nearer_segments: true,
        }
    }
}

impl CorridorOptions {
    /// Columns N across the corridor.
    pub fn cols(&self) -> usize {
        (self.width_m / self.bin_m).round().max(1.0) as usize
    }
}

/// A segment's frame: origin, unit direction and left normal.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SegmentFrame {
    /// `p_{s,b}` in the local frame, metres.
    pub origin: [f64; 2],
    /// Unit vector `p_{s,b} → p_{s,e}`.
    pub along: [f64; 2],
    /// Unit left normal.
    pub left: [f64; 2],
    /// Segment length, metres.
    pub length_m: f64,
}

impl SegmentFrame {
    /// The frame of a segment (`None` for a zero-length segment).
    pub fn of(segment: &StreetSegment) -> Option<SegmentFrame> {
        let d = [segment.b[0] - segment.a[0], segment.b[1] - segment.a[1]];
        let len = d[0].hypot(d[1]);
        if !(len > 0.0 && len.is_finite()) {
            return None;
        }
        let along = [d[0] / len, d[1] / len];
        Some(SegmentFrame {
            origin: segment.a,
            along,
            left: [-along[1], along[0]],
            length_m: len,
        })
    }

    /// (t, u) of a point.
    pub fn local(&self, p: [f64; 2]) -> (f64, f64) {
        let q = [p[0] - self.origin[0], p[1] - self.origin[1]];
        (
            q[0] * self.along[0] + q[1] * self.along[1],
            q[0] * self.left[0] + q[1] * self.left[1],
        )
    }

    /// The point at (t, u).
    pub fn world(&self, t: f64, u: f64) -> [f64; 2] {
        [
            self.origin[0] + t * self.along[0] + u * self.left[0],
            self.origin[1] + t * self.along[1] + u * self.left[1],
        ]
    }
}

/// One segment's corridor.
#[derive(Debug, Clone, PartialEq)]
pub struct Corridor {
    /// Index of the segment in the map's street network.
    pub segment: usize,
    /// The segment frame.
    pub frame: SegmentFrame,
    /// The bins (rows along, columns across) with their point ids.
    pub grid: BinGrid,
    /// Bins within the intersection radius (not used for estimation or evaluation).
    pub masked: Vec<bool>,
}

impl Corridor {
    /// Centre of bin (row, col) in the local frame.
    pub fn bin_centre(&self, row: usize, col: usize) -> [f64; 2] {
        let b = self.grid.bin_m;
        let half = 0.5 * self.grid.cols as f64 * b;
        self.frame
            .world((row as f64 + 0.5) * b, -half + (col as f64 + 0.5) * b)
    }

    /// Bins that are unmasked and hold at least one point.
    pub fn usable_bins(&self) -> usize {
        (0..self.grid.len())
            .filter(|&k| !self.masked[k] && !self.grid.points(k).is_empty())
            .count()
    }
}

/// A uniform hash grid over the xy of a cloud's points.
pub struct PointIndex {
    cell_m: f64,
    cells: HashMap<(i64, i64), Vec<u32>>,
}

impl PointIndex {
    /// Indexes all positions with cells of `cell_m` (non-finite points are left out).
    pub fn new(positions: &[[f64; 3]], cell_m: f64) -> PointIndex {
        let mut cells: HashMap<(i64, i64), Vec<u32>> = HashMap::new();
        for (i, p) in positions.iter().enumerate() {
            if p[0].is_finite() && p[1].is_finite() && p[2].is_finite() {
                let key = (
                    (p[0] / cell_m).floor() as i64,
                    (p[1] / cell_m).floor() as i64,
                );
                cells.entry(key).or_default().push(i as u32);
            }
        }
        PointIndex { cell_m, cells }
    }

    /// Point ids in cells overlapping the box `min..max` (a superset of the points inside).
    pub fn candidates(&self, min: [f64; 2], max: [f64; 2]) -> impl Iterator<Item = u32> + '_ {
        let (x0, y0) = (
            (min[0] / self.cell_m).floor() as i64,
            (min[1] / self.cell_m).floor() as i64,
        );
        let (x1, y1) = (
            (max[0] / self.cell_m).floor() as i64,
            (max[1] / self.cell_m).floor() as i64,
        );
        (x0..=x1)
            .flat_map(move |x| (y0..=y1).map(move |y| (x, y)))
            .filter_map(|k| self.cells.get(&k))
            .flat_map(|v| v.iter().copied())
    }
}

/// The corridor of one segment (`None` for a segment shorter than one bin); `competitors`
/// are the centre lines that claim bins nearer to them (see [`CorridorOptions::mask_nearer_segments`]).
#[allow(clippy::too_many_arguments)]
pub fn corridor(
    segment_id: usize,
    segment: &StreetSegment,
    intersections: &[Intersection],
    competitors: &[[[f64; 2]; 2]],
    positions: &[[f64; 3]],
    index: &PointIndex,
    options: &CorridorOptions,
) -> Option<Corridor> {
    let frame = SegmentFrame::of(segment)?;
    let bin = options.bin_m;
    let rows = (frame.length_m / bin).floor() as usize;
    if rows == 0 {
        return None;
    }
    let cols = options.cols();
    let half = 0.5 * cols as f64 * bin;
    let length = rows as f64 * bin;
    let corners = [
        frame.world(0.0, -half),
        frame.world(0.0, half),
        frame.world(length, -half),
        frame.world(length, half),
    ];
    let mut min = [f64::INFINITY; 2];
    let mut max = [f64::NEG_INFINITY; 2];
    for c in corners {
        for k in 0..2 {
            min[k] = min[k].min(c[k]);
            max[k] = max[k].max(c[k]);
        }
    }
    let mut pairs = Vec::new();
    for id in index.candidates(min, max) {
        let p = positions[id as usize];
        let (t, u) = frame.local([p[0], p[1]]);
        if t < 0.0 || t >= length || u < -half || u >= half {
            continue;
        }
        let row = ((t / bin) as usize).min(rows - 1);
        let col = (((u + half) / bin) as usize).min(cols - 1);
        pairs.push(((row * cols + col) as u32, id));
    }
    let grid = BinGrid::from_pairs(rows, cols, bin, &pairs);
    // Intersections near the corridor mask their disc.
    let r = options.intersection_radius_m;
    let near: Vec<[f64; 2]> = intersections
        .iter()
        .map(|i| i.position)
        .filter(|p| {
            p[0] >= min[0] - r && p[0] <= max[0] + r && p[1] >= min[1] - r && p[1] <= max[1] + r
        })
        .map(|p| {
            let (t, u) = frame.local(p);
            [t, u]
        })
        .collect();
    let mut masked = vec![false; rows * cols];
    let rivals: Vec<[[f64; 2]; 2]> = competitors
        .iter()
        .filter(|l| {
            let (lo, hi) = (
                [l[0][0].min(l[1][0]), l[0][1].min(l[1][1])],
                [l[0][0].max(l[1][0]), l[0][1].max(l[1][1])],
            );
            (l[0] != segment.a || l[1] != segment.b)
                && hi[0] >= min[0] - half
                && lo[0] <= max[0] + half
                && hi[1] >= min[1] - half
                && lo[1] <= max[1] + half
        })
        .copied()
        .collect();
    if !rivals.is_empty() {
        for row in 0..rows {
            let t = (row as f64 + 0.5) * bin;
            for col in 0..cols {
                let u = -half + (col as f64 + 0.5) * bin;
                let p = frame.world(t, u);
                let own = u.abs();
                masked[row * cols + col] = rivals
                    .iter()
                    .any(|l| point_segment_distance(p, l[0], l[1]) < own);
            }
        }
    }
    if !near.is_empty() {
        for row in 0..rows {
            let t = (row as f64 + 0.5) * bin;
            for col in 0..cols {
                let u = -half + (col as f64 + 0.5) * bin;
                masked[row * cols + col] |= near
                    .iter()
                    .any(|c| (c[0] - t).powi(2) + (c[1] - u).powi(2) <= r * r);
            }
        }
    }
    Some(Corridor {
        segment: segment_id,
        frame,
        grid,
        masked,
    })
}

/// Corridors of the given segments, in parallel (`None` where a segment is shorter than a bin).
pub fn corridors(
    segments: &[StreetSegment],
    which: &[usize],
    intersections: &[Intersection],
    positions: &[[f64; 3]],
    options: &CorridorOptions,
) -> Vec<Option<Corridor>> {
    map_corridors(segments, which, intersections, positions, options, |c| c)
}

/// Builds each corridor of `which` in parallel and maps it through `f` right away, so that
/// only `f`'s results are held (`None` where a segment is shorter than a bin).
pub fn map_corridors<T: Send>(
    segments: &[StreetSegment],
    which: &[usize],
    intersections: &[Intersection],
    positions: &[[f64; 3]],
    options: &CorridorOptions,
    f: impl Fn(Corridor) -> T + Sync,
) -> Vec<Option<T>> {
    CorridorSource::new(segments, intersections, positions, options).map(which, f)
}

/// Everything a corridor is cut from: the map's segments and intersections, the cloud with
/// its point index, and the competing centre lines. Built once (O(P + S)); each corridor is
/// then a function of its segment alone, whichever other segments are asked for with it.
pub struct CorridorSource<'a> {
    segments: &'a [StreetSegment],
    intersections: &'a [Intersection],
    positions: &'a [[f64; 3]],
    options: &'a CorridorOptions,
    index: PointIndex,
    competitors: Vec<[[f64; 2]; 2]>,
}

impl<'a> CorridorSource<'a> {
    /// Indexes the cloud and collects the drivable centre lines (when
    /// [`CorridorOptions::mask_nearer_segments`]).
    pub fn new(
        segments: &'a [StreetSegment],
        intersections: &'a [Intersection],
        positions: &'a [[f64; 3]],
        options: &'a CorridorOptions,
    ) -> CorridorSource<'a> {
        let competitors = if options.mask_nearer_segments {
            segments
                .iter()
                .filter(|s| geodata::osm::tags::is_drivable(&s.highway))
                .map(|s| [s.a, s.b])
                .collect()
        } else {
            Vec::new()
        };
        CorridorSource {
            segments,
            intersections,
            positions,
            options,
            index: PointIndex::new(positions, 10.0),
            competitors,
        }
    }

    /// Builds each corridor of `which` in parallel and maps it through `f` right away
    /// (`None` where a segment is shorter than a bin or out of range).
    pub fn map<T: Send>(
        &self,
        which: &[usize],
        f: impl Fn(Corridor) -> T + Sync,
    ) -> Vec<Option<T>> {
        which
            .par_iter()
            .map(|&s| {
                self.segments
                    .get(s)
                    .and_then(|seg| {
                        corridor(
                            s,
                            seg,
                            self.intersections,
                            &self.competitors,
                            self.positions,
                            &self.index,
                            self.options,
                        )
                    })
                    .map(&f)
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn seg(a: [f64; 2], b: [f64; 2]) -> StreetSegment {
        StreetSegment {
            way_index: 0,
            index_in_way: 0,
            from_node: 1,
            to_node: 2,
            a,
            b,
            length_m: ((b[0] - a[0]).powi(2) + (b[1] - a[1]).powi(2)).sqrt(),
            highway: "residential".into(),
        }
    }

    #[test]
    fn points_fall_into_the_right_bins_and_intersections_mask() {
        // A segment pointing north: left is west (−x).
        let s = seg([0.0, 0.0], [0.0, 30.0]);
        let positions = vec![
            [-1.05, 5.05, 0.0], // u = 1.05 → col 105, row 25
            [1.05, 29.9, 0.0],  // u = −1.05 → col 94, row 149
            [25.0, 5.0, 0.0],   // outside
            [0.0, -0.1, 0.0],   // before the start
        ];
        let inter = vec![Intersection {
            node_id: 2,
            position: [0.0, 30.0],
            segment_ids: vec![0],
        }];
        let opts = CorridorOptions::default();
        let index = PointIndex::new(&positions, 10.0);
        let c = corridor(0, &s, &inter, &[], &positions, &index, &opts).unwrap();
        assert_eq!((c.grid.rows, c.grid.cols), (150, 200));
        assert_eq!(c.grid.points(25 * 200 + 105), &[0]);
        assert_eq!(c.grid.points(149 * 200 + 94), &[1]);
        assert_eq!(c.grid.point_ids.len(), 2);
        assert!(c.masked[149 * 200 + 100]);
        assert!(!c.masked[25 * 200 + 100]);
        assert_eq!(c.usable_bins(), 1);
        let centre = c.bin_centre(25, 105);
        assert!((centre[0] + 1.1).abs() < 1e-9 && (centre[1] - 5.1).abs() < 1e-9);
    }

    #[test]
    fn bins_nearer_to_a_parallel_street_are_masked() {
        let s = seg([0.0, 0.0], [0.0, 30.0]);
        // A parallel street 10 m to the left (west).
        let rival = [[-10.0, 0.0], [-10.0, 30.0]];
        let index = PointIndex::new(&[], 10.0);
        let c = corridor(
            0,
            &s,
            &[],
            &[rival, [s.a, s.b]],
            &[],
            &index,
            &CorridorOptions::default(),
        )
        .unwrap();
        // Column of u = 4.9 (kept) and u = 5.1 (masked).
        assert!(!c.masked[10 * 200 + 124]);
        assert!(c.masked[10 * 200 + 125]);
        assert!(!c.masked[10 * 200 + 10]);
    }

    #[test]
    fn segment_shorter_than_a_bin_has_no_corridor() {
        let s = seg([0.0, 0.0], [0.1, 0.0]);
        let index = PointIndex::new(&[], 10.0);
        assert!(corridor(0, &s, &[], &[], &[], &index, &CorridorOptions::default()).is_none());
    }
}
