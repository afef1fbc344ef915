//! The SRTree map: fixed-resolution occupancy cells kept only where occupied, indexed by an
//! R-tree (thesis §3.3.1, after RMAP).
//!
//! A point at `p` falls into the cell with integer key `⌊p / resolution⌋`. Each cell keeps
//! its hit count, an occupancy log-odds (OctoMap's sensor model: +0.85 per hit, −0.4 per
//! miss, clamped to [−2, 3.5]), the sum of the colours inserted, a class-count histogram
//! and the majority object id (Boyer–Moore vote: exact whenever one id holds more than half
//! of the cell's points). The cell label is the Dirichlet choice of [`crate::dirichlet`]
//! when the map has a model, else the histogram's majority.
//!
//! The cells live in a vector; a hash index maps keys to cells for insertion, and an
//! R-tree ([`rstar`], inner nodes are minimum bounding cuboids of ≤ [`NODE_CAPACITY`]
//! children) over the cell centres answers the spatial queries. A batch that adds more
//! cells than a quarter of the map re-bulk-loads the tree (OMT packing, O(n log n));
//! smaller batches are inserted one by one (O(log n) each).
//!
//! Free-space ray casting (optional, per batch as OctoMap's `insertPointCloud`): every
//! cell traversed by the ray from the sensor origin to a point (3-D DDA, Amanatides & Woo
//! 1987), except the cells hit in this batch, gets one miss per batch. Only cells that
//! exist are updated: free space is never stored. Queries return occupied cells only
//! (log-odds > 0).
//!
//! ```
//! use geodata::cloud::{Columns, PointCloud, PointRecord, Precision};
//! use srtree::map::{MapOptions, SrMap};
//! let mut cloud = PointCloud::with_columns(Columns { label: true, ..Columns::default() }, Precision::F32, 3);
//! for x in [0.01, 0.05, 0.52] {
//!     cloud.push(&PointRecord { position: [x, 0.0, 0.0], label: 1, ..PointRecord::default() });
//! }
//! let mut map = SrMap::new(MapOptions::default())?;
//! map.insert_cloud(&cloud, None)?;
//! assert_eq!(map.len(), 2);
//! assert_eq!(map.cells_in_box([0.0, -0.1, -0.1], [0.2, 0.1, 0.1]).len(), 1);
//! # Ok::<(), srtree::SrtreeError>(())
//! ```

use crate::dirichlet::{majority, DirichletModel};
use crate::error::{Result, SrtreeError};
use geodata::classes::Class;
use geodata::cloud::PointCloud;
use rayon::prelude::*;
use rstar::primitives::GeomWithData;
use rstar::{RTree, RTreeParams, AABB};
use rustc_hash::FxHashMap;

/// Largest number of children of an R-tree node (M of the thesis).
pub const NODE_CAPACITY: usize = 16;

/// R-tree parameters: nodes of 8 to [`NODE_CAPACITY`] children, R* insertion.
#[derive(Debug, Clone, Copy)]
pub struct CellTreeParams;

impl RTreeParams for CellTreeParams {
    const MIN_SIZE: usize = 6;
    const MAX_SIZE: usize = NODE_CAPACITY;
    const REINSERTION_COUNT: usize = 4;
    type DefaultInsertionStrategy = rstar::RStarInsertionStrategy;
}

/// A leaf entry of the R-tree: a cell centre and the cell's index.
pub type CellEntry = GeomWithData<[f32; 3], u32>;

/// Options of a map.
#[derive(Debug, Clone, PartialEq)]
pub struct MapOptions {
    /// Cell edge length, metres (default 0.1).
    pub resolution_m: f64,
    /// Cast rays from the sensor origin to mark traversed cells as free (OctoMap-like).
    pub ray_casting: bool,
    /// Log-odds added per hit.
    pub log_odds_hit: f32,
    /// Log-odds added per miss (negative).
    pub log_odds_miss: f32,
    /// Lower clamp of the log-odds.
    pub log_odds_min: f32,
    /// Upper clamp of the log-odds.
    pub log_odds_max: f32,
    /// Rays longer than this are not cast (the endpoint still counts), metres.
    pub max_ray_m: f64,
}

impl Default for MapOptions {
    fn default() -> Self {
        MapOptions {
            resolution_m: 0.1,
            ray_casting: false,
            log_odds_hit: 0.85,
            log_odds_miss: -0.4,
            log_odds_min: -2.0,
            log_odds_max: 3.5,
            max_ray_m: 100.0,
        }
    }
}

/// One occupied cell.
#[derive(Debug, Clone, PartialEq)]
pub struct Cell {
    /// Integer cell coordinates: the cell spans `[key·r, (key+1)·r)` per axis.
    pub key: [i32; 3],
    /// Points inserted.
    pub hits: u32,
    /// Occupancy log-odds.
    pub log_odds: f32,
    /// Sum of the colours of the points with colour.
    pub rgb_sum: [u32; 3],
    /// Points with colour.
    pub rgb_count: u32,
    /// Points per class id (halved together when one count would overflow).
    pub histogram: [u16; Class::COUNT],
    /// Majority object id candidate (0: none).
    pub object: u32,
    /// Boyer–Moore vote counter of `object`.
    pub object_votes: u32,
    /// Chosen class id.
    pub label: u8,
}

impl Cell {
    fn empty(key: [i32; 3]) -> Cell {
        Cell {
            key,
            hits: 0,
            log_odds: 0.0,
            rgb_sum: [0; 3],
            rgb_count: 0,
            histogram: [0; Class::COUNT],
            object: 0,
            object_votes: 0,
            label: 0,
        }
    }

    /// Mean colour of the points with colour (grey if none had colour).
    pub fn mean_rgb(&self) -> [u8; 3] {
        if self.rgb_count == 0 {
            return [128; 3];
        }
        let n = u64::from(self.rgb_count);
        self.rgb_sum
            .map(|s| ((u64::from(s) + n / 2) / n).min(255) as u8)
    }

    /// Occupancy probability from the log-odds.
    pub fn occupancy(&self) -> f64 {
        1.0 / (1.0 + (-f64::from(self.log_odds)).exp())
    }

    /// Whether the cell counts as occupied (log-odds > 0).
    pub fn occupied(&self) -> bool {
        self.log_odds > 0.0
    }

    /// The chosen class.
    pub fn class(&self) -> Class {
        Class::from_id(self.label).unwrap_or(Class::Unlabelled)
    }

    fn add_label(&mut self, label: u8) {
        let i = usize::from(label).min(Class::COUNT - 1);
        if self.histogram[i] == u16::MAX {
            for h in &mut self.histogram {
                *h /= 2;
            }
        }
        self.histogram[i] += 1;
    }

    fn add_object(&mut self, id: u32) {
        if self.object_votes == 0 {
            self.object = id;
            self.object_votes = 1;
        } else if self.object == id {
            self.object_votes = self.object_votes.saturating_add(1);
        } else {
            self.object_votes -= 1;
        }
    }
}

/// What one insertion did.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct InsertStats {
    /// Points inserted.
    pub points: usize,
    /// Cells created.
    pub new_cells: usize,
    /// Cells updated (created ones included).
    pub touched_cells: usize,
    /// Rays cast.
    pub rays: usize,
    /// Free-space updates applied to existing cells.
    pub misses: usize,
    /// Whether the R-tree was bulk-loaded anew.
    pub bulk_loaded: bool,
}

/// Bytes used by the map, by part.
#[derive(Debug, Clone, Copy, Default, PartialEq, serde::Serialize)]
pub struct MemoryReport {
    /// Cells stored.
    pub cells: usize,
    /// Bytes of the cell records.
    pub cell_bytes: usize,
    /// Bytes of the key → cell hash index (estimate from its capacity).
    pub index_bytes: usize,
    /// Bytes of the R-tree (leaf entries plus inner nodes, estimated).
    pub tree_bytes: usize,
    /// Total bytes.
    pub total_bytes: usize,
    /// Total bytes per stored cell.
    pub bytes_per_cell: f64,
}

/// The semantic R-tree map.
#[derive(Debug, Clone)]
pub struct SrMap {
    options: MapOptions,
    cells: Vec<Cell>,
    index: FxHashMap<[i32; 3], u32>,
    tree: RTree<CellEntry, CellTreeParams>,
    dirichlet: Option<DirichletModel>,
    /// Per cell: touched in the current batch (all false between batches; reused so a
    /// batch costs O(its points), not O(map)).
    stamp: Vec<bool>,
    /// The spatial relation graph inferred over the map's objects.
    pub relations: crate::graph::RelationGraph,
}

/// Largest |key| the grid accepts (keeps cell arithmetic far from i32 overflow).
const KEY_LIMIT: f64 = 1.0e9;

impl SrMap {
    /// An empty map.
    pub fn new(options: MapOptions) -> Result<SrMap> {
        let r = options.resolution_m;
        if !(r.is_finite() && r >= 1e-3) {
            return Err(SrtreeError::InvalidOption {
                name: "resolution_m",
                value: r,
                expected: "a cell size of at least 1 mm",
            });
        }
        if !(options.log_odds_min < 0.0
            && options.log_odds_max > 0.0
            && options.log_odds_hit > 0.0
            && options.log_odds_miss < 0.0)
        {
            return Err(SrtreeError::InvalidOption {
                name: "log_odds",
                value: f64::from(options.log_odds_hit),
                expected: "hit > 0, miss < 0, min < 0 < max",
            });
        }
        Ok(SrMap {
            options,
            cells: Vec::new(),
            index: FxHashMap::default(),
            tree: RTree::new_with_params(),
            dirichlet: None,
            stamp: Vec::new(),
            relations: Default::default(),
        })
    }

    /// A map from stored parts (used by the file reader).
    pub(crate) fn from_parts(
        options: MapOptions,
        cells: Vec<Cell>,
        dirichlet: Option<DirichletModel>,
        relations: crate::graph::RelationGraph,
    ) -> Result<SrMap> {
        let mut map = SrMap::new(options)?;
        map.index = cells
            .iter()
            .enumerate()
            .map(|(i, c)| (c.key, i as u32))
            .collect();
        map.cells = cells;
        map.dirichlet = dirichlet;
        map.relations = relations;
        map.rebuild_tree();
        Ok(map)
    }

    /// The options.
    pub fn options(&self) -> &MapOptions {
        &self.options
    }

    /// Cell size, metres.
    pub fn resolution_m(&self) -> f64 {
        self.options.resolution_m
    }

    /// Number of stored cells.
    pub fn len(&self) -> usize {
        self.cells.len()
    }

    /// True when no cell is stored.
    pub fn is_empty(&self) -> bool {
        self.cells.is_empty()
    }

    /// All stored cells (index = cell id used by the queries).
    pub fn cells(&self) -> &[Cell] {
        &self.cells
    }

    /// The cell with this key, if stored.
    pub fn cell_at_key(&self, key: [i32; 3]) -> Option<&Cell> {
        self.index.get(&key).map(|&i| &self.cells[i as usize])
    }

    /// The key of the cell containing a point.
    pub fn key_of(&self, p: [f64; 3]) -> [i32; 3] {
        let r = self.options.resolution_m;
        p.map(|v| (v / r).floor().clamp(-KEY_LIMIT, KEY_LIMIT) as i32)
    }

    /// Centre of a cell, metres.
    pub fn centre(&self, key: [i32; 3]) -> [f64; 3] {
        let r = self.options.resolution_m;
        key.map(|k| (f64::from(k) + 0.5) * r)
    }

    /// The Dirichlet model used for labels, if any.
    pub fn dirichlet(&self) -> Option<&DirichletModel> {
        self.dirichlet.as_ref()
    }

    /// Sets (or clears) the Dirichlet model and relabels every cell.
    pub fn set_dirichlet(&mut self, model: Option<DirichletModel>) {
        self.dirichlet = model;
        let model = self.dirichlet.as_ref();
        self.cells
            .par_iter_mut()
            .for_each(|c| c.label = choose_label(model, &c.histogram));
    }

    fn entry(&self, i: usize) -> CellEntry {
        let c = self.centre(self.cells[i].key);
        GeomWithData::new(c.map(|v| v as f32), i as u32)
    }

    fn rebuild_tree(&mut self) {
        let entries: Vec<CellEntry> = (0..self.cells.len()).map(|i| self.entry(i)).collect();
        self.tree = RTree::bulk_load_with_params(entries);
    }

    /// Inserts a cloud (its `label`, `rgb` and `object` columns when present); with
    /// ray casting on and an `origin` (the sensor position), traversed cells get a miss.
    pub fn insert_cloud(
        &mut self,
        cloud: &PointCloud,
        origin: Option<[f64; 3]>,
    ) -> Result<InsertStats> {
        let old_len = self.cells.len();
        let mut stats = self.update_cells(cloud, origin)?;
        stats.bulk_loaded = self.index_new_cells(old_len);
        Ok(stats)
    }

    /// Inserts scans one after the other (each a batch of its own, with its sensor origin
    /// for ray casting), and indexes the new cells once at the end, as OctoMap's lazy
    /// evaluation defers its inner nodes, then releases the cell vector's spare capacity.
    /// Returns the summed statistics.
    pub fn insert_scans(
        &mut self,
        scans: &[(&PointCloud, Option<[f64; 3]>)],
    ) -> Result<InsertStats> {
        let old_len = self.cells.len();
        let mut total = InsertStats::default();
        for (cloud, origin) in scans {
            let s = self.update_cells(cloud, *origin)?;
            total.points += s.points;
            total.new_cells += s.new_cells;
            total.touched_cells += s.touched_cells;
            total.rays += s.rays;
            total.misses += s.misses;
        }
        total.bulk_loaded = self.index_new_cells(old_len);
        // A batch of scans is the whole map or a large part: drop the growth slack.
        self.cells.shrink_to_fit();
        Ok(total)
    }

    /// Adds the cells from `old_len` on to the R-tree: a bulk load when they are more than
    /// a quarter of the old map, else one insertion each. Returns whether it bulk-loaded.
    fn index_new_cells(&mut self, old_len: usize) -> bool {
        let new_cells = self.cells.len() - old_len;
        if new_cells == 0 {
            return false;
        }
        if new_cells * 4 > old_len {
            self.rebuild_tree();
            return true;
        }
        for i in old_len..self.cells.len() {
            let e = self.entry(i);
            self.tree.insert(e);
        }
        false
    }

    /// Endpoint, ray and label updates of one batch; the R-tree is left to the caller.
    fn update_cells(
        &mut self,
        cloud: &PointCloud,
        origin: Option<[f64; 3]>,
    ) -> Result<InsertStats> {
        cloud.check_columns()?;
        let r = self.options.resolution_m;
        let limit_m = KEY_LIMIT * r;
        // Keys in parallel, checking every position.
        let keys: Vec<[i32; 3]> = cloud
            .positions
            .par_iter()
            .enumerate()
            .map(|(index, p)| {
                if !p.iter().all(|v| v.is_finite()) {
                    return Err(SrtreeError::NonFinite {
                        index,
                        position: *p,
                    });
                }
                if p.iter().any(|v| v.abs() >= limit_m) {
                    return Err(SrtreeError::OutOfGrid {
                        index,
                        position: *p,
                        limit_m,
                    });
                }
                Ok(p.map(|v| (v / r).floor() as i32))
            })
            .collect::<Result<_>>()?;
        let mut stats = InsertStats {
            points: keys.len(),
            ..InsertStats::default()
        };
        let old_len = self.cells.len();
        // Endpoint updates, one pass (hash lookups dominate; the cells touched are recorded
        // once through a batch stamp).
        let mut touched: Vec<u32> = Vec::new();
        let mut stamp = std::mem::take(&mut self.stamp);
        stamp.resize(old_len, false);
        let labels = cloud.label.as_deref();
        let rgbs = cloud.rgb.as_deref();
        let objects = cloud.object.as_deref();
        let hit = self.options.log_odds_hit;
        let max = self.options.log_odds_max;
        for (i, key) in keys.iter().enumerate() {
            let next = self.cells.len() as u32;
            let ci = *self.index.entry(*key).or_insert(next);
            if ci == next {
                self.cells.push(Cell::empty(*key));
                stamp.push(false);
            }
            let cell = &mut self.cells[ci as usize];
            if !stamp[ci as usize] {
                stamp[ci as usize] = true;
                touched.push(ci);
                // One hit per batch and cell, as OctoMap's insertPointCloud.
                cell.log_odds = (cell.log_odds + hit).min(max);
            }
            cell.hits = cell.hits.saturating_add(1);
            if let Some(l) = labels {
                cell.add_label(l[i]);
            }
            if let Some(c) = rgbs {
                if cell.rgb_count >= 1 << 24 {
                    cell.rgb_sum = cell.rgb_sum.map(|s| s / 2);
                    cell.rgb_count /= 2;
                }
                for (sum, v) in cell.rgb_sum.iter_mut().zip(c[i]) {
                    *sum += u32::from(v);
                }
                cell.rgb_count += 1;
            }
            if let Some(o) = objects {
                if o[i] != 0 {
                    cell.add_object(o[i]);
                }
            }
        }
        stats.new_cells = self.cells.len() - old_len;
        stats.touched_cells = touched.len();
        if let (true, Some(origin)) = (self.options.ray_casting, origin) {
            let (rays, misses) = self.cast_rays(origin, &cloud.positions, &stamp);
            stats.rays = rays;
            stats.misses = misses;
        }
        for &ci in &touched {
            stamp[ci as usize] = false;
        }
        self.stamp = stamp;
        // Labels of the touched cells.
        let model = self.dirichlet.as_ref();
        let cells = &mut self.cells;
        let new_labels: Vec<(u32, u8)> = touched
            .par_iter()
            .map(|&ci| (ci, choose_label(model, &cells[ci as usize].histogram)))
            .collect();
        for (ci, l) in new_labels {
            cells[ci as usize].label = l;
        }
        Ok(stats)
    }

    /// Free-space updates: one miss per batch for every existing cell a ray traverses
    /// before its endpoint, unless the cell was hit in this batch. Returns (rays, misses).
    fn cast_rays(
        &mut self,
        origin: [f64; 3],
        points: &[[f64; 3]],
        hit_now: &[bool],
    ) -> (usize, usize) {
        let r = self.options.resolution_m;
        let max_ray = self.options.max_ray_m;
        let index = &self.index;
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
                        if let Some(&ci) = index.get(&key) {
                            if !hit_now[ci as usize] {
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

    /// Occupied cells whose volume intersects the box `[min, max]` (metres), unsorted.
    pub fn cells_in_box(&self, min: [f64; 3], max: [f64; 3]) -> Vec<u32> {
        let h = 0.5 * self.options.resolution_m;
        let lo = [min[0] - h, min[1] - h, min[2] - h].map(|v| v as f32);
        let hi = [max[0] + h, max[1] + h, max[2] + h].map(|v| v as f32);
        let env = AABB::from_corners(lo, hi);
        self.tree
            .locate_in_envelope(&env)
            .map(|e| e.data)
            .filter(|&i| self.cells[i as usize].occupied())
            .collect()
    }

    /// Occupied cells whose centre lies within `radius_m` of `centre`, unsorted.
    pub fn cells_within_radius(&self, centre: [f64; 3], radius_m: f64) -> Vec<u32> {
        let c = centre.map(|v| v as f32);
        let r2 = (radius_m * radius_m) as f32;
        self.tree
            .locate_within_distance(c, r2)
            .map(|e| e.data)
            .filter(|&i| self.cells[i as usize].occupied())
            .collect()
    }

    /// The `k` occupied cells with centres nearest to `p`, nearest first.
    pub fn nearest_cells(&self, p: [f64; 3], k: usize) -> Vec<u32> {
        let q = p.map(|v| v as f32);
        self.tree
            .nearest_neighbor_iter(&q)
            .map(|e| e.data)
            .filter(|&i| self.cells[i as usize].occupied())
            .take(k)
            .collect()
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

    /// Bytes used, by part.
    pub fn memory(&self) -> MemoryReport {
        let cells = self.cells.len();
        let cell_bytes = self.cells.capacity() * std::mem::size_of::<Cell>();
        // hashbrown: one control byte plus the (key, value) slot per bucket.
        let index_bytes = self.index.capacity().next_power_of_two().max(1) * 8 / 7
            * (std::mem::size_of::<([i32; 3], u32)>() + 1);
        // Leaves plus inner nodes (each ~ one entry per child and a bounding box).
        let leaf = std::mem::size_of::<CellEntry>();
        let inner_nodes = cells.div_ceil(CellTreeParams::MIN_SIZE + 2);
        let tree_bytes = cells * (leaf + 8) + inner_nodes * (24 + 8 + 24);
        let total_bytes = cell_bytes + index_bytes + tree_bytes;
        MemoryReport {
            cells,
            cell_bytes,
            index_bytes,
            tree_bytes,
            total_bytes,
            bytes_per_cell: total_bytes as f64 / cells.max(1) as f64,
        }
    }

    /// Removes cells that are no longer occupied and rebuilds the index and tree.
    pub fn prune_free(&mut self) -> usize {
        let before = self.cells.len();
        self.cells.retain(Cell::occupied);
        self.index = self
            .cells
            .iter()
            .enumerate()
            .map(|(i, c)| (c.key, i as u32))
            .collect();
        self.rebuild_tree();
        before - self.cells.len()
    }

    /// Height of the R-tree (leaf level = 1).
    pub fn tree_height(&self) -> usize {
        fn depth<T: rstar::RTreeObject>(n: &rstar::ParentNode<T>) -> usize {
            1 + n
                .children()
                .iter()
                .map(|c| match c {
                    rstar::RTreeNode::Parent(p) => depth(p),
                    rstar::RTreeNode::Leaf(_) => 0,
                })
                .max()
                .unwrap_or(0)
        }
        depth(self.tree.root())
    }
}

/// The label of a histogram: the Dirichlet choice, or the majority without a model.
pub fn choose_label(model: Option<&DirichletModel>, histogram: &[u16]) -> u8 {
    model
        .and_then(|m| m.label(histogram))
        .or_else(|| majority(histogram))
        .unwrap_or(0)
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
pub(crate) mod tests {
    use super::*;
    use geodata::cloud::{Columns, PointRecord, Precision};
    use rand::{Rng, SeedableRng};

    pub(crate) fn random_cloud(n: usize, extent_m: f64, seed: u64) -> PointCloud {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        let columns = Columns {
            label: true,
            rgb: true,
            object: true,
            ..Columns::default()
        };
        let mut cloud = PointCloud::with_columns(columns, Precision::F64, n);
        for _ in 0..n {
            let p = [
                rng.gen_range(-extent_m..extent_m),
                rng.gen_range(-extent_m..extent_m),
                rng.gen_range(0.0..extent_m / 4.0),
            ];
            cloud.push(&PointRecord {
                position: p,
                label: rng.gen_range(0..Class::COUNT as u8),
                rgb: [rng.gen(), rng.gen(), rng.gen()],
                object: rng.gen_range(0..5),
                ..PointRecord::default()
            });
        }
        cloud
    }

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
        assert_eq!(c.mean_rgb(), [20, 40, 60]);
        assert_eq!(c.histogram[1..4], [2, 1, 0]);
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

    /// Brute-force versions of the queries.
    fn scan_box(map: &SrMap, min: [f64; 3], max: [f64; 3]) -> Vec<u32> {
        let h = 0.5 * map.resolution_m();
        (0..map.len() as u32)
            .filter(|&i| {
                let c = map.centre(map.cells()[i as usize].key).map(|v| v as f32);
                (0..3).all(|k| c[k] >= (min[k] - h) as f32 && c[k] <= (max[k] + h) as f32)
            })
            .collect()
    }

    fn dist2(map: &SrMap, i: u32, p: [f64; 3]) -> f32 {
        let c = map.centre(map.cells()[i as usize].key).map(|v| v as f32);
        let q = p.map(|v| v as f32);
        (0..3).map(|k| (c[k] - q[k]) * (c[k] - q[k])).sum()
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
                .filter(|&i| dist2(&map, i, a) <= (radius * radius) as f32)
                .collect();
            assert_eq!(got, want);
            let k = rng.gen_range(1..30);
            let got = map.nearest_cells(a, k);
            let mut all: Vec<f32> = (0..map.len() as u32).map(|i| dist2(&map, i, a)).collect();
            all.sort_by(f32::total_cmp);
            let got_d: Vec<f32> = got.iter().map(|&i| dist2(&map, i, a)).collect();
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
        assert_eq!(deferred.cells(), one_by_one.cells());
        let (mut a, mut b) = (
            deferred.cells_in_box([-2.0, -2.0, 0.0], [2.0, 3.0, 1.0]),
            one_by_one.cells_in_box([-2.0, -2.0, 0.0], [2.0, 3.0, 1.0]),
        );
        a.sort_unstable();
        b.sort_unstable();
        assert_eq!(a, b);
        assert!(!a.is_empty());
    }

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
