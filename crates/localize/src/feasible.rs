//! The feasible poses of the search: grid cells whose pose (the cell's corner) lies outside
//! every building and, when the map has streets, within a distance of a street segment — the
//! filters of thesis §5.3.4 as a mask over the search domain, so that the minimum that the
//! factor of [`crate::candidates::search`] refers to is the minimum over poses a robot can
//! have, and a pose inside a building can neither set that minimum nor suppress a feasible
//! neighbour.
//!
//! Level 0 is one flag per domain cell; level h ≥ 1 flags the aligned boxes of 2^h × 2^h cells
//! (the branch-and-bound nodes) holding at least one feasible cell, so that the search skips
//! boxes without one. Inside-building flags are filled row by row with the crossings of the
//! even–odd rule of `geodata`'s `point_in_polygon` (the same floating-point expressions, so
//! the same answer at every cell corner); the street band stamps each segment's
//! neighbourhood with the exact point–segment distance. Cost O(Σ building box cells +
//! Σ street band cells + domain cells).

use crate::chamfer::{Domain, DtTensor};
use geodata::osm::geometry::point_segment_distance;
use geodata::osm::OsmMap;
use rayon::prelude::*;

/// Flags of one level: boxes `[bx0, bx0 + w) × [by0, by0 + h)` (box (bx, by) covers the cells
/// `[bx·2^h, (bx + 1)·2^h) × [by·2^h, (by + 1)·2^h)`).
#[derive(Debug, Clone, Default, PartialEq)]
struct Level {
    bx0: i64,
    by0: i64,
    w: i64,
    h: i64,
    flags: Vec<bool>,
}

impl Level {
    fn get(&self, bx: i64, by: i64) -> bool {
        let (x, y) = (bx - self.bx0, by - self.by0);
        if x < 0 || y < 0 || x >= self.w || y >= self.h {
            return false;
        }
        self.flags
            .get((y * self.w + x) as usize)
            .copied()
            .unwrap_or(false)
    }
}

/// Feasible pose cells of a search domain and their any-feasible pyramid.
#[derive(Debug, Clone, PartialEq)]
pub struct FeasibleMask {
    /// The domain the flags cover (cells outside it are infeasible).
    pub domain: Domain,
    /// Feasible cells.
    pub feasible_cells: u64,
    levels: Vec<Level>,
}

impl FeasibleMask {
    /// Every cell of the domain feasible.
    pub fn everything(domain: Domain, top: u32) -> FeasibleMask {
        let w = (domain.i1 - domain.i0).max(0);
        let h = (domain.j1 - domain.j0).max(0);
        Self::from_cells(domain, vec![true; (w * h) as usize], top)
    }

    /// The cells of `domain` whose corner is outside every building of `map` and, if the map
    /// has street segments, within `street_distance_m` of one; pyramid up to level `top`.
    pub fn build(
        map: &OsmMap,
        dt: &DtTensor,
        domain: Domain,
        street_distance_m: f64,
        top: u32,
    ) -> FeasibleMask {
        let w = (domain.i1 - domain.i0).max(0);
        let h = (domain.j1 - domain.j0).max(0);
        let x_of = |i: i64| dt.corner_of(i, 0)[0];
        let y_of = |j: i64| dt.corner_of(0, j)[1];
        // Rows of the domain, each filled independently.
        let rows: Vec<Vec<bool>> = (0..h)
            .into_par_iter()
            .map(|r| {
                let j = domain.j0 + r;
                let y = y_of(j);
                let mut near = vec![map.streets.segments.is_empty(); w as usize];
                let d = street_distance_m;
                for s in &map.streets.segments {
                    if y < s.a[1].min(s.b[1]) - d || y > s.a[1].max(s.b[1]) + d {
                        continue;
                    }
                    let (lo, hi) = (s.a[0].min(s.b[0]) - d, s.a[0].max(s.b[0]) + d);
                    let (c0, c1) = cell_range(dt, domain, lo, hi);
                    for i in c0..c1 {
                        let k = (i - domain.i0) as usize;
                        if !near[k] && point_segment_distance([x_of(i), y], s.a, s.b) <= d {
                            near[k] = true;
                        }
                    }
                }
                for b in &map.buildings {
                    let Some((ylo, yhi)) = y_range(&b.outer) else {
                        continue;
                    };
                    if y < ylo || y > yhi {
                        continue;
                    }
                    let outer = crossings(&b.outer, y);
                    let inners: Vec<Vec<f64>> = b.inners.iter().map(|r| crossings(r, y)).collect();
                    let (Some(&first), Some(&last)) = (outer.first(), outer.last()) else {
                        continue;
                    };
                    let (c0, c1) = cell_range(dt, domain, first, last);
                    for i in c0..c1 {
                        let x = x_of(i);
                        if inside(&outer, x) && !inners.iter().any(|c| inside(c, x)) {
                            if let Some(f) = near.get_mut((i - domain.i0) as usize) {
                                *f = false;
                            }
                        }
                    }
                }
                near
            })
            .collect();
        Self::from_cells(domain, rows.concat(), top)
    }

    /// A mask from one flag per domain cell (row-major from (i0, j0); missing flags are
    /// infeasible), pyramid up to level `top`.
    pub fn from_cells(domain: Domain, mut cells: Vec<bool>, top: u32) -> FeasibleMask {
        cells.resize(domain.cells() as usize, false);
        let feasible_cells = cells.iter().filter(|&&f| f).count() as u64;
        let w = (domain.i1 - domain.i0).max(0);
        let h = (domain.j1 - domain.j0).max(0);
        let mut levels = vec![Level {
            bx0: domain.i0,
            by0: domain.j0,
            w,
            h,
            flags: cells,
        }];
        for l in 1..=top {
            let Some(prev) = levels.last() else { break };
            let (bx0, by0) = (domain.i0 >> l, domain.j0 >> l);
            let (bx1, by1) = ((domain.i1 - 1) >> l, (domain.j1 - 1) >> l);
            let (lw, lh) = ((bx1 - bx0 + 1).max(0), (by1 - by0 + 1).max(0));
            if w == 0 || h == 0 {
                levels.push(Level::default());
                continue;
            }
            let mut flags = vec![false; (lw * lh) as usize];
            for y in 0..lh {
                for x in 0..lw {
                    let (bx, by) = (bx0 + x, by0 + y);
                    flags[(y * lw + x) as usize] =
                        (0..4).any(|q| prev.get(2 * bx + (q & 1), 2 * by + (q >> 1)));
                }
            }
            levels.push(Level {
                bx0,
                by0,
                w: lw,
                h: lh,
                flags,
            });
        }
        FeasibleMask {
            domain,
            feasible_cells,
            levels,
        }
    }

    /// Whether the aligned box (bx, by) of level h (cells `[bx·2^h, (bx + 1)·2^h)` per axis)
    /// holds a feasible cell; level 0 is the cell itself. Levels above the pyramid's top
    /// answer true.
    #[inline]
    pub fn any(&self, h: u32, bx: i64, by: i64) -> bool {
        self.levels.get(h as usize).is_none_or(|l| l.get(bx, by))
    }

    /// Whether the pose at cell (i, j) is feasible.
    pub fn is_feasible(&self, i: i64, j: i64) -> bool {
        self.any(0, i, j)
    }

    /// Memory held, bytes.
    pub fn bytes(&self) -> usize {
        self.levels.iter().map(|l| l.flags.len()).sum()
    }
}

/// Cells `[c0, c1)` of the domain whose corner x lies in `[lo, hi]`.
fn cell_range(dt: &DtTensor, domain: Domain, lo: f64, hi: f64) -> (i64, i64) {
    let to_cell = |x: f64| dt.cell_of([x, 0.0]).0;
    let c0 = to_cell(lo).max(domain.i0);
    let c1 = (to_cell(hi) + 2).min(domain.i1);
    (c0, c1.max(c0))
}

fn y_range(ring: &[[f64; 2]]) -> Option<(f64, f64)> {
    let first = ring.first()?;
    Some(ring.iter().fold((first[1], first[1]), |(lo, hi), p| {
        (lo.min(p[1]), hi.max(p[1]))
    }))
}

/// The x of the ring's crossings with the row y, sorted, computed as `point_in_ring` does.
fn crossings(ring: &[[f64; 2]], y: f64) -> Vec<f64> {
    let n = ring.len();
    let mut xs = Vec::new();
    let mut j = n.wrapping_sub(1);
    for i in 0..n {
        let (Some(a), Some(b)) = (ring.get(i), ring.get(j)) else {
            j = i;
            continue;
        };
        if (a[1] > y) != (b[1] > y) {
            xs.push(a[0] + (y - a[1]) * (b[0] - a[0]) / (b[1] - a[1]));
        }
        j = i;
    }
    xs.sort_by(f64::total_cmp);
    xs
}

/// Even–odd rule: inside when an odd number of crossings lie strictly right of x.
fn inside(sorted_crossings: &[f64], x: f64) -> bool {
    let right = sorted_crossings.len() - sorted_crossings.partition_point(|&c| c <= x);
    right % 2 == 1
}

/// Index file codec (see [`crate::index`]).
impl FeasibleMask {
    pub(crate) fn encode(&self, e: &mut crate::codec::Enc<'_>) {
        for v in [
            self.domain.i0,
            self.domain.j0,
            self.domain.i1,
            self.domain.j1,
        ] {
            e.i64(v);
        }
        e.u64(self.feasible_cells);
        e.u64(self.levels.len() as u64);
        for l in &self.levels {
            for v in [l.bx0, l.by0, l.w, l.h] {
                e.i64(v);
            }
            e.u64(l.flags.len() as u64);
            // One byte per flag, written as scalars (the flags are bools, not bytes).
            for &f in &l.flags {
                e.u8(u8::from(f));
            }
        }
    }

    pub(crate) fn decode<R: std::io::Read>(
        d: &mut crate::codec::Dec<'_, R>,
    ) -> crate::Result<FeasibleMask> {
        let domain = crate::chamfer::Domain::decode(d)?;
        let feasible_cells = d.u64("feasible cell count")?;
        let n = d.count(40, "feasible levels")?;
        let mut levels = Vec::with_capacity(n);
        for _ in 0..n {
            let v: [i64; 4] = d.i64s("level box")?;
            if v.iter().any(|x| x.unsigned_abs() > 1 << 40) || v[2] < 0 || v[3] < 0 {
                return Err(d.bad(format!("feasible level box {v:?}")));
            }
            let cells = v[2]
                .checked_mul(v[3])
                .ok_or_else(|| d.bad(format!("feasible level box {v:?} overflows")))?;
            let flags: Vec<bool> = d
                .bytes(cells as usize, "feasible flags")?
                .into_iter()
                .map(|b| b != 0)
                .collect();
            levels.push(Level {
                bx0: v[0],
                by0: v[1],
                w: v[2],
                h: v[3],
                flags,
            });
        }
        Ok(FeasibleMask {
            domain,
            feasible_cells,
            levels,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::chamfer::{map_edges, ChamferOptions};
    use geodata::osm::index::MapIndex;
    use geodata::osm::model::{Building, OsmStats, StreetNetwork};
    use geodata::projection::LocalFrame;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    fn random_map(seed: u64, streets: bool) -> OsmMap {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let mut buildings = Vec::new();
        for k in 0..12 {
            let c = [rng.gen_range(0.0..60.0), rng.gen_range(0.0..60.0)];
            let n = rng.gen_range(3..8);
            let ring: Vec<[f64; 2]> = (0..n)
                .map(|i| {
                    let a = i as f64 * std::f64::consts::TAU / n as f64 + rng.gen_range(0.0..0.5);
                    let r = rng.gen_range(3.0..9.0);
                    [c[0] + r * a.cos(), c[1] + r * a.sin()]
                })
                .collect();
            let inners = if k % 3 == 0 {
                vec![(0..4)
                    .map(|i| {
                        let a = i as f64 * std::f64::consts::FRAC_PI_2;
                        [c[0] + 1.5 * a.cos(), c[1] + 1.5 * a.sin()]
                    })
                    .collect()]
            } else {
                Vec::new()
            };
            buildings.push(Building::outline(k, ring, inners));
        }
        let mut net = StreetNetwork::default();
        if streets {
            for _ in 0..4 {
                let a = [rng.gen_range(-10.0..70.0), rng.gen_range(-10.0..70.0)];
                let b = [rng.gen_range(-10.0..70.0), rng.gen_range(-10.0..70.0)];
                net.segments.push(geodata::osm::model::StreetSegment {
                    way_index: 0,
                    index_in_way: net.segments.len(),
                    from_node: 0,
                    to_node: 0,
                    a,
                    b,
                    length_m: (b[0] - a[0]).hypot(b[1] - a[1]),
                    highway: "residential".into(),
                });
            }
        }
        OsmMap {
            frame: LocalFrame::new(48.15, 11.57).unwrap(),
            bbox_lonlat: [11.5, 48.1, 11.6, 48.2],
            buildings,
            highways: Vec::new(),
            streets: net,
            stats: OsmStats::default(),
        }
    }

    #[test]
    fn mask_equals_the_filters_predicates_at_every_cell() {
        for seed in 0..6 {
            let map = random_map(seed, seed % 2 == 0);
            let edges = map_edges(&map);
            let dt = DtTensor::build(&edges, &ChamferOptions::default()).unwrap();
            let domain = Domain::from_box(&dt, [-15.0, -12.0], [75.0, 71.0]);
            let d = 6.0;
            let mask = FeasibleMask::build(&map, &dt, domain, d, 5);
            let index = MapIndex::new(&map);
            let mut feasible = 0;
            for j in domain.j0..domain.j1 {
                for i in domain.i0..domain.i1 {
                    let p = dt.corner_of(i, j);
                    let expected = index.building_at(p).is_none()
                        && (map.streets.segments.is_empty()
                            || index.nearest_segment(p).is_some_and(|(_, dist)| dist <= d));
                    assert_eq!(mask.is_feasible(i, j), expected, "seed {seed} cell {i} {j}");
                    feasible += expected as u64;
                }
            }
            assert_eq!(mask.feasible_cells, feasible);
            assert!(feasible > 0 && feasible < domain.cells(), "seed {seed}");
            assert!(!mask.is_feasible(domain.i1, domain.j0));
            // Each level's flag is the OR of its cells.
            let mut rng = ChaCha8Rng::seed_from_u64(seed);
            for _ in 0..300 {
                let h = rng.gen_range(1..=5u32);
                let bx = rng.gen_range((domain.i0 >> h) - 1..=(domain.i1 >> h) + 1);
                let by = rng.gen_range((domain.j0 >> h) - 1..=(domain.j1 >> h) + 1);
                let side = 1i64 << h;
                let brute = (0..side)
                    .any(|dy| (0..side).any(|dx| mask.is_feasible(bx * side + dx, by * side + dy)));
                assert_eq!(
                    mask.any(h, bx, by),
                    brute,
                    "seed {seed} level {h} box {bx} {by}"
                );
            }
        }
    }

    #[test]
    fn everything_is_feasible_in_the_trivial_mask() {
        let domain = Domain {
            i0: -3,
            j0: 2,
            i1: 9,
            j1: 7,
        };
        let mask = FeasibleMask::everything(domain, 3);
        assert_eq!(mask.feasible_cells, domain.cells());
        assert!(mask.is_feasible(-3, 2) && mask.is_feasible(8, 6));
        assert!(!mask.is_feasible(9, 6) && !mask.is_feasible(-4, 2));
        assert!(mask.any(3, -1, 0) && mask.any(3, 1, 0) && !mask.any(3, 2, 0));
    }
}
