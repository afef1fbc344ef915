//! Free-space ray casting: the cells a ray traverses (3-D DDA) and one scan's misses.

use super::{morton, SrMap};
use rayon::prelude::*;
use rustc_hash::FxHashMap;

impl SrMap {
    /// Free-space updates of one scan: one miss for every existing cell a ray traverses
    /// before its endpoint, unless the cell was hit in this scan. Returns (rays, misses).
    pub(super) fn cast_rays(
        &mut self,
        origin: [f64; 3],
        points: &[[f64; 3]],
        scan: u32,
        (index, last_scan): (&FxHashMap<u64, u32>, &[u32]),
    ) -> (usize, usize) {
        let r = self.options.resolution_m;
        let max_ray = self.options.max_ray_m;
        let chunk = 4096;
        let mut missed: Vec<u32> = points
            .par_chunks(chunk)
            .flat_map_iter(|ps| {
                let mut out = Vec::new();
                for p in ps {
                    let d = [p[0] - origin[0], p[1] - origin[1], p[2] - origin[2]];
                    let len = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
                    if len > max_ray || len < 1e-9 {
                        continue;
                    }
                    traverse(origin, *p, r, |key| {
                        if let Some(&ci) = index.get(&morton(key)) {
                            if last_scan[ci as usize] != scan {
                                out.push(ci);
                            }
                        }
                    });
                }
                out.sort_unstable();
                out.dedup();
                out
            })
            .collect();
        missed.par_sort_unstable();
        missed.dedup();
        let (miss, min) = (self.options.log_odds_miss, self.options.log_odds_min);
        for &ci in &missed {
            let c = &mut self.cells[ci as usize];
            c.log_odds = (c.log_odds + miss).max(min);
        }
        (points.len(), missed.len())
    }
}

/// Visits the keys of the cells a segment from `a` to `b` passes through, excluding the
/// cell of `b` (3-D DDA, Amanatides & Woo 1987). O(length / resolution).
pub fn traverse(a: [f64; 3], b: [f64; 3], resolution_m: f64, mut visit: impl FnMut([i32; 3])) {
    let r = resolution_m;
    let mut key = a.map(|v| (v / r).floor() as i32);
    let end = b.map(|v| (v / r).floor() as i32);
    let d = [b[0] - a[0], b[1] - a[1], b[2] - a[2]];
    let mut step = [0i32; 3];
    let mut t_max = [f64::INFINITY; 3];
    let mut t_delta = [f64::INFINITY; 3];
    for k in 0..3 {
        if d[k] > 0.0 {
            step[k] = 1;
            t_max[k] = ((f64::from(key[k]) + 1.0) * r - a[k]) / d[k];
            t_delta[k] = r / d[k];
        } else if d[k] < 0.0 {
            step[k] = -1;
            t_max[k] = (f64::from(key[k]) * r - a[k]) / d[k];
            t_delta[k] = -r / d[k];
        }
    }
    let max_steps = end
        .iter()
        .zip(&key)
        .map(|(e, s)| (i64::from(*e) - i64::from(*s)).unsigned_abs())
        .sum::<u64>();
    for _ in 0..max_steps {
        if key == end {
            return;
        }
        visit(key);
        let k = if t_max[0] < t_max[1] {
            if t_max[0] < t_max[2] {
                0
            } else {
                2
            }
        } else if t_max[1] < t_max[2] {
            1
        } else {
            2
        };
        if t_max[k] > 1.0 {
            return;
        }
        key[k] += step[k];
        t_max[k] += t_delta[k];
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::map::MapOptions;
    use geodata::cloud::{Columns, PointCloud, PointRecord, Precision};

    #[test]
    fn traversal_visits_each_crossed_cell_once() {
        let mut keys = Vec::new();
        traverse([0.05, 0.05, 0.05], [0.95, 0.05, 0.05], 0.1, |k| {
            keys.push(k)
        });
        assert_eq!(keys.len(), 9);
        assert_eq!(keys[0], [0, 0, 0]);
        assert_eq!(keys[8], [8, 0, 0]);
        // A diagonal: consecutive keys differ in one axis by one.
        let mut keys = Vec::new();
        traverse([0.01, 0.02, 0.03], [2.3, 1.7, -0.9], 0.1, |k| keys.push(k));
        for w in keys.windows(2) {
            let d: i32 = (0..3).map(|k| (w[1][k] - w[0][k]).abs()).sum();
            assert_eq!(d, 1);
        }
        assert!(!keys.contains(&[23, 17, -10]));
    }

    #[test]
    fn ray_casting_clears_cells_passed_through() {
        let columns = Columns::default();
        let mut wall = PointCloud::with_columns(columns, Precision::F64, 1);
        wall.push(&PointRecord {
            position: [2.05, 0.05, 0.05],
            ..PointRecord::default()
        });
        let mut far = PointCloud::with_columns(columns, Precision::F64, 1);
        far.push(&PointRecord {
            position: [5.05, 0.05, 0.05],
            ..PointRecord::default()
        });
        let mut map = SrMap::new(MapOptions {
            ray_casting: true,
            ..MapOptions::default()
        })
        .unwrap();
        map.insert_cloud(&wall, Some([0.05, 0.05, 0.05])).unwrap();
        assert_eq!(map.cells_in_box([2.0, 0.0, 0.0], [2.1, 0.1, 0.1]).len(), 1);
        // The wall moved away: three rays through the old cell make it free.
        for _ in 0..3 {
            let s = map.insert_cloud(&far, Some([0.05, 0.05, 0.05])).unwrap();
            assert_eq!(s.misses, 1);
        }
        assert!(map
            .cells_in_box([2.0, 0.0, 0.0], [2.1, 0.1, 0.1])
            .is_empty());
        assert_eq!(map.prune_free(), 1);
        assert_eq!(map.len(), 1);
    }
}
