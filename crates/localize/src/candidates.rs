//! Pose candidates: exact minimisation of d_DCM (eq. 5.3) over rotation × translation,
//! every pose within a factor of the minimum, non-maximum suppression, and filtering by
//! buildings and streets (thesis §5.3.3–5.3.4).
//!
//! The scan's segments are sampled every grid cell; at yaw k a sample point p has the integer
//! cell offset ⌊p/grid⌋ and the channel of its rotated segment, and the cost of the pose at
//! cell (i, j) is the sum of the tensor at (i, j) + offset over the samples (the discrete
//! FDCM cost). The search is a branch and bound over translation boxes of 2^h × 2^h cells per
//! yaw, as in Cartographer's real-time correlative scan matcher (Hess et al., ICRA 2016,
//! doi:10.1109/ICRA.2016.7487258): a box's bound sums the [`BoundPyramid`] at level h, samples
//! sharing a block and channel are summed once with their count, and a box is cut when its
//! bound exceeds factor × the best cost found so far. Since the best only decreases, every
//! pose within the factor of the final minimum survives: the result equals exhaustive search
//! ([`exhaustive_search`], checked in the tests).

use crate::chamfer::{BoundPyramid, DtTensor};
use crate::{angle_diff, Pose2, Segment};
use geodata::osm::index::MapIndex;
use rayon::prelude::*;
use rustc_hash::FxHashMap;
use std::sync::atomic::{AtomicU64, Ordering};

/// Options of the candidate search.
#[derive(Debug, Clone, PartialEq)]
pub struct SearchOptions {
    /// Yaw step, degrees.
    pub yaw_step_deg: f64,
    /// Top level of the branch and bound (boxes of 2^levels cells).
    pub levels: u32,
    /// Keep every pose with cost ≤ keep_factor × minimum (given as numerator/denominator).
    pub keep_factor: (u64, u64),
    /// Poses are searched over the edges' bounding box grown by this, metres.
    pub pose_margin_m: f64,
    /// Non-maximum suppression radius, metres.
    pub nms_radius_m: f64,
    /// Non-maximum suppression yaw radius, radians.
    pub nms_yaw_rad: f64,
    /// Candidates farther than this from every street segment are dropped, metres.
    pub street_distance_m: f64,
    /// Most raw poses kept (the cheapest); 0: no limit.
    pub max_raw_poses: usize,
}

impl Default for SearchOptions {
    fn default() -> Self {
        SearchOptions {
            yaw_step_deg: 1.0,
            levels: 6,
            keep_factor: (8, 5),
            pose_margin_m: 40.0,
            nms_radius_m: 2.0,
            nms_yaw_rad: 10f64.to_radians(),
            street_distance_m: 12.0,
            max_raw_poses: 2_000_000,
        }
    }
}

/// The scan's samples at one yaw, summed per (block, channel) at every pyramid level.
#[derive(Debug, Clone)]
pub struct Template {
    /// Yaw, radians.
    pub yaw_rad: f64,
    /// Number of samples.
    pub samples: u64,
    /// Per level h: (block offset x, block offset y, channel, count).
    pub levels: Vec<Vec<(i64, i64, usize, u64)>>,
}

/// Sample points (sensor frame) and orientation of the scan segments, one every `spacing_m`.
pub fn sample_segment_points(segments: &[Segment], spacing_m: f64) -> Vec<([f64; 2], f64)> {
    let mut out = Vec::new();
    for s in segments {
        let n = ((s.length() / spacing_m).round() as usize).max(1);
        let o = s.orientation_rad();
        for k in 0..n {
            let t = (k as f64 + 0.5) / n as f64;
            out.push((
                [
                    s.a[0] + t * (s.b[0] - s.a[0]),
                    s.a[1] + t * (s.b[1] - s.a[1]),
                ],
                o,
            ));
        }
    }
    out
}

/// The template of the scan segments at one yaw.
pub fn build_template(segments: &[Segment], yaw_rad: f64, dt: &DtTensor, levels: u32) -> Template {
    let pose = Pose2 {
        x: 0.0,
        y: 0.0,
        yaw_rad,
    };
    let mut base: FxHashMap<(i64, i64, usize), u64> = FxHashMap::default();
    for (p, o) in sample_segment_points(segments, dt.grid_m) {
        let q = pose.apply(p);
        let key = (
            (q[0] / dt.grid_m).floor() as i64,
            (q[1] / dt.grid_m).floor() as i64,
            dt.channel_of(o + yaw_rad),
        );
        *base.entry(key).or_default() += 1;
    }
    let samples = base.values().sum();
    let mut out = Vec::new();
    for h in 0..=levels {
        let mut m: FxHashMap<(i64, i64, usize), u64> = FxHashMap::default();
        for (&(x, y, c), &n) in &base {
            *m.entry((x >> h, y >> h, c)).or_default() += n;
        }
        let mut v: Vec<(i64, i64, usize, u64)> =
            m.into_iter().map(|((x, y, c), n)| (x, y, c, n)).collect();
        v.sort_unstable();
        out.push(v);
    }
    Template {
        yaw_rad,
        samples,
        levels: out,
    }
}

/// One pose of the search: yaw index, cell (i, j) of the pose, cost (sum of tensor units).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub struct RawPose {
    /// Cost: the sum of the tensor over the samples (units of τ/255).
    pub cost: u64,
    /// Index into the templates.
    pub yaw_index: usize,
    /// Cell x of the pose.
    pub i: i64,
    /// Cell y of the pose.
    pub j: i64,
}

/// A translation search domain in cells: `[i0, i1) × [j0, j1)`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Domain {
    /// First cell x.
    pub i0: i64,
    /// First cell y.
    pub j0: i64,
    /// One past the last cell x.
    pub i1: i64,
    /// One past the last cell y.
    pub j1: i64,
}

impl Domain {
    /// The cells whose corner lies in `min..max` (metres).
    pub fn from_box(dt: &DtTensor, min: [f64; 2], max: [f64; 2]) -> Domain {
        let (i0, j0) = dt.cell_of(min);
        let (i1, j1) = dt.cell_of(max);
        Domain {
            i0,
            j0,
            i1: i1 + 1,
            j1: j1 + 1,
        }
    }

    /// Number of cells.
    pub fn cells(&self) -> u64 {
        ((self.i1 - self.i0).max(0) * (self.j1 - self.j0).max(0)) as u64
    }
}

/// Exact cost of a template at cell (i, j).
#[inline]
pub fn pose_cost(dt: &DtTensor, t: &Template, i: i64, j: i64) -> u64 {
    t.levels[0]
        .iter()
        .map(|&(x, y, c, n)| dt.get(c, i + x, j + y) as u64 * n)
        .sum()
}

/// The bound of a box at level h (the exact cost at level 0); the sum stops as soon as it
/// exceeds `limit` (the returned value is then some partial sum > `limit`).
#[inline]
fn box_bound(
    dt: &DtTensor,
    pyr: &BoundPyramid,
    t: &Template,
    h: u32,
    bx: i64,
    by: i64,
    limit: u64,
) -> u64 {
    let mut sum = 0u64;
    match h {
        0 => {
            for &(x, y, c, n) in &t.levels[0] {
                sum += dt.get(c, bx + x, by + y) as u64 * n;
                if sum > limit {
                    break;
                }
            }
        }
        1 => {
            // Exact 2 × 2 window minima at full resolution.
            let (x0, y0) = (bx << 1, by << 1);
            for &(x, y, c, n) in &t.levels[0] {
                sum += pyr.get_fine(dt.channels, c, x0 + x, y0 + y) as u64 * n;
                if sum > limit {
                    break;
                }
            }
        }
        _ => {
            for &(x, y, c, n) in &t.levels[h as usize] {
                sum += pyr.get(dt.channels, h, c, bx + x, by + y) as u64 * n;
                if sum > limit {
                    break;
                }
            }
        }
    }
    sum
}

/// Largest cost within `factor` of `best`.
fn limit_of(best: u64, factor: (u64, u64)) -> u64 {
    let l = (best as u128) * (factor.0 as u128) / (factor.1.max(1) as u128);
    l.min(u64::MAX as u128) as u64
}

fn within(cost: u64, best: u64, factor: (u64, u64)) -> bool {
    (cost as u128) * (factor.1 as u128) <= (best as u128) * (factor.0 as u128)
}

/// Statistics of one search.
#[derive(Debug, Clone, Copy, Default, PartialEq, serde::Serialize)]
pub struct SearchStats {
    /// Boxes whose bound was evaluated.
    pub boxes: u64,
    /// Full-resolution poses evaluated.
    pub leaves: u64,
    /// Poses in the exhaustive search space.
    pub space: u64,
}

/// Every pose (over all templates and the domain) with cost ≤ factor × minimum, sorted by
/// (cost, yaw, i, j), by branch and bound. Equal to [`exhaustive_search`].
pub fn search(
    dt: &DtTensor,
    pyr: &BoundPyramid,
    templates: &[Template],
    domain: Domain,
    factor: (u64, u64),
) -> (Vec<RawPose>, SearchStats) {
    let top = pyr.top();
    let s = 1i64 << top;
    let mut roots: Vec<(u64, usize, i64, i64)> = Vec::new();
    let bi0 = domain.i0 >> top;
    let bj0 = domain.j0 >> top;
    let bi1 = (domain.i1 - 1) >> top;
    let bj1 = (domain.j1 - 1) >> top;
    let stats_boxes = AtomicU64::new(0);
    let stats_leaves = AtomicU64::new(0);
    if domain.cells() == 0 {
        return (Vec::new(), SearchStats::default());
    }
    for (k, t) in templates.iter().enumerate() {
        for bj in bj0..=bj1 {
            for bi in bi0..=bi1 {
                roots.push((
                    box_bound(dt, pyr, t, top, bi, bj, u64::MAX),
                    k,
                    bi * s,
                    bj * s,
                ));
            }
        }
    }
    stats_boxes.fetch_add(roots.len() as u64, Ordering::Relaxed);
    roots.sort_unstable();
    let best = AtomicU64::new(u64::MAX);
    let mut found: Vec<RawPose> = roots
        .par_iter()
        .with_min_len(16)
        .flat_map_iter(|&(lb, k, x, y)| {
            let mut out = Vec::new();
            let mut stack = vec![(lb, top, x, y)];
            let t = &templates[k];
            let (mut nb, mut nl) = (0u64, 0u64);
            while let Some((lb, h, x, y)) = stack.pop() {
                if !within(lb, best.load(Ordering::Relaxed), factor) {
                    continue;
                }
                if h == 0 {
                    out.push(RawPose {
                        cost: lb,
                        yaw_index: k,
                        i: x,
                        j: y,
                    });
                    best.fetch_min(lb, Ordering::Relaxed);
                    continue;
                }
                let half = 1i64 << (h - 1);
                let mut children: Vec<(u64, u32, i64, i64)> = Vec::with_capacity(4);
                for (dx, dy) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
                    let (cx, cy) = (x + dx * half, y + dy * half);
                    if cx >= domain.i1
                        || cy >= domain.j1
                        || cx + half <= domain.i0
                        || cy + half <= domain.j0
                    {
                        continue;
                    }
                    let ch = h - 1;
                    let limit = limit_of(best.load(Ordering::Relaxed), factor);
                    let b = box_bound(dt, pyr, t, ch, cx >> ch, cy >> ch, limit);
                    if ch == 0 {
                        nl += 1;
                    } else {
                        nb += 1;
                    }
                    if within(b, best.load(Ordering::Relaxed), factor) {
                        children.push((b, ch, cx, cy));
                    }
                }
                children.sort_unstable_by(|a, b| b.cmp(a));
                stack.extend(children);
            }
            stats_boxes.fetch_add(nb, Ordering::Relaxed);
            stats_leaves.fetch_add(nl, Ordering::Relaxed);
            out
        })
        .collect();
    let final_best = best.load(Ordering::Relaxed);
    found.retain(|p| within(p.cost, final_best, factor));
    found.sort_unstable();
    let stats = SearchStats {
        boxes: stats_boxes.load(Ordering::Relaxed),
        leaves: stats_leaves.load(Ordering::Relaxed),
        space: domain.cells() * templates.len() as u64,
    };
    (found, stats)
}

/// Every pose with cost ≤ factor × minimum by evaluating every pose (reference for tests).
pub fn exhaustive_search(
    dt: &DtTensor,
    templates: &[Template],
    domain: Domain,
    factor: (u64, u64),
) -> Vec<RawPose> {
    let mut all = Vec::new();
    for (k, t) in templates.iter().enumerate() {
        for j in domain.j0..domain.j1 {
            for i in domain.i0..domain.i1 {
                all.push(RawPose {
                    cost: pose_cost(dt, t, i, j),
                    yaw_index: k,
                    i,
                    j,
                });
            }
        }
    }
    let Some(min) = all.iter().map(|p| p.cost).min() else {
        return all;
    };
    all.retain(|p| within(p.cost, min, factor));
    all.sort_unstable();
    all
}

/// A pose candidate with its search cost.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct SearchCandidate {
    /// The pose in the map frame.
    pub pose: Pose2,
    /// d_DCM of the search, metres (mean tensor value over the samples).
    pub dcm: f64,
}

/// Raw poses → candidates with non-maximum suppression: in cost order, a pose is dropped when
/// a kept one lies within `radius_m` and `yaw_rad`. O(n) with a hash grid.
pub fn suppress(
    raw: &[RawPose],
    templates: &[Template],
    dt: &DtTensor,
    radius_m: f64,
    yaw_rad: f64,
) -> Vec<SearchCandidate> {
    let mut kept: Vec<SearchCandidate> = Vec::new();
    let mut grid: FxHashMap<(i64, i64), Vec<usize>> = FxHashMap::default();
    let cell = radius_m.max(1e-6);
    for p in raw {
        let Some(t) = templates.get(p.yaw_index) else {
            continue;
        };
        let xy = dt.corner_of(p.i, p.j);
        let pose = Pose2 {
            x: xy[0],
            y: xy[1],
            yaw_rad: t.yaw_rad,
        };
        let key = ((xy[0] / cell).floor() as i64, (xy[1] / cell).floor() as i64);
        let mut suppressed = false;
        'n: for dx in -1..=1 {
            for dy in -1..=1 {
                if let Some(ids) = grid.get(&(key.0 + dx, key.1 + dy)) {
                    for &id in ids {
                        let k = &kept[id].pose;
                        if k.distance_to(&pose) < radius_m
                            && angle_diff(k.yaw_rad, pose.yaw_rad) < yaw_rad
                        {
                            suppressed = true;
                            break 'n;
                        }
                    }
                }
            }
        }
        if suppressed {
            continue;
        }
        grid.entry(key).or_default().push(kept.len());
        kept.push(SearchCandidate {
            pose,
            dcm: p.cost as f64 / dt.units_per_m / t.samples.max(1) as f64,
        });
    }
    kept
}

/// Why a candidate was dropped by [`filter`].
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize)]
pub struct FilterCounts {
    /// Inside a building.
    pub inside_building: usize,
    /// Too far from every street segment.
    pub far_from_street: usize,
}

/// Drops candidates inside a building or farther than `street_distance_m` from every street
/// segment (skipped when the map has no streets).
pub fn filter(
    candidates: Vec<SearchCandidate>,
    index: &MapIndex<'_>,
    has_streets: bool,
    street_distance_m: f64,
) -> (Vec<SearchCandidate>, FilterCounts) {
    let mut counts = FilterCounts::default();
    let kept = candidates
        .into_iter()
        .filter(|c| {
            let p = [c.pose.x, c.pose.y];
            if index.building_at(p).is_some() {
                counts.inside_building += 1;
                return false;
            }
            if has_streets
                && index
                    .nearest_segment(p)
                    .is_none_or(|(_, d)| d > street_distance_m)
            {
                counts.far_from_street += 1;
                return false;
            }
            true
        })
        .collect();
    (kept, counts)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::chamfer::ChamferOptions;
    use proptest::prelude::*;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    fn random_segments(rng: &mut ChaCha8Rng, n: usize, span: f64) -> Vec<Segment> {
        (0..n)
            .map(|_| {
                let a = [rng.gen_range(-span..span), rng.gen_range(-span..span)];
                let ang: f64 = rng.gen_range(0.0..std::f64::consts::TAU);
                let l = rng.gen_range(1.0..8.0);
                Segment::new(a, [a[0] + l * ang.cos(), a[1] + l * ang.sin()])
            })
            .collect()
    }

    fn check_equal_to_exhaustive(seed: u64, levels: u32, factor: (u64, u64)) {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let map: Vec<Segment> = random_segments(&mut rng, 12, 12.0);
        // The scan: some map edges seen from a random pose, plus clutter.
        let truth = Pose2 {
            x: rng.gen_range(-3.0..3.0),
            y: rng.gen_range(-3.0..3.0),
            yaw_rad: rng.gen_range(0.0..std::f64::consts::TAU),
        };
        let (s, c) = truth.yaw_rad.sin_cos();
        let to_scan = |p: [f64; 2]| {
            let (dx, dy) = (p[0] - truth.x, p[1] - truth.y);
            [c * dx + s * dy, -s * dx + c * dy]
        };
        let mut scan: Vec<Segment> = map
            .iter()
            .take(6)
            .map(|e| Segment::new(to_scan(e.a), to_scan(e.b)))
            .collect();
        scan.extend(random_segments(&mut rng, 2, 8.0));
        let options = ChamferOptions {
            grid_m: 0.5,
            ..ChamferOptions::default()
        };
        let dt = DtTensor::build(&map, &options).unwrap();
        let pyr = BoundPyramid::build(&dt, levels);
        let templates: Vec<Template> = (0..8)
            .map(|k| build_template(&scan, k as f64 * 0.8, &dt, levels))
            .collect();
        let domain = Domain::from_box(&dt, [-10.0, -9.0], [9.0, 10.5]);
        let (fast, stats) = search(&dt, &pyr, &templates, domain, factor);
        let slow = exhaustive_search(&dt, &templates, domain, factor);
        assert_eq!(fast, slow, "seed {seed}");
        assert!(stats.leaves <= stats.space + 4 * stats.space / 3);
    }

    #[test]
    fn search_equals_exhaustive_search_by_hand_cases() {
        for seed in 0..4 {
            check_equal_to_exhaustive(seed, 3, (8, 5));
        }
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(24))]
        #[test]
        fn search_equals_exhaustive_search(seed in 0u64..10_000, levels in 1u32..6, num in 5u64..20) {
            check_equal_to_exhaustive(seed, levels, (num, 5));
        }
    }

    #[test]
    fn empty_template_or_domain() {
        let dt = DtTensor::build(&[], &ChamferOptions::default()).unwrap();
        let pyr = BoundPyramid::build(&dt, 2);
        let t = build_template(&[], 0.0, &dt, 2);
        let d = Domain {
            i0: 0,
            j0: 0,
            i1: 0,
            j1: 0,
        };
        assert!(search(&dt, &pyr, &[t], d, (8, 5)).0.is_empty());
    }
}
