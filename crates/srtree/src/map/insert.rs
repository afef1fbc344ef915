//! Insertion of clouds and scans: the checks, the numbering of a batch's points, their runs
//! sorted by cell, and the batch itself (endpoint updates, ray casting, indexing the new
//! cells).

use super::codes::BatchCodes;
use super::sort::{radix_sort_by_code, Item};
use super::{floor_i32, morton, ColourSum, SrMap, KEY_LIMIT};
use crate::error::{Result, SrtreeError};
use geodata::cloud::PointCloud;
use rayon::prelude::*;
use rustc_hash::FxHashMap;

/// What one insertion did.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct InsertStats {
    /// Points inserted.
    pub points: usize,
    /// Cells created.
    pub new_cells: usize,
    /// Cell updates by endpoints, summed over scans (created cells included).
    pub touched_cells: usize,
    /// Rays cast.
    pub rays: usize,
    /// Free-space updates applied to existing cells.
    pub misses: usize,
    /// Whether the whole R-tree was packed anew.
    pub bulk_loaded: bool,
}

/// State of one insertion batch: with ray casting (which looks up every traversed cell) a
/// hash index of all cells, and per cell the last scan that hit it.
pub(super) struct Batch {
    /// Morton code → cell id of every cell (with ray casting only).
    pub(super) index: FxHashMap<u64, u32>,
    /// Whether `index` holds the cells.
    pub(super) hashed: bool,
    /// Per cell (with ray casting only), the last scan that hit it.
    pub(super) last_scan: Vec<u32>,
}

impl SrMap {
    /// Checks the columns, the origin and (with `positions`) every position: finite and
    /// inside the grid.
    fn check_scan(
        &self,
        cloud: &PointCloud,
        origin: Option<[f64; 3]>,
        positions: bool,
    ) -> Result<()> {
        cloud.check_columns()?;
        if u32::try_from(cloud.len()).is_err() {
            return Err(SrtreeError::InvalidOption {
                name: "cloud",
                value: cloud.len() as f64,
                expected: "at most 2³² − 1 points per cloud",
            });
        }
        let limit_m = f64::from(KEY_LIMIT) * self.options.resolution_m;
        if positions {
            if let Some(index) = cloud
                .positions
                .par_iter()
                .position_first(|p| !self.inside_grid(p))
            {
                return Err(self.position_error(index, cloud.positions[index], limit_m));
            }
        }
        if let Some(o) = origin.filter(|_| self.options.ray_casting) {
            if let Some(&bad) = o.iter().find(|v| !(v.is_finite() && v.abs() < limit_m)) {
                return Err(SrtreeError::InvalidOption {
                    name: "origin",
                    value: bad,
                    expected: "a finite sensor origin inside the grid",
                });
            }
        }
        Ok(())
    }

    /// Whether a position is finite and inside the grid.
    fn inside_grid(&self, p: &[f64; 3]) -> bool {
        let limit_m = f64::from(KEY_LIMIT) * self.options.resolution_m;
        p.iter().all(|v| v.abs() < limit_m)
    }

    /// The error of a position that is not finite or outside the grid.
    fn position_error(&self, index: usize, position: [f64; 3], limit_m: f64) -> SrtreeError {
        if position.iter().all(|v| v.is_finite()) {
            SrtreeError::OutOfGrid {
                index,
                position,
                limit_m,
            }
        } else {
            SrtreeError::NonFinite { index, position }
        }
    }

    /// Inserts a cloud (its `label`, `rgb` and `object` columns when present); with
    /// ray casting on and an `origin` (the sensor position), traversed cells get a miss.
    pub fn insert_cloud(
        &mut self,
        cloud: &PointCloud,
        origin: Option<[f64; 3]>,
    ) -> Result<InsertStats> {
        self.insert_scans(&[(cloud, origin)])
    }

    /// Inserts scans one after the other (each with its sensor origin for ray casting) in
    /// one batch: the new cells are indexed once at the end, as OctoMap's lazy evaluation
    /// defers its inner nodes. Every scan is checked first: on error the map is unchanged.
    /// Returns the summed statistics.
    pub fn insert_scans(
        &mut self,
        scans: &[(&PointCloud, Option<[f64; 3]>)],
    ) -> Result<InsertStats> {
        let rays = self.options.ray_casting && scans.iter().any(|(_, o)| o.is_some());
        // Without ray casting the positions are checked while their cells are computed,
        // before the map changes.
        for (cloud, origin) in scans {
            self.check_scan(cloud, *origin, rays)?;
        }
        let old_len = self.cells.len();
        let points: usize = scans.iter().map(|(c, _)| c.len()).sum();
        if old_len.saturating_add(points) >= u32::MAX as usize {
            return Err(SrtreeError::InvalidOption {
                name: "points",
                value: points as f64,
                expected: "fewer than 2³² cells plus new points in one map",
            });
        }
        let mut batch = Batch {
            index: if rays {
                self.cells
                    .iter()
                    .enumerate()
                    .map(|(i, c)| (morton(c.key), i as u32))
                    .collect()
            } else {
                FxHashMap::default()
            },
            hashed: rays,
            last_scan: if rays { vec![0; old_len] } else { Vec::new() },
        };
        let clouds: Vec<&PointCloud> = scans.iter().map(|(c, _)| *c).collect();
        let mut total = InsertStats {
            points: clouds.iter().map(|c| c.len()).sum(),
            ..InsertStats::default()
        };
        if clouds.iter().any(|c| c.rgb.is_some()) && !self.coloured {
            self.coloured = true;
            self.colours = vec![ColourSum::default(); self.cells.len()];
        }
        if rays {
            // Scan by scan: the misses of a scan must see the hits of the scans before it.
            for (s, (cloud, origin)) in scans.iter().enumerate() {
                let scan = s as u32 + 1;
                let (order, codes) = self.sorted_points(&clouds[s..=s])?;
                total.touched_cells +=
                    self.update_endpoints(&clouds[s..=s], scan, (&order, &codes), &mut batch);
                if let Some(origin) = origin {
                    let (rays, misses) = self.cast_rays(
                        *origin,
                        &cloud.positions,
                        scan,
                        (&batch.index, &batch.last_scan),
                    );
                    total.rays += rays;
                    total.misses += misses;
                }
            }
        } else {
            // Hits only commute between cells: all points at once, sorted by cell and then
            // in insertion order, so new cells come out in Morton order.
            let (order, codes) = self.sorted_points(&clouds)?;
            total.touched_cells += self.update_endpoints(&clouds, 1, (&order, &codes), &mut batch);
        }
        drop(batch);
        total.new_cells = self.cells.len() - old_len;
        // Without rays, the cells are created in code order, which is Morton order.
        total.bulk_loaded = self.index_new_cells(old_len, !rays);
        Ok(total)
    }

    /// The runs of consecutive points of one cloud in one cell (see [`Item`]) of `clouds`,
    /// sorted: by cell, then in insertion order; the codes are the batch's [`BatchCodes`].
    /// A position that is not finite or outside the grid is an error.
    fn sorted_points(&self, clouds: &[&PointCloud]) -> Result<(Vec<Item>, BatchCodes)> {
        let r = self.options.resolution_m;
        let limit_m = f64::from(KEY_LIMIT) * r;
        // The positions' bounding box, and whether all are finite and inside the grid.
        type Bounds = ([f64; 3], [f64; 3], bool);
        let empty: Bounds = ([f64::INFINITY; 3], [f64::NEG_INFINITY; 3], true);
        let bounds = |ps: &[[f64; 3]]| {
            let (mut lo, mut hi, mut inside) = empty;
            for p in ps {
                for a in 0..3 {
                    lo[a] = lo[a].min(p[a]);
                    hi[a] = hi[a].max(p[a]);
                }
                inside &= self.inside_grid(p);
            }
            (lo, hi, inside)
        };
        let merge = |x: Bounds, y: Bounds| -> Bounds {
            (
                std::array::from_fn(|a| x.0[a].min(y.0[a])),
                std::array::from_fn(|a| x.1[a].max(y.1[a])),
                x.2 && y.2,
            )
        };
        let chunks = || {
            clouds.par_iter().enumerate().flat_map(|(s, c)| {
                c.positions
                    .par_chunks(POINT_CHUNK)
                    .enumerate()
                    .map(move |(j, ps)| (s, j * POINT_CHUNK, ps))
            })
        };
        let (lo, hi, inside) = chunks()
            .map(|(_, _, ps)| bounds(ps))
            .reduce(|| empty, merge);
        if !inside {
            for cloud in clouds {
                if let Some(index) = cloud.positions.iter().position(|p| !self.inside_grid(p)) {
                    return Err(self.position_error(index, cloud.positions[index], limit_m));
                }
            }
        }
        if lo[0] > hi[0] {
            return Ok((Vec::new(), BatchCodes::new([0; 3], [0; 3])));
        }
        // Division and floor are monotone: every key lies in the box of the corner keys.
        let key = |p: &[f64; 3]| p.map(|v| floor_i32(v / r));
        let codes = BatchCodes::new(key(&lo), key(&hi));
        let numbering = PointNumbering::new(clouds);
        // Runs of consecutive points in one cell, chunk by chunk (into a scratch vector per
        // thread, so that only exact-size vectors are allocated).
        let parts: Vec<Vec<Item>> = chunks()
            .map_init(Vec::new, |run: &mut Vec<Item>, (s, start, ps)| {
                run.clear();
                let mut last_key = None;
                for (k, p) in ps.iter().enumerate() {
                    let key = key(p);
                    if last_key == Some(key) {
                        if let Some(last) = run.last_mut().filter(|x| x.2 < u16::MAX) {
                            last.2 += 1;
                            continue;
                        }
                    }
                    last_key = Some(key);
                    run.push(Item(codes.code(key), numbering.number(s, start + k), 0));
                }
                run.to_vec()
            })
            .collect();
        let mut order = parts.concat();
        drop(parts);
        radix_sort_by_code(&mut order);
        Ok((order, codes))
    }
}

/// Numbers the points of a batch's clouds in insertion order in a `u32`: cloud and index
/// packed into bit fields when they fit, else the running index over the clouds.
pub(super) struct PointNumbering {
    /// Bits of the index within a cloud (packed numbering).
    index_bits: u32,
    /// Running index of each cloud's first point (`None`: packed numbering).
    starts: Option<Vec<u32>>,
}

impl PointNumbering {
    /// The numbering of these clouds (insert_scans checked that they hold fewer than 2³²
    /// points).
    pub(super) fn new(clouds: &[&PointCloud]) -> PointNumbering {
        let bits = |n: usize| usize::BITS - n.saturating_sub(1).leading_zeros();
        let index_bits = bits(clouds.iter().map(|c| c.len()).max().unwrap_or(0));
        if bits(clouds.len()) + index_bits <= u32::BITS {
            return PointNumbering {
                index_bits,
                starts: None,
            };
        }
        PointNumbering::running(clouds)
    }

    /// The running-index numbering.
    fn running(clouds: &[&PointCloud]) -> PointNumbering {
        let mut starts = Vec::with_capacity(clouds.len());
        let mut n = 0u32;
        for c in clouds {
            starts.push(n);
            n = n.wrapping_add(c.len() as u32);
        }
        PointNumbering {
            index_bits: 0,
            starts: Some(starts),
        }
    }

    /// The number of point `index` of cloud `cloud`.
    #[inline]
    fn number(&self, cloud: usize, index: usize) -> u32 {
        match &self.starts {
            None => ((cloud as u64) << self.index_bits | index as u64) as u32,
            Some(starts) => starts[cloud] + index as u32,
        }
    }

    /// (cloud, index) of a point number.
    #[inline]
    pub(super) fn cloud_and_index(&self, number: u32) -> (usize, usize) {
        match &self.starts {
            None => (
                (u64::from(number) >> self.index_bits) as usize,
                (u64::from(number) & ((1u64 << self.index_bits) - 1)) as usize,
            ),
            Some(starts) => {
                let c = starts.partition_point(|&s| s <= number) - 1;
                (c, (number - starts[c]) as usize)
            }
        }
    }
}

/// Points per chunk of the parallel passes over the positions.
const POINT_CHUNK: usize = 1 << 14;

#[cfg(test)]
mod tests {
    use super::*;
    use crate::dirichlet::majority;
    use crate::map::label::{add_label, expand_histogram};
    use crate::map::test_util::{canonical, random_cloud};
    use crate::map::MapOptions;
    use geodata::classes::Class;
    use geodata::cloud::{Columns, PointRecord, Precision};
    use rand::{Rng, SeedableRng};

    #[test]
    fn cells_hold_counts_colours_and_majorities() {
        let columns = Columns {
            label: true,
            rgb: true,
            object: true,
            ..Columns::default()
        };
        let mut cloud = PointCloud::with_columns(columns, Precision::F32, 4);
        for (x, label, rgb, object) in [
            (0.01, 1u8, [10u8, 20, 30], 7u32),
            (0.02, 1, [20, 40, 60], 7),
            (0.03, 2, [30, 60, 90], 9),
            (0.25, 3, [0, 0, 0], 4),
        ] {
            cloud.push(&PointRecord {
                position: [x, 0.05, 0.05],
                label,
                rgb,
                object,
                ..PointRecord::default()
            });
        }
        let mut map = SrMap::new(MapOptions::default()).unwrap();
        let stats = map.insert_cloud(&cloud, None).unwrap();
        assert_eq!((stats.points, stats.new_cells), (4, 2));
        let c = map.cell_at_key([0, 0, 0]).unwrap();
        assert_eq!(c.hits, 3);
        let id = map.cells().iter().position(|x| x == c).unwrap() as u32;
        assert_eq!(map.mean_rgb(id), [20, 40, 60]);
        assert_eq!(map.histogram(c)[1..4], [2, 1, 0]);
        assert_eq!((c.object, c.label), (7, 1));
        assert!((c.log_odds - 0.85).abs() < 1e-6);
        assert!(map.cell_at_key([2, 0, 0]).is_some());
    }

    #[test]
    fn non_finite_points_are_errors() {
        let mut cloud = random_cloud(10, 5.0, 1);
        cloud.positions[4][1] = f64::NAN;
        let mut map = SrMap::new(MapOptions::default()).unwrap();
        assert!(matches!(
            map.insert_cloud(&cloud, None),
            Err(SrtreeError::NonFinite { index: 4, .. })
        ));
        assert!(SrMap::new(MapOptions {
            resolution_m: 0.0,
            ..MapOptions::default()
        })
        .is_err());
    }

    /// Point-by-point reference: every cell's hits, histogram, object vote and log-odds
    /// from a plain per-point loop.
    #[test]
    fn batch_insertion_equals_a_point_by_point_reference() {
        let mut clouds: Vec<PointCloud> = (0..3).map(|s| random_cloud(3000, 2.0, 40 + s)).collect();
        // A scan-like cloud: neighbours often share a cell (runs of points).
        let mut walk = random_cloud(3000, 2.0, 43);
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(44);
        for i in 1..walk.len() {
            let step: [f64; 3] = std::array::from_fn(|_| rng.gen_range(-0.03..0.03));
            walk.positions[i] = std::array::from_fn(|a| walk.positions[i - 1][a] + step[a]);
        }
        clouds.push(walk);
        let mut map = SrMap::new(MapOptions::default()).unwrap();
        let batch: Vec<(&PointCloud, Option<[f64; 3]>)> =
            clouds.iter().map(|c| (c, None)).collect();
        map.insert_scans(&batch).unwrap();
        let o = MapOptions::default();
        /// Hits, log-odds, histogram, object, votes, red sum.
        type Want = (u32, f32, [u32; Class::COUNT], u32, u32, u32);
        let mut want: std::collections::BTreeMap<[i32; 3], Want> = Default::default();
        for cloud in &clouds {
            let mut hit_now = std::collections::BTreeSet::new();
            for i in 0..cloud.len() {
                let key = map.key_of(cloud.positions[i]);
                let e = want
                    .entry(key)
                    .or_insert((0, 0.0, [0; Class::COUNT], 0, 0, 0));
                e.0 += 1;
                if hit_now.insert(key) {
                    e.1 = (e.1 + o.log_odds_hit).min(o.log_odds_max);
                }
                e.2[usize::from(cloud.label.as_ref().unwrap()[i])] += 1;
                let id = cloud.object.as_ref().unwrap()[i];
                if id != 0 {
                    if e.4 == 0 {
                        (e.3, e.4) = (id, 1);
                    } else if e.3 == id {
                        e.4 += 1;
                    } else {
                        e.4 -= 1;
                    }
                }
                e.5 += u32::from(cloud.rgb.as_ref().unwrap()[i][0]);
            }
        }
        assert_eq!(map.len(), want.len());
        assert!(map.cells().is_sorted_by_key(|c| morton(c.key)));
        let mut mixed = 0;
        for (i, c) in map.cells().iter().enumerate() {
            let w = want[&c.key];
            let h = map.histogram(c);
            assert_eq!((c.hits, c.log_odds, c.object_votes as u32), (w.0, w.1, w.4));
            assert_eq!(h.map(u32::from), w.2);
            if w.4 > 0 {
                assert_eq!(c.object, w.3);
            }
            assert_eq!(c.label, majority(&h).unwrap());
            let sum = map.colours[i].sum[0];
            assert_eq!(sum, w.5);
            mixed += usize::from(h.iter().filter(|&&x| x > 0).count() > 1);
        }
        assert!(mixed > 0 && mixed < map.len());
        assert_eq!(map.histogram_table().len(), mixed);
    }

    #[test]
    fn a_run_longer_than_an_item_holds_is_split() {
        let n = usize::from(u16::MAX) + 5000;
        let mut cloud = random_cloud(n, 1.0, 45);
        cloud.positions.fill([0.05, 0.05, 0.05]);
        let mut map = SrMap::new(MapOptions::default()).unwrap();
        map.insert_cloud(&cloud, None).unwrap();
        assert_eq!(map.len(), 1);
        assert_eq!(map.cells()[0].hits, n as u32);
        let (mut table, mut r) = (Vec::new(), 0);
        for &l in cloud.label.as_ref().unwrap() {
            add_label(&mut table, &mut r, l);
        }
        assert_eq!(map.histogram(&map.cells()[0]), expand_histogram(&table, r));
    }

    #[test]
    fn point_numbers_follow_insertion_order_and_decode() {
        let clouds: Vec<PointCloud> = [3, 0, 5, 1]
            .iter()
            .map(|&n| random_cloud(n, 1.0, n as u64))
            .collect();
        let refs: Vec<&PointCloud> = clouds.iter().collect();
        let packed = PointNumbering::new(&refs);
        assert!(packed.starts.is_none());
        for numbering in [packed, PointNumbering::running(&refs)] {
            let mut last = None;
            for (c, cloud) in refs.iter().enumerate() {
                for i in 0..cloud.len() {
                    let number = numbering.number(c, i);
                    assert!(last.is_none_or(|l| l < number));
                    assert_eq!(numbering.cloud_and_index(number), (c, i));
                    last = Some(number);
                }
            }
        }
    }

    #[test]
    fn deferred_indexing_equals_one_batch_at_a_time() {
        let clouds: Vec<PointCloud> = (0..4).map(|s| random_cloud(800, 5.0, 20 + s)).collect();
        let options = MapOptions {
            resolution_m: 0.3,
            ray_casting: true,
            ..MapOptions::default()
        };
        let mut one_by_one = SrMap::new(options.clone()).unwrap();
        for c in &clouds {
            one_by_one.insert_cloud(c, Some([0.1, 0.2, 0.3])).unwrap();
        }
        let mut deferred = SrMap::new(options).unwrap();
        let batch: Vec<(&PointCloud, Option<[f64; 3]>)> =
            clouds.iter().map(|c| (c, Some([0.1, 0.2, 0.3]))).collect();
        let stats = deferred.insert_scans(&batch).unwrap();
        assert_eq!(stats.points, 3200);
        assert_eq!(canonical(&deferred), canonical(&one_by_one));
        let keys = |m: &SrMap| {
            let mut k: Vec<[i32; 3]> = m
                .cells_in_box([-2.0, -2.0, 0.0], [2.0, 3.0, 1.0])
                .iter()
                .map(|&i| m.cells()[i as usize].key)
                .collect();
            k.sort_unstable();
            k
        };
        let (a, b) = (keys(&deferred), keys(&one_by_one));
        assert_eq!(a, b);
        assert!(!a.is_empty());
    }
}
