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
//! sharing a block and channel are summed once with their count. A best-first phase finds
//! the exact minimum, then a parallel depth-first phase cuts every box whose bound exceeds
//! factor × minimum (see [`search`]): every pose within the factor of the minimum survives,
//! and the result equals exhaustive search ([`exhaustive_search`], checked in the tests).
//! With a count ([`Cap::count`], [`SearchOptions::max_raw_poses`]) the second phase is best
//! first too and stops once no box can hold one of the `count` cheapest poses: the result is
//! then the first `count` poses of the full search, also checked against exhaustive search.

pub use crate::chamfer::Domain;
use crate::chamfer::{stride_shift, BoundPyramid, DtTensor, GridView};
use crate::feasible::FeasibleMask;
use crate::heading::{street_direction, turn_at, HeadingMask};
use crate::{angle_diff, orientation_diff, Pose2, Segment};
use geodata::osm::geometry::point_segment_distance;
use geodata::osm::index::MapIndex;
use rayon::prelude::*;
use rustc_hash::FxHashMap;

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
    /// For a scan from a car ([`crate::sensor::Vehicle`]): candidates heading more than this
    /// from the direction (either way) of every street segment within `street_distance_m`
    /// are dropped, degrees.
    pub along_street_deg: f64,
    /// Most raw poses kept, the cheapest; the search stops once no other pose can be among
    /// them ([`search_capped`] with [`Cap::count`]). 0: every pose within the keep factor.
    pub max_raw_poses: usize,
    /// Box budget (with `max_raw_poses` > 0): once the minimum is known, the search stops
    /// after bounding this many boxes, and its poses are the cheapest found by then
    /// ([`Cap::max_boxes`]); 0: no budget (the result equals exhaustive search).
    pub max_boxes: u64,
    /// Search only feasible poses (outside buildings, near streets; see
    /// [`crate::feasible`]): the factor then refers to the minimum over feasible poses.
    /// False: every pose of the domain, filtered after the search (the thesis' order).
    pub feasible_only: bool,
}

/// Default of [`SearchOptions::max_raw_poses`]: a scan with few walls (a car's) has a flat
/// cost landscape with millions of poses within the keep factor, and keeping 20 000 of them
/// keeps real car scans within the time target without changing any simulated or MCD result
/// (README, *The search keeps the cheapest poses*); it was 2 000 000 until 2026-11-30 and
/// 5 000 until 2026-12-01, when the faster best-first batches made room for 20 000.
pub const MAX_RAW_POSES: usize = 20_000;

/// Default of [`SearchOptions::max_boxes`]: a scan of few walls in a long street of similar
/// façades can need 14 M boxes (8 s) to prove its 20 000 cheapest poses; with 6 M after the
/// minimum every measured result was unchanged (simulated Helsinki HDL-64, VLP-16 and
/// terrestrial, KTH, MCD, real KITTI-360; README, *A box budget*), and the slowest simulated
/// Helsinki scan took 1.7 s instead of 7.9 s.
pub const MAX_BOXES: u64 = 6_000_000;

impl Default for SearchOptions {
    fn default() -> Self {
        SearchOptions {
            yaw_step_deg: 0.5,
            levels: 6,
            keep_factor: (8, 5),
            pose_margin_m: 40.0,
            nms_radius_m: 2.0,
            nms_yaw_rad: 10f64.to_radians(),
            street_distance_m: 12.0,
            along_street_deg: 20.0,
            max_raw_poses: MAX_RAW_POSES,
            max_boxes: MAX_BOXES,
            feasible_only: true,
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
            // Windows at stride 2^(h − k) over the entries of level h − k.
            let k = stride_shift(h);
            let (x0, y0) = (bx << k, by << k);
            for &(x, y, c, n) in &t.levels[(h - k) as usize] {
                sum += pyr.get(h, c, x0 + x, y0 + y) as u64 * n;
                if sum > limit {
                    break;
                }
            }
        }
    }
    sum
}

/// A template's entries at one level as offsets into that level's flat grid.
#[derive(Debug, Clone, Default)]
struct Plan {
    /// (offset into the grid relative to the box's first cell, count), in entry order.
    terms: Vec<(i64, u64)>,
    /// Smallest entry offsets (x, y).
    lo: [i64; 2],
    /// Largest entry offsets (x, y).
    hi: [i64; 2],
}

/// Every template's [`Plan`] per level, with the grid views they index.
struct Plans<'a> {
    views: Vec<GridView<'a>>,
    per_template: Vec<Vec<Plan>>,
}

impl<'a> Plans<'a> {
    fn new(dt: &'a DtTensor, pyr: &'a BoundPyramid, templates: &[Template]) -> Plans<'a> {
        let mut views = vec![dt.view()];
        views.extend((1..=pyr.top()).map_while(|h| pyr.level_view(h)));
        let per_template = templates
            .par_iter()
            .map(|t| {
                views
                    .iter()
                    .enumerate()
                    .map(|(h, v)| {
                        let level = match h {
                            0 | 1 => 0,
                            _ => h - stride_shift(h as u32) as usize,
                        };
                        let entries = t.levels.get(level);
                        let entries = entries.map_or(&[][..], Vec::as_slice);
                        let mut plan = Plan {
                            terms: Vec::with_capacity(entries.len()),
                            lo: [i64::MAX; 2],
                            hi: [i64::MIN; 2],
                        };
                        for &(x, y, c, n) in entries {
                            plan.terms.push(((y * v.w + x) * v.channels + c as i64, n));
                            plan.lo = [plan.lo[0].min(x), plan.lo[1].min(y)];
                            plan.hi = [plan.hi[0].max(x), plan.hi[1].max(y)];
                        }
                        plan
                    })
                    .collect()
            })
            .collect();
        Plans {
            views,
            per_template,
        }
    }

    /// [`box_bound`] by flat offsets when every entry of the box lies in the stored grid
    /// (`None` otherwise): the same terms in the same order, so the same value.
    #[inline]
    fn bound(&self, k: usize, h: u32, bx: i64, by: i64, limit: u64) -> Option<u64> {
        let v = self.views.get(h as usize)?;
        let plan = self.per_template.get(k)?.get(h as usize)?;
        let shift = match h {
            0 => 0,
            1 => 1,
            _ => stride_shift(h),
        };
        let (x0, y0) = (bx << shift, by << shift);
        let (sx, sy) = (x0 + v.offset, y0 + v.offset);
        if plan.terms.is_empty()
            || sx + plan.lo[0] < 0
            || sy + plan.lo[1] < 0
            || sx + plan.hi[0] >= v.w
            || sy + plan.hi[1] >= v.h
        {
            return None;
        }
        let base = (sy * v.w + sx) * v.channels;
        let mut sum = 0u64;
        for &(r, n) in &plan.terms {
            sum += v.data.get((base + r) as usize).copied().unwrap_or(255) as u64 * n;
            if sum > limit {
                break;
            }
        }
        Some(sum)
    }
}

/// Largest cost within `factor` of `best`.
pub fn limit_of(best: u64, factor: (u64, u64)) -> u64 {
    let l = (best as u128) * (factor.0 as u128) / (factor.1.max(1) as u128);
    l.min(u64::MAX as u128) as u64
}

fn within(cost: u64, best: u64, factor: (u64, u64)) -> bool {
    (cost as u128) * (factor.1 as u128) <= (best as u128) * (factor.0 as u128)
}

/// The poses a search may visit: the feasible ones ([`FeasibleMask`]) and, for a car's scan,
/// those with a heading a car can have there ([`HeadingMask`]); no mask: every pose.
#[derive(Debug, Clone, Copy, Default)]
pub struct Masks<'a> {
    /// Feasible positions.
    pub feasible: Option<&'a FeasibleMask>,
    /// Allowed headings per position.
    pub heading: Option<&'a HeadingMask>,
}

impl<'a> Masks<'a> {
    /// The feasible positions only.
    pub fn feasible(mask: Option<&'a FeasibleMask>) -> Masks<'a> {
        Masks {
            feasible: mask,
            heading: None,
        }
    }

    /// Whether box (bx, by) at level h may hold an allowed pose at yaw template k.
    #[inline]
    pub fn any(&self, k: u32, h: u32, bx: i64, by: i64) -> bool {
        self.feasible.is_none_or(|m| m.any(h, bx, by))
            && self.heading.is_none_or(|m| m.any(k as usize, h, bx, by))
    }

    /// Whether the pose at cell (i, j) and yaw template k is allowed.
    pub fn allows(&self, k: usize, i: i64, j: i64) -> bool {
        self.feasible.is_none_or(|m| m.is_feasible(i, j))
            && self.heading.is_none_or(|m| m.allows(k, i, j))
    }
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
    /// The box budget ([`Cap::max_boxes`]) stopped the search before it had proved its
    /// poses the cheapest.
    pub truncated: bool,
}

/// A node of the search: (bound, level h, template, first cell x, first cell y); the node
/// covers the translations `[x, x + 2^h) × [y, y + 2^h)` at its template's yaw, and at h = 0
/// its bound is the exact cost. 24 bytes (cells as i32: a tensor 2^31 cells wide could not
/// be allocated), since the queue holds millions of them: on a real car scan (KITTI-360 2280)
/// the peak memory is 190 MB against 256 MB with 40-byte nodes, and the time in page faults
/// (12 % of the search, `perf`) falls with it.
type Node = (u64, u32, u32, i32, i32);

/// Pushes the children of a node at level h > 0 that meet the domain and whose bound is
/// ≤ `limit` (bound sums stop above it); returns how many bounds were evaluated. A child's
/// bound is the larger of its own and its parent's (both bound the child's poses), so bounds
/// never decrease going down.
#[inline]
#[allow(clippy::too_many_arguments)]
fn expand(
    dt: &DtTensor,
    pyr: &BoundPyramid,
    templates: &[Template],
    plans: &Plans<'_>,
    domain: Domain,
    mask: Masks<'_>,
    &(parent, h, k, x, y): &Node,
    limit: u64,
    out: &mut Vec<Node>,
) -> u64 {
    let Some(t) = templates.get(k as usize) else {
        return 0;
    };
    let (x, y) = (i64::from(x), i64::from(y));
    let half = 1i64 << (h - 1);
    let ch = h - 1;
    let mut evaluated = 0;
    for (dx, dy) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
        let (cx, cy) = (x + dx * half, y + dy * half);
        if cx >= domain.i1 || cy >= domain.j1 || cx + half <= domain.i0 || cy + half <= domain.j0 {
            continue;
        }
        let (bx, by) = (cx >> ch, cy >> ch);
        if !mask.any(k, ch, bx, by) {
            continue;
        }
        evaluated += 1;
        let b = plans
            .bound(k as usize, ch, bx, by, limit)
            .unwrap_or_else(|| box_bound(dt, pyr, t, ch, bx, by, limit))
            .max(parent);
        if b <= limit {
            out.push((b, ch, k, cx as i32, cy as i32));
        }
    }
    evaluated
}

/// Nodes expanded together in the best-first phase.
const BATCH: usize = 1024;

/// Queue buckets a batch takes its nodes from, at most (so that a sparse queue is not
/// scanned far ahead for every batch).
const BATCH_SPAN: usize = 4096;

/// Number of buckets of width `width` for bounds up to `max_bound`.
fn buckets_len(max_bound: u64, width: u64) -> usize {
    (max_bound / width) as usize + 1
}

/// Every pose (over all templates and the domain's cells, only the feasible ones when a
/// `mask` is given) with cost ≤ factor × minimum over those poses, sorted by
/// (cost, yaw, i, j), by branch and bound. Equal to [`exhaustive_search`]. Boxes without a
/// feasible cell are never bounded.
///
/// Two phases, so that no box is bounded against a cut looser than factor × the minimum:
/// 1. best first: the queue starts with the top-level boxes of every yaw; the 1024 best
///    non-leaf entries are expanded at a time (in parallel) until the best entry is a leaf,
///    whose cost is then the minimum (every other entry's bound is at least that cost).
///    Children bounded above factor × the best leaf seen are dropped: they hold no pose within
///    factor × the minimum.
/// 2. depth first, in parallel over the queue's remaining entries within factor × the
///    minimum, with that fixed cut.
///
/// The expanded nodes are exactly those whose bound is ≤ factor × minimum (phase 1 expands
/// those below the minimum), each once.
pub fn search(
    dt: &DtTensor,
    pyr: &BoundPyramid,
    templates: &[Template],
    domain: Domain,
    mask: Masks<'_>,
    factor: (u64, u64),
) -> (Vec<RawPose>, SearchStats) {
    let (found, stats, _) = search_capped(dt, pyr, templates, domain, mask, factor, Cap::NONE);
    (found, stats)
}

/// A cap on a search: poses costing more than `cost` are not wanted, and `minimum_only`
/// stops once the minimum is known (a map tile's first pass, [`crate::tiles`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Cap {
    /// The most a returned pose may cost.
    pub cost: u64,
    /// Return the minimum only (no poses).
    pub minimum_only: bool,
    /// Return at most this many poses, the first ones in (cost, yaw, i, j) order; 0: all.
    pub count: usize,
    /// With a count: once the minimum is known, stop after bounding this many boxes; the
    /// poses are then the cheapest of those found, not necessarily of all (0: no budget).
    pub max_boxes: u64,
}

impl Cap {
    /// No cap.
    pub const NONE: Cap = Cap {
        cost: u64::MAX,
        minimum_only: false,
        count: 0,
        max_boxes: 0,
    };
}

/// [`search`] with a cap: every pose with cost ≤ min(factor × minimum, `cap.cost`) (only the
/// first `cap.count` of them when that is not 0), and the minimum when it is ≤ `cap.cost`
/// (`None` otherwise: no pose costs that little). Boxes bounded above the cap are never
/// expanded, so a region that cannot beat it costs little.
///
/// With a count, phase 2 is best first too, and its cut falls to an upper bound on the
/// `cap.count`-th cheapest leaf found so far (the upper edge of the queue bucket where the
/// leaves' running count reaches it): no pose of a box bounded above that cut can be among
/// the first `cap.count`, so the result equals the uncounted one truncated, and a flat cost
/// landscape costs about `cap.count` leaves rather than every pose within the factor.
pub fn search_capped(
    dt: &DtTensor,
    pyr: &BoundPyramid,
    templates: &[Template],
    domain: Domain,
    mask: Masks<'_>,
    factor: (u64, u64),
    cap: Cap,
) -> (Vec<RawPose>, SearchStats, Option<u64>) {
    let mut stats = SearchStats {
        space: domain.cells() * templates.len() as u64,
        ..SearchStats::default()
    };
    if domain.cells() == 0 || templates.is_empty() {
        return (Vec::new(), stats, None);
    }
    let top = pyr.top();
    let plans = Plans::new(dt, pyr, templates);
    let (bi0, bj0) = (domain.i0 >> top, domain.j0 >> top);
    let (bi1, bj1) = ((domain.i1 - 1) >> top, (domain.j1 - 1) >> top);
    let roots: Vec<Node> = templates
        .par_iter()
        .enumerate()
        .flat_map_iter(|(k, t)| {
            let plans = &plans;
            (bj0..=bj1).flat_map(move |bj| {
                (bi0..=bi1)
                    .filter(move |&bi| mask.any(k as u32, top, bi, bj))
                    .map(move |bi| {
                        let b = plans
                            .bound(k, top, bi, bj, u64::MAX)
                            .unwrap_or_else(|| box_bound(dt, pyr, t, top, bi, bj, u64::MAX));
                        (b, top, k as u32, (bi << top) as i32, (bj << top) as i32)
                    })
            })
        })
        .collect();
    let count = |h: u32, n: u64, stats: &mut SearchStats| {
        if h == 0 {
            stats.leaves += n;
        } else {
            stats.boxes += n;
        }
    };
    count(top, roots.len() as u64, &mut stats);
    // Phase 1, with a bucket queue (bounds are integers, and children's bounds are at least
    // their parent's, so the queue's minimum only grows).
    let max_bound = roots
        .iter()
        .map(|r| r.0)
        .max()
        .unwrap_or(0)
        .max(255 * templates.iter().map(|t| t.samples).max().unwrap_or(0));
    let width = (max_bound / (1 << 20)).max(1);
    let mut buckets: Vec<Vec<Node>> = vec![Vec::new(); buckets_len(max_bound, width)];
    let bucket_of = |b: u64| ((b / width) as usize).min(buckets_len(max_bound, width) - 1);
    for r in roots.into_iter().filter(|r| r.0 <= cap.cost) {
        if let Some(v) = buckets.get_mut(bucket_of(r.0)) {
            v.push(r);
        }
    }
    let mut leaves: Vec<Node> = Vec::new();
    let mut best_leaf = u64::MAX;
    let mut cursor = 0usize;
    let mut batch: Vec<Node> = Vec::with_capacity(BATCH);
    let mut count_cut = CountCut::new(cap.count, buckets.len());
    loop {
        while cursor < buckets.len() && buckets[cursor].is_empty() {
            cursor += 1;
        }
        // At least as large as best_leaf even for a factor below 1.
        let cut = limit_of(best_leaf, factor)
            .max(best_leaf)
            .min(cap.cost)
            .min(count_cut.cut(width));
        let floor = (cursor as u64).saturating_mul(width);
        // Phase 1 is done when every queued box's bound is at least the best leaf's cost;
        // with a count, phase 2 goes on best first until every bound is above the cut.
        let phase_1_done = floor >= best_leaf;
        if cursor >= buckets.len()
            || (phase_1_done && (cap.count == 0 || cap.minimum_only))
            || floor > cut
        {
            break;
        }
        // The budget: the minimum is known, more boxes would only prove the rest.
        if phase_1_done && cap.max_boxes > 0 && stats.boxes >= cap.max_boxes {
            stats.truncated = true;
            break;
        }
        // The batch takes up to BATCH nodes from the lowest BATCH_SPAN buckets within the cut
        // (a flat cost landscape spreads its boxes thinly over the buckets: one bucket at a
        // time made batches of ~100 nodes, whose hand-over to the thread pool cost more than
        // their work).
        batch.clear();
        let mut b = cursor;
        let end = buckets.len().min(cursor.saturating_add(BATCH_SPAN));
        while batch.len() < BATCH && b < end && (b as u64).saturating_mul(width) <= cut {
            let bucket = &mut buckets[b];
            let take = bucket.len().min(BATCH - batch.len());
            batch.extend(bucket.drain(bucket.len() - take..).filter(|n| n.0 <= cut));
            b += 1;
        }
        let expanded: Vec<(u64, u64, Vec<Node>)> = batch
            .par_chunks(BATCH / 8)
            .map(|chunk| {
                let (mut boxes, mut leaves, mut out) = (0, 0, Vec::with_capacity(4 * chunk.len()));
                for node in chunk {
                    let n = expand(
                        dt, pyr, templates, &plans, domain, mask, node, cut, &mut out,
                    );
                    if node.1 == 1 {
                        leaves += n;
                    } else {
                        boxes += n;
                    }
                }
                (boxes, leaves, out)
            })
            .collect();
        for (boxes, leaves_n, kids) in expanded {
            stats.boxes += boxes;
            stats.leaves += leaves_n;
            for kid in kids {
                if kid.1 == 0 {
                    best_leaf = best_leaf.min(kid.0);
                    count_cut.add(bucket_of(kid.0));
                    leaves.push(kid);
                } else if let Some(v) = buckets.get_mut(bucket_of(kid.0)) {
                    v.push(kid);
                }
            }
        }
    }
    if best_leaf == u64::MAX || best_leaf > cap.cost {
        return (Vec::new(), stats, None);
    }
    let minimum = best_leaf;
    if cap.minimum_only {
        return (Vec::new(), stats, Some(minimum));
    }
    let limit = limit_of(minimum, factor).min(cap.cost);
    if cap.count > 0 {
        // Phase 2 ran best first above: every pose that can be among the first `count` is
        // a leaf found.
        let mut found: Vec<RawPose> = leaves
            .into_iter()
            .filter(|node| node.0 <= limit)
            .map(|(cost, _, k, i, j)| RawPose {
                cost,
                yaw_index: k as usize,
                i: i64::from(i),
                j: i64::from(j),
            })
            .collect();
        found.sort_unstable();
        found.truncate(cap.count);
        return (found, stats, Some(minimum));
    }
    // Phase 2, depth first.
    let frontier: Vec<Node> = buckets
        .into_iter()
        .flatten()
        .chain(leaves)
        .filter(|node| node.0 <= limit)
        .collect();
    // One stack per rayon split, reused across its roots.
    let (found, boxes, leaves, _) = frontier
        .par_iter()
        .with_min_len(16)
        .fold(
            || (Vec::new(), 0u64, 0u64, Vec::with_capacity(64)),
            |(mut found, mut boxes, mut leaves, mut stack), root| {
                stack.push(*root);
                while let Some(node) = stack.pop() {
                    let (cost, h, k, i, j) = node;
                    if h == 0 {
                        found.push(RawPose {
                            cost,
                            yaw_index: k as usize,
                            i: i64::from(i),
                            j: i64::from(j),
                        });
                        continue;
                    }
                    let n = expand(
                        dt, pyr, templates, &plans, domain, mask, &node, limit, &mut stack,
                    );
                    if h == 1 {
                        leaves += n;
                    } else {
                        boxes += n;
                    }
                }
                (found, boxes, leaves, stack)
            },
        )
        .reduce(
            || (Vec::new(), 0, 0, Vec::new()),
            |mut a, b| {
                a.0.extend(b.0);
                (a.0, a.1 + b.1, a.2 + b.2, a.3)
            },
        );
    stats.boxes += boxes;
    stats.leaves += leaves;
    let mut found = found;
    found.sort_unstable();
    (found, stats, Some(minimum))
}

/// Upper bound on the `count`-th cheapest leaf found, from the leaves' counts per queue
/// bucket: the bucket `at` where the running count first reaches `count`, kept as leaves
/// arrive (it only moves down).
struct CountCut {
    count: u64,
    per_bucket: Vec<u64>,
    /// Leaves found in total.
    total: u64,
    /// The bucket and the leaves in buckets 0..=it, once `total` ≥ `count`.
    at: Option<(usize, u64)>,
}

impl CountCut {
    fn new(count: usize, buckets: usize) -> CountCut {
        CountCut {
            count: count as u64,
            per_bucket: if count > 0 {
                vec![0; buckets]
            } else {
                Vec::new()
            },
            total: 0,
            at: None,
        }
    }

    /// Counts a leaf in bucket `b`.
    fn add(&mut self, b: usize) {
        if self.count == 0 {
            return;
        }
        let Some(slot) = self.per_bucket.get_mut(b) else {
            return;
        };
        *slot += 1;
        self.total += 1;
        match &mut self.at {
            Some((at, below)) if b <= *at => *below += 1,
            Some(_) => {}
            None if self.total >= self.count => {
                let mut below = 0;
                for (at, &n) in self.per_bucket.iter().enumerate() {
                    below += n;
                    if below >= self.count {
                        self.at = Some((at, below));
                        break;
                    }
                }
            }
            None => {}
        }
        // Move down while the buckets below still hold `count` leaves.
        if let Some((at, below)) = &mut self.at {
            while *at > 0 && *below - self.per_bucket[*at] >= self.count {
                *below -= self.per_bucket[*at];
                *at -= 1;
            }
        }
    }

    /// The cut: the upper edge of bucket `at` (u64::MAX until `count` leaves are found; the
    /// last bucket also holds every larger bound).
    fn cut(&self, width: u64) -> u64 {
        match self.at {
            Some((at, _)) if at + 1 < self.per_bucket.len() => {
                ((at as u64 + 1).saturating_mul(width)).saturating_sub(1)
            }
            _ => u64::MAX,
        }
    }
}

/// Every (feasible) pose with cost ≤ factor × minimum by evaluating every pose (reference
/// for tests).
pub fn exhaustive_search(
    dt: &DtTensor,
    templates: &[Template],
    domain: Domain,
    mask: Masks<'_>,
    factor: (u64, u64),
) -> Vec<RawPose> {
    let mut all = Vec::new();
    for (k, t) in templates.iter().enumerate() {
        for j in domain.j0..domain.j1 {
            for i in domain.i0..domain.i1 {
                if !mask.allows(k, i, j) {
                    continue;
                }
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

/// Whether non-maximum suppression drops `pose` for the better `kept`: within `radius_m`
/// and `yaw_rad` of it.
pub(crate) fn suppresses(kept: &Pose2, pose: &Pose2, radius_m: f64, yaw_rad: f64) -> bool {
    kept.distance_to(pose) < radius_m && angle_diff(kept.yaw_rad, pose.yaw_rad) < yaw_rad
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
                        if suppresses(&kept[id].pose, &pose, radius_m, yaw_rad) {
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
    /// Heading across every street near it (scans from a car only).
    pub across_streets: usize,
}

/// Whether a pose at `p` heading `yaw_rad` runs along (either way, within `max_rad`) a
/// street segment within `radius_m` of it, or lies within `radius_m` of a turn of the
/// network (a node where two street segments meet at more than `max_rad`: a car turning
/// there heads anywhere between them).
pub fn along_a_street(
    index: &MapIndex<'_>,
    p: [f64; 2],
    yaw_rad: f64,
    radius_m: f64,
    max_rad: f64,
) -> bool {
    let segments = &index.map().streets.segments;
    let near: Vec<&geodata::osm::model::StreetSegment> = index
        .segments_in_box(
            [p[0] - radius_m, p[1] - radius_m],
            [p[0] + radius_m, p[1] + radius_m],
        )
        .into_iter()
        .filter_map(|i| segments.get(i))
        .collect();
    let along = near.iter().any(|s| {
        orientation_diff(yaw_rad, street_direction(s)) <= max_rad
            && point_segment_distance(p, s.a, s.b) <= radius_m
    });
    along
        || near.iter().enumerate().any(|(k, s)| {
            near[k + 1..].iter().any(|t| {
                turn_at(s, t, max_rad)
                    .is_some_and(|node| (node[0] - p[0]).hypot(node[1] - p[1]) <= radius_m)
            })
        })
}

/// The street filters of [`filter`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StreetFilter {
    /// Candidates farther than this from every street segment are dropped, metres.
    pub distance_m: f64,
    /// When set, candidates heading more than this (radians, either way) from every street
    /// segment within `distance_m` are dropped too (a car drives along a street).
    pub along_rad: Option<f64>,
}

/// Drops candidates inside a building, farther than the street distance from every street
/// segment, or (when asked) heading across every street near them; the street filters are
/// skipped when the map has no streets. `place` gives the spatial index of the map around a
/// position and whether that map has streets.
pub fn filter<'i>(
    candidates: Vec<SearchCandidate>,
    place: impl Fn([f64; 2]) -> (&'i MapIndex<'i>, bool),
    streets: StreetFilter,
) -> (Vec<SearchCandidate>, FilterCounts) {
    let mut counts = FilterCounts::default();
    let kept = candidates
        .into_iter()
        .filter(|c| {
            let p = [c.pose.x, c.pose.y];
            let (index, has_streets) = place(p);
            if index.building_at(p).is_some() {
                counts.inside_building += 1;
                return false;
            }
            if !has_streets {
                return true;
            }
            if index
                .nearest_segment(p)
                .is_none_or(|(_, d)| d > streets.distance_m)
            {
                counts.far_from_street += 1;
                return false;
            }
            if let Some(max_rad) = streets.along_rad {
                if !along_a_street(index, p, c.pose.yaw_rad, streets.distance_m, max_rad) {
                    counts.across_streets += 1;
                    return false;
                }
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

    /// A map of streets only.
    fn street_map(segments: Vec<geodata::osm::model::StreetSegment>) -> geodata::osm::OsmMap {
        geodata::osm::OsmMap {
            frame: geodata::projection::LocalFrame::new(48.15, 11.57).unwrap(),
            bbox_lonlat: [0.0; 4],
            buildings: Vec::new(),
            highways: Vec::new(),
            streets: geodata::osm::model::StreetNetwork {
                segments,
                ..Default::default()
            },
            stats: Default::default(),
        }
    }

    #[test]
    fn a_pose_runs_along_a_street_near_it_either_way() {
        use geodata::osm::model::StreetSegment;
        let seg = |from: i64, a: [f64; 2], b: [f64; 2]| StreetSegment {
            way_index: 0,
            index_in_way: 0,
            from_node: from,
            to_node: from + 1,
            a,
            b,
            length_m: (b[0] - a[0]).hypot(b[1] - a[1]),
            highway: "residential".into(),
        };
        // An L: a street along x, one along y from its end.
        let map = street_map(vec![
            seg(1, [0.0, 0.0], [100.0, 0.0]),
            seg(2, [100.0, 0.0], [100.0, 80.0]),
        ]);
        let index = MapIndex::new(&map);
        let max = 20f64.to_radians();
        let along = |x: f64, y: f64, yaw_deg: f64| {
            along_a_street(&index, [x, y], yaw_deg.to_radians(), 12.0, max)
        };
        assert!(along(50.0, 5.0, 10.0));
        assert!(along(50.0, 5.0, 190.0));
        assert!(along(50.0, -5.0, -170.0));
        assert!(!along(50.0, 5.0, 30.0));
        assert!(!along(50.0, 5.0, 90.0));
        // Near the corner both directions are streets near the pose, and a car turning
        // there heads anywhere between them.
        assert!(along(95.0, 5.0, 90.0));
        assert!(along(95.0, 5.0, 0.0));
        assert!(along(95.0, 5.0, 45.0));
        // Beyond the turn's radius the headings are the street's again.
        assert!(along(100.0 - 13.0, 5.0, 0.0));
        assert!(!along(100.0 - 13.0, 5.0, 45.0));
        // Beyond the radius of every street: nothing to run along.
        assert!(!along(50.0, 13.0, 0.0));
    }

    /// Checks every search against exhaustive search; returns how many budgeted searches
    /// the budget stopped.
    fn check_equal_to_exhaustive(seed: u64, levels: u32, factor: (u64, u64)) -> usize {
        let mut truncated_runs = 0;
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
        let (fast, stats) = search(&dt, &pyr, &templates, domain, Masks::default(), factor);
        let slow = exhaustive_search(&dt, &templates, domain, Masks::default(), factor);
        assert_eq!(fast, slow, "seed {seed}");
        assert!(stats.leaves <= stats.space + 4 * stats.space / 3);
        // With a count: the first `count` poses of the uncounted search, with no more leaves.
        for count in [1, 2, 7, slow.len() / 3, slow.len(), slow.len() + 5] {
            let cap = Cap {
                count: count.max(1),
                ..Cap::NONE
            };
            let (counted, counted_stats, minimum) =
                search_capped(&dt, &pyr, &templates, domain, Masks::default(), factor, cap);
            let mut expected = slow.clone();
            expected.truncate(count.max(1));
            assert_eq!(counted, expected, "seed {seed}, count {count}");
            assert_eq!(minimum, slow.first().map(|p| p.cost));
            assert!(
                counted_stats.leaves <= stats.leaves,
                "seed {seed}, count {count}"
            );
            assert!(!counted_stats.truncated);
            // A box budget: the minimum is still exact and comes first, the poses are
            // poses of the exhaustive search (a sorted subset); a budget the search does not
            // reach changes nothing.
            for max_boxes in [1, counted_stats.boxes / 2, counted_stats.boxes + 1] {
                let (budget, budget_stats, budget_min) = search_capped(
                    &dt,
                    &pyr,
                    &templates,
                    domain,
                    Masks::default(),
                    factor,
                    Cap { max_boxes, ..cap },
                );
                assert_eq!(budget_min, minimum, "seed {seed}, budget {max_boxes}");
                assert_eq!(budget.first().map(|p| p.cost), minimum, "seed {seed}");
                assert!(budget.iter().all(|p| slow.contains(p)), "seed {seed}");
                assert!(budget.windows(2).all(|w| w[0] <= w[1]), "seed {seed}");
                if max_boxes > counted_stats.boxes {
                    assert_eq!(budget, counted, "seed {seed}, budget {max_boxes}");
                    assert!(!budget_stats.truncated);
                }
                if budget_stats.truncated {
                    truncated_runs += 1;
                    assert!(budget_stats.boxes >= max_boxes, "seed {seed}");
                    assert!(budget_stats.boxes <= counted_stats.boxes, "seed {seed}");
                }
            }
        }
        // Restricted to a mask of random infeasible rectangles (buildings).
        let (w, h) = (domain.i1 - domain.i0, domain.j1 - domain.j0);
        let mut flags = vec![true; (w * h) as usize];
        for _ in 0..6 {
            let (x0, y0) = (rng.gen_range(0..w), rng.gen_range(0..h));
            let (x1, y1) = (
                (x0 + rng.gen_range(2..16)).min(w),
                (y0 + rng.gen_range(2..16)).min(h),
            );
            for y in y0..y1 {
                for x in x0..x1 {
                    flags[(y * w + x) as usize] = false;
                }
            }
        }
        let mask = FeasibleMask::from_cells(domain, flags, levels);
        let feasible = Masks::feasible(Some(&mask));
        let (fast, _) = search(&dt, &pyr, &templates, domain, feasible, factor);
        let slow = exhaustive_search(&dt, &templates, domain, feasible, factor);
        assert_eq!(fast, slow, "seed {seed}, masked");
        let count = (slow.len() / 2).max(1);
        let cap = Cap {
            count,
            cost: slow.last().map_or(u64::MAX, |p| p.cost),
            minimum_only: false,
            max_boxes: 0,
        };
        let (counted, _, _) = search_capped(&dt, &pyr, &templates, domain, feasible, factor, cap);
        assert_eq!(
            counted,
            slow[..count.min(slow.len())],
            "seed {seed}, masked, count"
        );
        assert!(fast.iter().all(|p| mask.is_feasible(p.i, p.j)));
        // With a heading mask from a random street network too (a car's search).
        let streets = random_streets(&mut rng, 5, 12.0);
        let yaws: Vec<f64> = templates.iter().map(|t| t.yaw_rad).collect();
        let heading = HeadingMask::build(
            &streets,
            &dt,
            domain,
            &yaws,
            rng.gen_range(1.0..6.0),
            rng.gen_range(0.1..0.6),
            levels,
        );
        for feasible in [None, Some(&mask)] {
            let masks = Masks {
                feasible,
                heading: Some(&heading),
            };
            let (fast, _) = search(&dt, &pyr, &templates, domain, masks, factor);
            let slow = exhaustive_search(&dt, &templates, domain, masks, factor);
            assert_eq!(fast, slow, "seed {seed}, heading mask");
            let count = (slow.len() / 2).max(1);
            let cap = Cap { count, ..Cap::NONE };
            let (counted, _, _) = search_capped(&dt, &pyr, &templates, domain, masks, factor, cap);
            assert_eq!(
                counted,
                slow[..count.min(slow.len())],
                "seed {seed}, heading, count"
            );
            assert!(fast.iter().all(|p| heading.allows(p.yaw_index, p.i, p.j)));
        }
        truncated_runs
    }

    /// A random street network: `n` ways of two or three segments around the origin, some
    /// sharing a node with the way before (a turn or a straight continuation).
    fn random_streets(
        rng: &mut ChaCha8Rng,
        n: usize,
        span: f64,
    ) -> Vec<geodata::osm::model::StreetSegment> {
        let mut out: Vec<geodata::osm::model::StreetSegment> = Vec::new();
        let mut node = 1i64;
        for w in 0..n {
            let (mut id, mut a) = match out.last() {
                Some(last) if rng.gen_bool(0.5) => (last.to_node, last.b),
                _ => {
                    node += 1;
                    (
                        node,
                        [rng.gen_range(-span..span), rng.gen_range(-span..span)],
                    )
                }
            };
            for k in 0..rng.gen_range(2..4) {
                let ang: f64 = rng.gen_range(0.0..std::f64::consts::TAU);
                let l = rng.gen_range(2.0..10.0);
                let b = [a[0] + l * ang.cos(), a[1] + l * ang.sin()];
                node += 1;
                out.push(geodata::osm::model::StreetSegment {
                    way_index: w,
                    index_in_way: k,
                    from_node: id,
                    to_node: node,
                    a,
                    b,
                    length_m: l,
                    highway: "residential".into(),
                });
                (id, a) = (node, b);
            }
        }
        out
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(48))]
        /// The heading mask keeps every pose the street filter keeps, on the whole lattice and
        /// on a window of it (a map tile's) alike.
        #[test]
        fn heading_mask_keeps_every_pose_along_a_street(
            seed in 0u64..100_000,
            radius in 1.0f64..14.0,
            max_deg in 2.0f64..45.0,
            window in (0i64..13, 0i64..13),
        ) {
            let mut rng = ChaCha8Rng::seed_from_u64(seed);
            let streets = random_streets(&mut rng, 4, 15.0);
            let map = street_map(streets.clone());
            let index = MapIndex::new(&map);
            let walls = random_segments(&mut rng, 6, 15.0);
            let options = ChamferOptions { grid_m: 0.5, ..ChamferOptions::default() };
            let dt = DtTensor::build(&walls, &options).unwrap();
            let yaws: Vec<f64> = (0..48).map(|k| k as f64 * std::f64::consts::TAU / 48.0).collect();
            let max = max_deg.to_radians();
            let domain = Domain::from_box(&dt, [-20.0, -20.0], [20.0, 20.0]);
            let whole = HeadingMask::build(&streets, &dt, domain, &yaws, radius, max, 5);
            // A window starting `window` cells into the lattice, as a tile's tensor.
            let size = [(dt.width as i64 - window.0) as usize, (dt.height as i64 - window.1) as usize];
            let tile = DtTensor::build_window(&walls, &options, dt.origin, [window.0, window.1], size).unwrap();
            let local = Domain {
                i0: (domain.i0 - window.0).max(0),
                j0: (domain.j0 - window.1).max(0),
                i1: domain.i1 - window.0,
                j1: domain.j1 - window.1,
            };
            let part = HeadingMask::build(&streets, &tile, local, &yaws, radius, max, 5);
            for _ in 0..400 {
                let (i, j) = (rng.gen_range(domain.i0..domain.i1), rng.gen_range(domain.j0..domain.j1));
                let k = rng.gen_range(0..yaws.len());
                let p = dt.corner_of(i, j);
                if along_a_street(&index, p, yaws[k], radius, max) {
                    prop_assert!(whole.allows(k, i, j), "pose {p:?} yaw {k} dropped");
                }
                let (li, lj) = (i - window.0, j - window.1);
                if li >= local.i0 && lj >= local.j0 {
                    prop_assert_eq!(part.allows(k, li, lj), whole.allows(k, i, j));
                    // Every box holding the pose may hold an allowed one when it is allowed.
                    for h in 0..=5u32 {
                        if part.allows(k, li, lj) {
                            prop_assert!(part.any(k, h, li >> h, lj >> h));
                        }
                        if whole.allows(k, i, j) {
                            prop_assert!(whole.any(k, h, i >> h, j >> h));
                        }
                    }
                }
            }
        }
    }

    #[test]
    fn search_equals_exhaustive_search_by_hand_cases() {
        let mut truncated_runs = 0;
        for seed in 0..4 {
            truncated_runs += check_equal_to_exhaustive(seed, 3, (8, 5));
        }
        // The budget did stop some of those searches.
        assert!(truncated_runs > 0);
        // A case where a count cut one bucket too low loses a pose tied at the cut.
        check_equal_to_exhaustive(7864, 1, (8, 5));
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(24))]
        #[test]
        fn search_equals_exhaustive_search(seed in 0u64..10_000, levels in 1u32..6, num in 5u64..20) {
            check_equal_to_exhaustive(seed, levels, (num, 5));
        }
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(64))]
        #[test]
        fn count_cut_is_the_upper_edge_of_the_kth_cheapest_leafs_bucket(
            costs in proptest::collection::vec(0u64..400, 0..120),
            count in 1usize..40,
            width in 1u64..12,
        ) {
            let buckets = buckets_len(399, width);
            let mut cut = CountCut::new(count, buckets);
            let mut seen: Vec<u64> = Vec::new();
            for &c in &costs {
                cut.add(((c / width) as usize).min(buckets - 1));
                seen.push(c);
                seen.sort_unstable();
                let expected = match seen.get(count - 1) {
                    Some(&kth) if (kth / width) as usize + 1 < buckets => {
                        (kth / width + 1) * width - 1
                    }
                    _ => u64::MAX,
                };
                prop_assert_eq!(cut.cut(width), expected);
            }
        }
    }

    #[test]
    fn flat_plans_equal_box_bounds() {
        let mut rng = ChaCha8Rng::seed_from_u64(11);
        let map = random_segments(&mut rng, 20, 20.0);
        let scan = random_segments(&mut rng, 6, 6.0);
        let dt = DtTensor::build(&map, &ChamferOptions::default()).unwrap();
        let pyr = BoundPyramid::build(&dt, 4);
        let templates: Vec<Template> = (0..6)
            .map(|k| build_template(&scan, k as f64, &dt, 4))
            .collect();
        let plans = Plans::new(&dt, &pyr, &templates);
        let mut fast = 0;
        for _ in 0..4000 {
            let k = rng.gen_range(0..templates.len());
            let h = rng.gen_range(0..=4u32);
            let span = (dt.width.max(dt.height) as i64 >> h) + 4;
            let (bx, by) = (rng.gen_range(-4..span), rng.gen_range(-4..span));
            let limit = if rng.gen_bool(0.5) {
                u64::MAX
            } else {
                rng.gen_range(0..3000)
            };
            if let Some(b) = plans.bound(k, h, bx, by, limit) {
                assert_eq!(b, box_bound(&dt, &pyr, &templates[k], h, bx, by, limit));
                fast += 1;
            }
        }
        assert!(fast > 500, "{fast}");
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
        assert!(search(&dt, &pyr, &[t], d, Masks::default(), (8, 5))
            .0
            .is_empty());
    }
}
