//! Queries of occupied cells: in a box, within a radius, the k nearest (best first over the
//! runs' trees), of a class, of an object.

use super::packed::{KeyBox, Visit};
use super::{SrMap, KEY_LIMIT};
use geodata::classes::Class;
use rayon::prelude::*;
use std::cmp::Ordering;
use std::collections::BinaryHeap;

/// A best-first search entry of [`SrMap::nearest_cells`].
#[derive(Debug, Clone, Copy)]
struct Candidate {
    d2: f64,
    /// Cell id, or node index.
    id: u32,
    /// `None` for a cell, else (run, level) of a node.
    node: Option<(u32, u32)>,
}

impl Candidate {
    fn rank(&self) -> (f64, bool, u32) {
        (self.d2, self.node.is_some(), self.id)
    }
}

impl PartialEq for Candidate {
    fn eq(&self, other: &Self) -> bool {
        self.cmp(other) == Ordering::Equal
    }
}
impl Eq for Candidate {}
impl PartialOrd for Candidate {
    fn partial_cmp(&self, other: &Self) -> Option<Ordering> {
        Some(self.cmp(other))
    }
}
impl Ord for Candidate {
    /// Reversed: the nearest candidate is the heap's maximum.
    fn cmp(&self, other: &Self) -> Ordering {
        let (a, b) = (self.rank(), other.rank());
        b.0.total_cmp(&a.0).then(b.1.cmp(&a.1)).then(b.2.cmp(&a.2))
    }
}

impl SrMap {
    /// The keys (one axis) whose cell centre lies in `[lo, hi]`, if any.
    fn key_range(&self, lo: f64, hi: f64) -> Option<(i32, i32)> {
        if lo.is_nan() || hi.is_nan() || lo > hi {
            return None;
        }
        let r = self.options.resolution_m;
        let centre = |k: i64| (k as f64 + 0.5) * r;
        let lim = i64::from(KEY_LIMIT) + 1;
        let clamp = |v: f64| v.clamp(-lim as f64, lim as f64) as i64;
        let mut kmin = clamp((lo / r - 0.5).ceil());
        while kmin > -lim && centre(kmin - 1) >= lo {
            kmin -= 1;
        }
        while kmin < lim && centre(kmin) < lo {
            kmin += 1;
        }
        let mut kmax = clamp((hi / r - 0.5).floor());
        while kmax < lim && centre(kmax + 1) <= hi {
            kmax += 1;
        }
        while kmax > -lim && centre(kmax) > hi {
            kmax -= 1;
        }
        (kmin <= kmax).then_some((kmin as i32, kmax as i32))
    }

    /// Occupied cells whose volume intersects the box `[min, max]` (metres), i.e. whose
    /// centre lies in the box grown by half a cell, unsorted.
    pub fn cells_in_box(&self, min: [f64; 3], max: [f64; 3]) -> Vec<u32> {
        let h = 0.5 * self.options.resolution_m;
        let mut q = KeyBox::EMPTY;
        for a in 0..3 {
            match self.key_range(min[a] - h, max[a] + h) {
                Some((lo, hi)) => (q.min[a], q.max[a]) = (lo, hi),
                None => return Vec::new(),
            }
        }
        self.occupied_where(|b| q.visit_node(b), |key| q.contains(key))
    }

    /// Occupied cells of every run's tree: nodes as `test` says, cells of a descended
    /// leaf where `keep(key)`. Unsorted.
    fn occupied_where(
        &self,
        mut test: impl FnMut(&KeyBox) -> Visit,
        keep: impl Fn([i32; 3]) -> bool,
    ) -> Vec<u32> {
        let mut out = Vec::new();
        for run in &self.runs {
            let cells = &self.cells[run.start..run.end];
            let base = run.start as u32;
            run.tree.visit(&mut test, |range, all| {
                let start = range.start;
                for (i, c) in cells[range].iter().enumerate() {
                    if c.occupied() && (all || keep(c.key)) {
                        out.push(base + (start + i) as u32);
                    }
                }
            });
        }
        out
    }

    /// Squared distance from `p` to the centre of a key, the one the queries compare.
    fn dist2(&self, key: [i32; 3], p: [f64; 3]) -> f64 {
        let c = self.centre(key);
        let d = [c[0] - p[0], c[1] - p[1], c[2] - p[2]];
        d[0] * d[0] + d[1] * d[1] + d[2] * d[2]
    }

    /// Smallest and largest squared distances from `p` to the centres of the keys of `b`.
    fn box_dist2(&self, b: &KeyBox, p: [f64; 3]) -> (f64, f64) {
        let (lo, hi) = (self.centre(b.min), self.centre(b.max));
        let mut near = [0.0; 3];
        let mut far = [0.0; 3];
        for a in 0..3 {
            near[a] = if p[a] < lo[a] {
                lo[a] - p[a]
            } else if p[a] > hi[a] {
                p[a] - hi[a]
            } else {
                0.0
            };
            far[a] = (p[a] - lo[a]).abs().max((hi[a] - p[a]).abs());
        }
        (
            near[0] * near[0] + near[1] * near[1] + near[2] * near[2],
            far[0] * far[0] + far[1] * far[1] + far[2] * far[2],
        )
    }

    /// Occupied cells whose centre lies within `radius_m` of `centre`, unsorted.
    pub fn cells_within_radius(&self, centre: [f64; 3], radius_m: f64) -> Vec<u32> {
        if radius_m.is_nan() || radius_m < 0.0 {
            return Vec::new();
        }
        let r2 = radius_m * radius_m;
        self.occupied_where(
            |b| {
                let (near, far) = self.box_dist2(b, centre);
                if near > r2 {
                    Visit::Skip
                } else if far <= r2 {
                    Visit::All
                } else {
                    Visit::Descend
                }
            },
            |key| self.dist2(key, centre) <= r2,
        )
    }

    /// The `k` occupied cells with centres nearest to `p`, nearest first (best-first
    /// search over the runs' trees).
    pub fn nearest_cells(&self, p: [f64; 3], k: usize) -> Vec<u32> {
        let mut out = Vec::with_capacity(k);
        if k == 0 || p.iter().any(|v| !v.is_finite()) {
            return out;
        }
        let mut heap = BinaryHeap::new();
        for (ri, run) in self.runs.iter().enumerate() {
            if let Some((level, j)) = run.tree.root() {
                heap.push(Candidate {
                    d2: self.box_dist2(run.tree.node_box(level, j), p).0,
                    id: j as u32,
                    node: Some((ri as u32, level as u32)),
                });
            }
        }
        while let Some(c) = heap.pop() {
            let Some((ri, level)) = c.node else {
                if self.cells[c.id as usize].occupied() {
                    out.push(c.id);
                    if out.len() == k {
                        break;
                    }
                }
                continue;
            };
            let run = &self.runs[ri as usize];
            let (level, j) = (level as usize, c.id as usize);
            for child in run.tree.children(level, j) {
                heap.push(if level == 0 {
                    let id = run.start + child;
                    Candidate {
                        d2: self.dist2(self.cells[id].key, p),
                        id: id as u32,
                        node: None,
                    }
                } else {
                    Candidate {
                        d2: self.box_dist2(run.tree.node_box(level - 1, child), p).0,
                        id: child as u32,
                        node: Some((ri, level as u32 - 1)),
                    }
                });
            }
        }
        out
    }

    /// Occupied cells labelled with a class, in cell order.
    pub fn cells_of_class(&self, class: Class) -> Vec<u32> {
        let id = class.id();
        (0..self.cells.len() as u32)
            .into_par_iter()
            .filter(|&i| {
                let c = &self.cells[i as usize];
                c.label == id && c.occupied()
            })
            .collect()
    }

    /// Occupied cells whose majority object is `object`, in cell order.
    pub fn cells_of_object(&self, object: u32) -> Vec<u32> {
        (0..self.cells.len() as u32)
            .into_par_iter()
            .filter(|&i| {
                let c = &self.cells[i as usize];
                c.object == object && c.object_votes > 0 && c.occupied()
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::map::test_util::random_cloud;
    use crate::map::MapOptions;
    use rand::{Rng, SeedableRng};

    /// Brute-force versions of the queries.
    fn scan_box(map: &SrMap, min: [f64; 3], max: [f64; 3]) -> Vec<u32> {
        let h = 0.5 * map.resolution_m();
        (0..map.len() as u32)
            .filter(|&i| {
                let c = map.centre(map.cells()[i as usize].key);
                (0..3).all(|k| c[k] >= min[k] - h && c[k] <= max[k] + h)
            })
            .collect()
    }

    fn dist2(map: &SrMap, i: u32, p: [f64; 3]) -> f64 {
        let c = map.centre(map.cells()[i as usize].key);
        (0..3).map(|k| (c[k] - p[k]) * (c[k] - p[k])).sum()
    }

    #[test]
    fn queries_equal_a_linear_scan_on_random_data() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(11);
        let mut map = SrMap::new(MapOptions {
            resolution_m: 0.25,
            ..MapOptions::default()
        })
        .unwrap();
        // Bulk load, then incremental inserts.
        map.insert_cloud(&random_cloud(3000, 6.0, 2), None).unwrap();
        let small = random_cloud(200, 7.0, 3);
        let stats = map.insert_cloud(&small, None).unwrap();
        assert!(!stats.bulk_loaded && stats.new_cells > 0);
        assert_eq!(map.runs(), 2);
        for _ in 0..50 {
            let a: [f64; 3] = std::array::from_fn(|_| rng.gen_range(-7.0..7.0));
            let b: [f64; 3] = std::array::from_fn(|_| rng.gen_range(-7.0..7.0));
            let (min, max) = (
                std::array::from_fn(|k| a[k].min(b[k])),
                std::array::from_fn(|k| a[k].max(b[k])),
            );
            let mut got = map.cells_in_box(min, max);
            got.sort_unstable();
            assert_eq!(got, scan_box(&map, min, max));
            let radius = rng.gen_range(0.0..3.0);
            let mut got = map.cells_within_radius(a, radius);
            got.sort_unstable();
            let want: Vec<u32> = (0..map.len() as u32)
                .filter(|&i| dist2(&map, i, a) <= radius * radius)
                .collect();
            assert_eq!(got, want);
            let k = rng.gen_range(1..30);
            let got = map.nearest_cells(a, k);
            let mut all: Vec<f64> = (0..map.len() as u32).map(|i| dist2(&map, i, a)).collect();
            all.sort_by(f64::total_cmp);
            let got_d: Vec<f64> = got.iter().map(|&i| dist2(&map, i, a)).collect();
            assert_eq!(got_d, all[..k]);
        }
        for class in Class::ALL {
            let want: Vec<u32> = (0..map.len() as u32)
                .filter(|&i| map.cells()[i as usize].label == class.id())
                .collect();
            assert_eq!(map.cells_of_class(class), want);
        }
        assert!(map.tree_height() >= 2);
    }
}
