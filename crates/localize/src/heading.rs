//! The headings a car can have where it stands: per search box and yaw, whether some street
//! near the box runs along that yaw (either way) or a turn of the street network is near it —
//! a superset of the poses that [`crate::candidates::along_a_street`] keeps, as a mask over
//! the search, so that for a car's scan the minimum that the keep factor refers to, and the
//! cheapest poses kept ([`crate::candidates::Cap::count`]), are those of poses a car can have.
//!
//! The flags are set on *base boxes* of 2^[`BASE_LEVEL`] × 2^[`BASE_LEVEL`] cells of the whole
//! lattice (boxes aligned on lattice cells, not on a tensor window's), so that a pose's flag
//! does not depend on which window (a map tile's, [`crate::tiles`]) searches it: a pose at
//! lattice cell g and yaw k is allowed when its base box is. A base box is flagged for yaw k
//! when a street segment lies within `radius + h` of the box's centre (h: half the diagonal
//! spanned by the box's cell corners) and runs within `max_rad` of yaw k, or when a turn (a
//! node shared by two street segments meeting at more than `max_rad`) lies within `radius + h`
//! of it. Every pose `along_a_street` keeps is within `radius` of such a segment or turn, so
//! within `radius + h` of its box's centre: the mask never drops a pose the street filter
//! keeps. Boxes of the search pyramid (aligned on the window's own cells) are flagged when
//! any base box they meet is. Hand-written (no crate keeps per-yaw flags over a box pyramid);
//! cost O(Σ street segment reach in base boxes × yaws / 64 + domain boxes × yaws / 64).

use crate::chamfer::{Domain, DtTensor};
use crate::orientation_diff;
use geodata::osm::geometry::point_segment_distance;
use geodata::osm::model::StreetSegment;
use rustc_hash::FxHashMap;
use std::sync::{Arc, OnceLock};

/// Level of the base boxes: 2^3 = 8 cells (4 m at the default 0.5 m grid).
pub const BASE_LEVEL: u32 = 3;

/// Per-yaw flags of a grid of boxes `[bx0, bx0 + w) × [by0, by0 + h)`, `words` u64 per box.
#[derive(Debug, Clone, Default, PartialEq)]
struct Flags {
    bx0: i64,
    by0: i64,
    w: i64,
    h: i64,
    words: usize,
    bits: Vec<u64>,
}

impl Flags {
    fn new(bx0: i64, by0: i64, bx1: i64, by1: i64, words: usize) -> Flags {
        let (w, h) = ((bx1 - bx0 + 1).max(0), (by1 - by0 + 1).max(0));
        Flags {
            bx0,
            by0,
            w,
            h,
            words,
            bits: vec![0; (w * h) as usize * words],
        }
    }

    /// The words of box (bx, by), if it is in the grid.
    fn at(&self, bx: i64, by: i64) -> Option<usize> {
        let (x, y) = (bx - self.bx0, by - self.by0);
        (x >= 0 && y >= 0 && x < self.w && y < self.h)
            .then(|| (y * self.w + x) as usize * self.words)
    }

    fn test(&self, bx: i64, by: i64, k: usize) -> bool {
        self.at(bx, by).is_some_and(|at| {
            self.bits
                .get(at + k / 64)
                .is_some_and(|w| w >> (k % 64) & 1 == 1)
        })
    }

    fn or_into(&mut self, bx: i64, by: i64, words: &[u64]) {
        if let Some(at) = self.at(bx, by) {
            for (d, s) in self.bits[at..at + self.words].iter_mut().zip(words) {
                *d |= s;
            }
        }
    }

    fn words_of(&self, bx: i64, by: i64) -> Option<&[u64]> {
        self.at(bx, by).map(|at| &self.bits[at..at + self.words])
    }
}

/// The headings a car can have, per yaw template and search box (module doc).
#[derive(Debug, Clone, PartialEq)]
pub struct HeadingMask {
    /// The tensor window's first lattice cell (its [`DtTensor::offset`]).
    offset: [i64; 2],
    /// Base level (boxes of 2^base cells), at most the search's top level.
    base: u32,
    /// Flags of the base boxes (lattice-aligned).
    grid: Flags,
    /// Flags of the search pyramid's boxes at levels base..=top (window-aligned).
    levels: Vec<Flags>,
    /// Number of yaw templates.
    yaws: usize,
}

impl HeadingMask {
    /// The mask of the search over `domain` (cells of `dt`) for templates at `yaws`
    /// (radians): street segments within `radius_m` running within `max_rad` of a yaw, or a
    /// turn within `radius_m`; pyramid up to level `top`.
    pub fn build(
        streets: &[StreetSegment],
        dt: &DtTensor,
        domain: Domain,
        yaws: &[f64],
        radius_m: f64,
        max_rad: f64,
        top: u32,
    ) -> HeadingMask {
        let base = BASE_LEVEL.min(top);
        let words = yaws.len().div_ceil(64).max(1);
        let offset = dt.offset;
        let g = dt.grid_m;
        // Lattice cells of the domain and their base boxes.
        let (gi0, gj0) = (domain.i0 + offset[0], domain.j0 + offset[1]);
        let (gi1, gj1) = (domain.i1 - 1 + offset[0], domain.j1 - 1 + offset[1]);
        let mut grid = Flags::new(gi0 >> base, gj0 >> base, gi1 >> base, gj1 >> base, words);
        let side = (1i64 << base) as f64;
        let centre = |u: i64, k: usize| {
            // Lattice cell corners of the box: origin + g·[u·2^b, (u + 1)·2^b − 1].
            dt.origin[k] + ((u << base) as f64 + (side - 1.0) / 2.0) * g
        };
        let reach = radius_m + (side - 1.0) * g * std::f64::consts::SQRT_2 / 2.0 + 1e-6 * g;
        let box_of = |x: f64, k: usize| (((x - dt.origin[k]) / g).floor() as i64) >> base;
        // The yaws' line orientations in [0, π): |a − b| folded is `orientation_diff` up to
        // rounding, far within the 1e-9 rad of slack.
        let pi = std::f64::consts::PI;
        let yaw_lines: Vec<f64> = yaws.iter().map(|y| y.rem_euclid(pi)).collect();
        let yaw_bits = |dir: Option<f64>| {
            let mut w = vec![0u64; words];
            let d = dir.map(|d| d.rem_euclid(pi));
            for (k, &y) in yaw_lines.iter().enumerate() {
                if d.is_none_or(|d| {
                    let a = (y - d).abs();
                    a.min(pi - a) <= max_rad + 1e-9
                }) {
                    w[k / 64] |= 1 << (k % 64);
                }
            }
            w
        };
        // Marks the base boxes whose centre lies within `reach` of segment a–b.
        let stamp = |a: [f64; 2], b: [f64; 2], bits: &[u64], grid: &mut Flags| {
            let (ux0, ux1) = (
                box_of(a[0].min(b[0]) - reach, 0).max(grid.bx0),
                box_of(a[0].max(b[0]) + reach, 0).min(grid.bx0 + grid.w - 1),
            );
            let (uy0, uy1) = (
                box_of(a[1].min(b[1]) - reach, 1).max(grid.by0),
                box_of(a[1].max(b[1]) + reach, 1).min(grid.by0 + grid.h - 1),
            );
            for uy in uy0..=uy1 {
                for ux in ux0..=ux1 {
                    if point_segment_distance([centre(ux, 0), centre(uy, 1)], a, b) <= reach {
                        grid.or_into(ux, uy, bits);
                    }
                }
            }
        };
        for s in streets {
            if s.a.iter().chain(&s.b).all(|v| v.is_finite()) {
                stamp(s.a, s.b, &yaw_bits(Some(street_direction(s))), &mut grid);
            }
        }
        // Turns, as `along_a_street` finds them: pairs of segments sharing a node (the flags
        // are an OR, so the order of the stamps does not matter).
        let mut at_node: FxHashMap<i64, Vec<usize>> = FxHashMap::default();
        for (i, s) in streets.iter().enumerate() {
            at_node.entry(s.from_node).or_default().push(i);
            if s.to_node != s.from_node {
                at_node.entry(s.to_node).or_default().push(i);
            }
        }
        let every = yaw_bits(None);
        for ids in at_node.values() {
            for (x, &s) in ids.iter().enumerate() {
                for &t in &ids[x + 1..] {
                    let turn = turn_at(&streets[s], &streets[t], max_rad);
                    if let Some(p) = turn.filter(|p| p.iter().all(|v| v.is_finite())) {
                        stamp(p, p, &every, &mut grid);
                    }
                }
            }
        }
        // The window's boxes at the base level meet at most 2 × 2 base boxes; above, the
        // union of their four children.
        let mut levels = Vec::new();
        let mut level = Flags::new(
            domain.i0 >> base,
            domain.j0 >> base,
            (domain.i1 - 1) >> base,
            (domain.j1 - 1) >> base,
            words,
        );
        let mut acc = vec![0u64; words];
        for by in level.by0..level.by0 + level.h {
            for bx in level.bx0..level.bx0 + level.w {
                acc.fill(0);
                let (ux0, ux1) = (
                    ((bx << base) + offset[0]) >> base,
                    (((bx + 1) << base) - 1 + offset[0]) >> base,
                );
                let (uy0, uy1) = (
                    ((by << base) + offset[1]) >> base,
                    (((by + 1) << base) - 1 + offset[1]) >> base,
                );
                for uy in uy0..=uy1 {
                    for ux in ux0..=ux1 {
                        if let Some(w) = grid.words_of(ux, uy) {
                            for (a, b) in acc.iter_mut().zip(w) {
                                *a |= b;
                            }
                        }
                    }
                }
                level.or_into(bx, by, &acc);
            }
        }
        levels.push(level);
        for _ in base..top {
            let Some(prev) = levels.last() else { break };
            let mut next = Flags::new(
                prev.bx0 >> 1,
                prev.by0 >> 1,
                (prev.bx0 + prev.w - 1) >> 1,
                (prev.by0 + prev.h - 1) >> 1,
                words,
            );
            for by in prev.by0..prev.by0 + prev.h {
                for bx in prev.bx0..prev.bx0 + prev.w {
                    if let (Some(from), Some(to)) = (prev.at(bx, by), next.at(bx >> 1, by >> 1)) {
                        for x in 0..words {
                            next.bits[to + x] |= prev.bits[from + x];
                        }
                    }
                }
            }
            levels.push(next);
        }
        HeadingMask {
            offset,
            base,
            grid,
            levels,
            yaws: yaws.len(),
        }
    }

    /// Whether some pose of box (bx, by) at level h (cells of the tensor window) is allowed
    /// at yaw template k.
    pub fn any(&self, k: usize, h: u32, bx: i64, by: i64) -> bool {
        if k >= self.yaws {
            return false;
        }
        if h >= self.base {
            return self
                .levels
                .get((h - self.base) as usize)
                .is_none_or(|l| l.test(bx, by, k));
        }
        // Below the base level a box meets at most 2 × 2 base boxes.
        let b = self.base;
        let (ux0, ux1) = (
            ((bx << h) + self.offset[0]) >> b,
            (((bx + 1) << h) - 1 + self.offset[0]) >> b,
        );
        let (uy0, uy1) = (
            ((by << h) + self.offset[1]) >> b,
            (((by + 1) << h) - 1 + self.offset[1]) >> b,
        );
        (uy0..=uy1).any(|uy| (ux0..=ux1).any(|ux| self.grid.test(ux, uy, k)))
    }

    /// Whether the pose at cell (i, j) of the tensor window is allowed at yaw template k.
    pub fn allows(&self, k: usize, i: i64, j: i64) -> bool {
        self.any(k, 0, i, j)
    }

    /// Share of (base box, yaw) pairs allowed.
    pub fn allowed_share(&self) -> f64 {
        let total = (self.grid.w * self.grid.h) as f64 * self.yaws as f64;
        let set: u64 = self
            .grid
            .bits
            .iter()
            .map(|w| u64::from(w.count_ones()))
            .sum();
        if total > 0.0 {
            set as f64 / total
        } else {
            0.0
        }
    }

    /// Memory held, bytes.
    pub fn bytes(&self) -> usize {
        8 * (self.grid.bits.len() + self.levels.iter().map(|l| l.bits.len()).sum::<usize>())
    }
}

/// Direction of a street segment, radians.
pub(crate) fn street_direction(s: &StreetSegment) -> f64 {
    (s.b[1] - s.a[1]).atan2(s.b[0] - s.a[0])
}

/// The node two street segments share (by OSM node id, the first of `s`'s ends that `t`
/// has) when they meet there at more than `max_rad`: a turn, where a car heads anywhere
/// between them.
pub(crate) fn turn_at(s: &StreetSegment, t: &StreetSegment, max_rad: f64) -> Option<[f64; 2]> {
    [(s.from_node, s.a), (s.to_node, s.b)]
        .into_iter()
        .find(|&(id, _)| id == t.from_node || id == t.to_node)
        .map(|(_, at)| at)
        .filter(|_| orientation_diff(street_direction(s), street_direction(t)) > max_rad)
}

/// What a heading mask depends on besides the map and the tensor window: the number of yaw
/// templates, the street distance and angle (their bits) and the search's top level.
pub type HeadingKey = (usize, u64, u64, u32);

/// A heading mask built on first use and kept for the key it was built for (a map's or a
/// tile's; building one takes 0.1–0.2 s on the Helsinki map, longer than many searches).
#[derive(Debug, Clone, Default)]
pub struct HeadingCache {
    cell: OnceLock<(HeadingKey, Option<Arc<HeadingMask>>)>,
}

impl HeadingCache {
    /// The mask for `key`: the kept one when it was built for `key`, else `build()` (kept
    /// when nothing is kept yet).
    pub fn get_or_build(
        &self,
        key: HeadingKey,
        build: impl FnOnce() -> Option<HeadingMask>,
    ) -> Option<Arc<HeadingMask>> {
        if let Some((kept_key, kept)) = self.cell.get() {
            if *kept_key == key {
                return kept.clone();
            }
            // Built for other options (a localizer's options changed after a search).
            return build().map(Arc::new);
        }
        let mask = build().map(Arc::new);
        // Two first searches at once both build; the first one set is kept.
        let _ = self.cell.set((key, mask.clone()));
        mask
    }
}
