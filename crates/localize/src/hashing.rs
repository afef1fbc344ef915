//! The geometric-hashing baseline of Cham et al., "Estimating camera pose from a single
//! urban ground-view omnidirectional image and a 2D building outline map", CVPR 2010
//! (doi:10.1109/CVPR.2010.5540191), as the thesis implemented it for laser scans (§5.4.2):
//! building corners are hashed by their two side lengths and the angle between the sides;
//! every scan corner looks up its matching map corners, each match gives a pose, and poses
//! vote into an accumulator of 5 m cells × 6 orientations. Cost O(c_s · k) votes for c_s scan
//! corners with k matches each.

use crate::{Pose2, Segment};
use geodata::osm::OsmMap;
use rustc_hash::FxHashMap;

/// Options of the hashing baseline.
#[derive(Debug, Clone, PartialEq)]
pub struct HashingOptions {
    /// Angle bin of the hash, degrees.
    pub angle_bin_deg: f64,
    /// Side-length bin of the hash, metres.
    pub length_bin_m: f64,
    /// Largest gap between two scan segment ends forming a corner, metres.
    pub corner_gap_m: f64,
    /// Corners whose sides are closer to straight than this are ignored, degrees.
    pub min_turn_deg: f64,
    /// Accumulator cell, metres.
    pub cell_m: f64,
    /// Accumulator orientations over the full turn.
    pub orientations: usize,
}

impl Default for HashingOptions {
    fn default() -> Self {
        HashingOptions {
            angle_bin_deg: 10.0,
            length_bin_m: 4.0,
            corner_gap_m: 2.0,
            min_turn_deg: 25.0,
            cell_m: 5.0,
            orientations: 6,
        }
    }
}

/// A corner: apex, unit directions of its two sides (d₂ = d₁ turned CCW by `angle_rad` ≤ π)
/// and the side lengths.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Corner {
    /// Apex, metres.
    pub apex: [f64; 2],
    /// Direction of the first side.
    pub d1: [f64; 2],
    /// Length of the first side, metres.
    pub l1: f64,
    /// Length of the second side, metres.
    pub l2: f64,
    /// Angle from d₁ counter-clockwise to d₂, (0, π].
    pub angle_rad: f64,
}

fn corner(apex: [f64; 2], p1: [f64; 2], p2: [f64; 2], min_turn: f64) -> Option<Corner> {
    let (v1, v2) = (
        [p1[0] - apex[0], p1[1] - apex[1]],
        [p2[0] - apex[0], p2[1] - apex[1]],
    );
    let (l1, l2) = (v1[0].hypot(v1[1]), v2[0].hypot(v2[1]));
    if l1 <= 1e-9 || l2 <= 1e-9 {
        return None;
    }
    let a = (v2[1].atan2(v2[0]) - v1[1].atan2(v1[0])).rem_euclid(std::f64::consts::TAU);
    let (d, l1, l2, angle) = if a <= std::f64::consts::PI {
        (v1, l1, l2, a)
    } else {
        (v2, l2, l1, std::f64::consts::TAU - a)
    };
    if angle < min_turn || angle > std::f64::consts::PI - min_turn {
        return None;
    }
    let n = d[0].hypot(d[1]);
    Some(Corner {
        apex,
        d1: [d[0] / n, d[1] / n],
        l1,
        l2,
        angle_rad: angle,
    })
}

/// Every outline vertex of the map that is a corner.
pub fn map_corners(map: &OsmMap, options: &HashingOptions) -> Vec<Corner> {
    let min_turn = options.min_turn_deg.to_radians();
    let mut out = Vec::new();
    for b in &map.buildings {
        for ring in std::iter::once(&b.outer).chain(b.inners.iter()) {
            let n = ring.len();
            if n < 3 {
                continue;
            }
            for i in 0..n {
                let (prev, cur, next) = (ring[(i + n - 1) % n], ring[i], ring[(i + 1) % n]);
                if let Some(c) = corner(cur, next, prev, min_turn) {
                    out.push(c);
                }
            }
        }
    }
    out
}

/// Corners of scan segments: pairs whose nearest ends are within `corner_gap_m`, apex at the
/// intersection of their lines.
pub fn scan_corners(segments: &[Segment], options: &HashingOptions) -> Vec<Corner> {
    let min_turn = options.min_turn_deg.to_radians();
    let mut out = Vec::new();
    for (i, s) in segments.iter().enumerate() {
        for t in &segments[i + 1..] {
            let mut best: Option<(f64, [f64; 2], [f64; 2])> = None;
            for (pe, pf) in [(s.a, s.b), (s.b, s.a)] {
                for (qe, qf) in [(t.a, t.b), (t.b, t.a)] {
                    let d = (pe[0] - qe[0]).hypot(pe[1] - qe[1]);
                    if best.is_none_or(|(bd, _, _)| d < bd) {
                        best = Some((d, pf, qf));
                    }
                }
            }
            let Some((gap, far_s, far_t)) = best else {
                continue;
            };
            if gap > options.corner_gap_m {
                continue;
            }
            let Some(apex) = line_intersection(s, t) else {
                continue;
            };
            if let Some(c) = corner(apex, far_s, far_t, min_turn) {
                out.push(c);
            }
        }
    }
    out
}

fn line_intersection(s: &Segment, t: &Segment) -> Option<[f64; 2]> {
    let d1 = [s.b[0] - s.a[0], s.b[1] - s.a[1]];
    let d2 = [t.b[0] - t.a[0], t.b[1] - t.a[1]];
    let den = d1[0] * d2[1] - d1[1] * d2[0];
    if den.abs() < 1e-9 {
        return None;
    }
    let w = [t.a[0] - s.a[0], t.a[1] - s.a[1]];
    let u = (w[0] * d2[1] - w[1] * d2[0]) / den;
    Some([s.a[0] + u * d1[0], s.a[1] + u * d1[1]])
}

/// Accumulator cell: votes, Σx, Σy, Σcos yaw, Σsin yaw.
type Votes = (u32, f64, f64, f64, f64);

/// The hash table of map corners.
#[derive(Debug, Clone)]
pub struct CornerIndex {
    /// The map corners.
    pub corners: Vec<Corner>,
    table: FxHashMap<(i64, i64, i64), Vec<u32>>,
    options: HashingOptions,
}

impl CornerIndex {
    /// Hashes the map's corners.
    pub fn new(map: &OsmMap, options: &HashingOptions) -> CornerIndex {
        let corners = map_corners(map, options);
        let mut table: FxHashMap<(i64, i64, i64), Vec<u32>> = FxHashMap::default();
        for (k, c) in corners.iter().enumerate() {
            table.entry(key(c, options)).or_default().push(k as u32);
        }
        CornerIndex {
            corners,
            table,
            options: options.clone(),
        }
    }

    /// Ranked poses (best first) with their votes for scan segments in the sensor frame.
    pub fn localize(&self, segments: &[Segment]) -> Vec<(Pose2, u32)> {
        let o = &self.options;
        let cell_yaw = std::f64::consts::TAU / o.orientations.max(1) as f64;
        // (cell x, cell y, orientation) → (votes, Σx, Σy, Σcos, Σsin)
        let mut acc: FxHashMap<(i64, i64, i64), Votes> = FxHashMap::default();
        for sc in scan_corners(segments, o) {
            let (a, l1, l2) = key(&sc, o);
            for da in -1..=1 {
                for d1 in -1..=1 {
                    for d2 in -1..=1 {
                        let Some(ids) = self.table.get(&(a + da, l1 + d1, l2 + d2)) else {
                            continue;
                        };
                        for &id in ids {
                            let Some(mc) = self.corners.get(id as usize) else {
                                continue;
                            };
                            let yaw = (mc.d1[1].atan2(mc.d1[0]) - sc.d1[1].atan2(sc.d1[0]))
                                .rem_euclid(std::f64::consts::TAU);
                            let (s, c) = yaw.sin_cos();
                            let x = mc.apex[0] - (c * sc.apex[0] - s * sc.apex[1]);
                            let y = mc.apex[1] - (s * sc.apex[0] + c * sc.apex[1]);
                            let k = (
                                (x / o.cell_m).floor() as i64,
                                (y / o.cell_m).floor() as i64,
                                (yaw / cell_yaw).floor() as i64,
                            );
                            let e = acc.entry(k).or_insert((0, 0.0, 0.0, 0.0, 0.0));
                            e.0 += 1;
                            e.1 += x;
                            e.2 += y;
                            e.3 += c;
                            e.4 += s;
                        }
                    }
                }
            }
        }
        let mut out: Vec<((i64, i64, i64), Pose2, u32)> = acc
            .into_iter()
            .map(|(k, (n, sx, sy, sc, ss))| {
                let nf = n as f64;
                (
                    k,
                    Pose2 {
                        x: sx / nf,
                        y: sy / nf,
                        yaw_rad: ss.atan2(sc).rem_euclid(std::f64::consts::TAU),
                    },
                    n,
                )
            })
            .collect();
        out.sort_by(|a, b| b.2.cmp(&a.2).then(a.0.cmp(&b.0)));
        out.into_iter().map(|(_, p, n)| (p, n)).collect()
    }
}

fn key(c: &Corner, o: &HashingOptions) -> (i64, i64, i64) {
    (
        (c.angle_rad.to_degrees() / o.angle_bin_deg).round() as i64,
        (c.l1 / o.length_bin_m).floor() as i64,
        (c.l2 / o.length_bin_m).floor() as i64,
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn corner_is_canonical_under_side_order() {
        let a = corner([0.0, 0.0], [4.0, 0.0], [0.0, 2.0], 0.3).unwrap();
        let b = corner([0.0, 0.0], [0.0, 2.0], [4.0, 0.0], 0.3).unwrap();
        assert_eq!(a, b);
        assert!((a.angle_rad - std::f64::consts::FRAC_PI_2).abs() < 1e-12);
        assert!(corner([0.0, 0.0], [4.0, 0.0], [-4.0, 0.01], 0.3).is_none());
    }

    #[test]
    fn scan_corner_of_two_touching_segments() {
        let segs = vec![
            Segment::new([1.0, 1.0], [9.0, 1.0]),
            Segment::new([0.8, 1.3], [0.8, 6.0]),
        ];
        let cs = scan_corners(&segs, &HashingOptions::default());
        assert_eq!(cs.len(), 1);
        assert!((cs[0].apex[0] - 0.8).abs() < 1e-9 && (cs[0].apex[1] - 1.0).abs() < 1e-9);
    }
}
