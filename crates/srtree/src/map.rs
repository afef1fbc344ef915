//! The SRTree map: fixed-resolution occupancy cells kept only where occupied, indexed by an
//! R-tree (thesis §3.3.1, after RMAP).
//!
//! A point at `p` falls into the cell with integer key `⌊p / resolution⌋` (each component
//! within ±[`KEY_LIMIT`]). Each cell keeps its hit count, an occupancy log-odds (OctoMap's
//! sensor model: +0.85 per hit, −0.4 per miss, clamped to [−2, 3.5]), a class-count
//! histogram and the majority object id (Boyer–Moore vote: exact whenever one id holds
//! more than half of the cell's points, votes saturate at 65 535); the sum of the colours
//! inserted is kept in a column of its own that exists only once a coloured point arrived.
//! The cell label is the Dirichlet choice of [`crate::dirichlet`] when the map has a
//! model, else the histogram's majority.
//!
//! **Memory.** A cell record is 32 bytes ([`Cell`]). A histogram holding one class lives in
//! the record (class and count); a cell that has seen two classes or more points to a
//! shared table of full histograms (20 bytes each). There is no hash index between
//! insertions: the cells are stored sorted by the Morton code of their keys, in runs, and
//! each run carries a packed R-tree ([`NODE_CAPACITY`] children per node, minimum bounding
//! cuboids of integer keys, ≈ 1.6 bytes per cell). A key is found by binary search.
//! [`SrMap::memory`] counts every byte the map holds (allocated capacities).
//!
//! **Insertion.** One batch (a cloud, or [`SrMap::insert_scans`]' list of scans) joins
//! consecutive points of a scan that share a cell into runs, and sorts the runs by (cell
//! code, scan, point) with a parallel radix sort on the batch's short codes (the Morton
//! order on ≈ 3·log₂(extent) bits, see `codes.rs`), finds each cell once
//! (binary search, or created in Morton order) and applies its points in insertion order,
//! slices of cells in parallel on copies that are merged in order: the result equals
//! inserting point by point, scan by scan. With ray casting the same is done scan by scan, and a
//! hash index of all cells lives during the batch for the rays' lookups. O(p log p) for p
//! points, no allocation per point. The batch's new cells form a new run; a
//! run is merged with the one before it while that one is less than twice its size
//! (Bentley–Saxe logarithmic method: O(log n) runs, each cell re-sorted O(log n) times),
//! so a batch adding more than a third of the map re-packs the whole tree.
//!
//! Free-space ray casting (optional, per scan as OctoMap's `insertPointCloud`): every
//! cell traversed by the ray from the sensor origin to a point (3-D DDA, Amanatides & Woo
//! 1987), except the cells hit in this scan, gets one miss per scan. Only cells that
//! exist are updated: free space is never stored. Queries return occupied cells only
//! (log-odds > 0). Cell ids (positions in [`SrMap::cells`]) hold until the next insertion.
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

mod codes;
mod packed;

use crate::dirichlet::{majority, DirichletModel};
use crate::error::{Result, SrtreeError};
use codes::BatchCodes;
use geodata::classes::Class;
use geodata::cloud::PointCloud;
pub(crate) use packed::morton;
use packed::{KeyBox, PackedTree, Visit};
use rayon::prelude::*;
use rustc_hash::FxHashMap;
use std::cmp::Ordering;
use std::collections::BinaryHeap;

/// Largest number of children of an R-tree node (M of the thesis).
pub const NODE_CAPACITY: usize = 16;

/// Largest |key| component the grid accepts (keys are 21-bit in the Morton code).
pub const KEY_LIMIT: i32 = (1 << 20) - 1;

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

/// A class histogram with all counts.
pub type Histogram = [u16; Class::COUNT];

/// Flag of [`Cell::histogram_ref`]: the low 31 bits index the map's histogram table.
const POOLED: u32 = 1 << 31;

/// One occupied cell (32 bytes).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Cell {
    /// Integer cell coordinates: the cell spans `[key·r, (key+1)·r)` per axis.
    pub key: [i32; 3],
    /// Points inserted.
    pub hits: u32,
    /// Occupancy log-odds.
    pub log_odds: f32,
    /// Majority object id candidate (0: none).
    pub object: u32,
    /// The class histogram: [`POOLED`] | index into the map's histogram table, or (one
    /// class only) `class << 16 | count` (count 0: no labelled point yet).
    pub(crate) histogram_ref: u32,
    /// Boyer–Moore vote counter of `object` (saturating).
    pub object_votes: u16,
    /// Chosen class id.
    pub label: u8,
}

const _: () = assert!(std::mem::size_of::<Cell>() == 32);

impl Cell {
    fn empty(key: [i32; 3]) -> Cell {
        Cell {
            key,
            hits: 0,
            log_odds: 0.0,
            object: 0,
            histogram_ref: 0,
            object_votes: 0,
            label: 0,
        }
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

/// The full histogram of a cell's `histogram_ref`.
pub(crate) fn expand_histogram(table: &[Histogram], r: u32) -> Histogram {
    if r & POOLED != 0 {
        return table[(r & !POOLED) as usize];
    }
    let mut h = [0; Class::COUNT];
    let count = (r & 0xffff) as u16;
    if count > 0 {
        h[((r >> 16) & 0xff) as usize] = count;
    }
    h
}

/// Whether a stored `histogram_ref` is valid for a table of `table_len` histograms.
pub(crate) fn histogram_ref_valid(r: u32, table_len: usize) -> bool {
    if r & POOLED != 0 {
        ((r & !POOLED) as usize) < table_len
    } else {
        r >> 16 < Class::COUNT as u32
    }
}

/// One more point of class `label` (ids ≥ COUNT count as the last class); a count at
/// `u16::MAX` halves the whole histogram first.
fn add_label(table: &mut Vec<Histogram>, r: &mut u32, label: u8) {
    let i = usize::from(label).min(Class::COUNT - 1);
    if *r & POOLED == 0 {
        let count = *r & 0xffff;
        let class = ((*r >> 16) & 0xff) as usize;
        if count == 0 || class == i {
            let count = if count == u32::from(u16::MAX) {
                count / 2
            } else {
                count
            };
            *r = (i as u32) << 16 | (count + 1);
            return;
        }
        let mut h = [0u16; Class::COUNT];
        h[class] = count as u16;
        assert!(table.len() < POOLED as usize, "histogram table overflow");
        *r = POOLED | table.len() as u32;
        table.push(h);
    }
    let h = &mut table[(*r & !POOLED) as usize];
    if h[i] == u16::MAX {
        for v in h.iter_mut() {
            *v /= 2;
        }
    }
    h[i] += 1;
}

/// Colour sum of a cell's coloured points.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub(crate) struct ColourSum {
    /// Sum per channel.
    pub sum: [u32; 3],
    /// Points with colour.
    pub count: u32,
}

impl ColourSum {
    fn add(&mut self, rgb: [u8; 3]) {
        if self.count >= 1 << 24 {
            self.sum = self.sum.map(|s| s / 2);
            self.count /= 2;
        }
        for (sum, v) in self.sum.iter_mut().zip(rgb) {
            *sum += u32::from(v);
        }
        self.count += 1;
    }

    fn mean(&self) -> [u8; 3] {
        if self.count == 0 {
            return [128; 3];
        }
        let n = u64::from(self.count);
        self.sum
            .map(|s| ((u64::from(s) + n / 2) / n).min(255) as u8)
    }
}

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

/// Bytes held by the map, by part (allocated capacities, not lengths).
#[derive(Debug, Clone, Copy, Default, PartialEq, serde::Serialize)]
pub struct MemoryReport {
    /// Cells stored.
    pub cells: usize,
    /// Bytes of the cell records.
    pub cell_bytes: usize,
    /// Bytes of the table of full histograms (cells with two classes or more).
    pub histogram_bytes: usize,
    /// Bytes of the colour sums (0 when no coloured point was inserted).
    pub colour_bytes: usize,
    /// Bytes of a key → cell index (0: keys are found by binary search).
    pub index_bytes: usize,
    /// Bytes of the R-tree nodes and runs.
    pub tree_bytes: usize,
    /// Total bytes.
    pub total_bytes: usize,
    /// Total bytes per stored cell.
    pub bytes_per_cell: f64,
}

/// A run of cells sorted by Morton code, with its packed R-tree.
#[derive(Debug, Clone, Default)]
struct Run {
    start: usize,
    end: usize,
    tree: PackedTree,
}

/// The semantic R-tree map.
#[derive(Debug, Clone)]
pub struct SrMap {
    options: MapOptions,
    cells: Vec<Cell>,
    histograms: Vec<Histogram>,
    /// One per cell once a coloured point was inserted (`coloured`), else empty.
    colours: Vec<ColourSum>,
    coloured: bool,
    runs: Vec<Run>,
    dirichlet: Option<DirichletModel>,
    /// The spatial relation graph inferred over the map's objects.
    pub relations: crate::graph::RelationGraph,
}

/// State of one insertion batch: with ray casting (which looks up every traversed cell) a
/// hash index of all cells, and per cell the last scan that hit it.
struct Batch {
    index: FxHashMap<u64, u32>,
    hashed: bool,
    /// Per cell (with ray casting only), the last scan that hit it.
    last_scan: Vec<u32>,
}

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
            histograms: Vec::new(),
            colours: Vec::new(),
            coloured: false,
            runs: Vec::new(),
            dirichlet: None,
            relations: Default::default(),
        })
    }

    /// A map from stored parts (used by the file reader, which has checked the keys and
    /// histogram references); the cells are re-packed into one run.
    pub(crate) fn from_parts(
        options: MapOptions,
        cells: Vec<Cell>,
        histograms: Vec<Histogram>,
        colours: Vec<ColourSum>,
        dirichlet: Option<DirichletModel>,
        relations: crate::graph::RelationGraph,
    ) -> Result<SrMap> {
        let mut map = SrMap::new(options)?;
        map.cells = cells;
        map.histograms = histograms;
        map.coloured = !colours.is_empty();
        map.colours = colours;
        map.dirichlet = dirichlet;
        map.relations = relations;
        map.index_new_cells(0, false);
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

    /// The table of full histograms (for the file writer).
    pub(crate) fn histogram_table(&self) -> &[Histogram] {
        &self.histograms
    }

    /// The colour sums, empty or one per cell (for the file writer).
    pub(crate) fn colour_sums(&self) -> &[ColourSum] {
        &self.colours
    }

    /// The class histogram of a cell of this map.
    pub fn histogram(&self, cell: &Cell) -> Histogram {
        expand_histogram(&self.histograms, cell.histogram_ref)
    }

    /// Mean colour of the coloured points of cell `id` (grey if none had colour).
    pub fn mean_rgb(&self, id: u32) -> [u8; 3] {
        self.colours
            .get(id as usize)
            .copied()
            .unwrap_or_default()
            .mean()
    }

    /// Id of the cell with this Morton code, by binary search in each run.
    fn find(&self, code: u64) -> Option<u32> {
        self.runs.iter().find_map(|run| {
            self.cells[run.start..run.end]
                .binary_search_by_key(&code, |c| morton(c.key))
                .ok()
                .map(|i| (run.start + i) as u32)
        })
    }

    /// The cell with this key, if stored. O(log² n).
    pub fn cell_at_key(&self, key: [i32; 3]) -> Option<&Cell> {
        if key.iter().any(|k| k.abs() > KEY_LIMIT) {
            return None;
        }
        self.find(morton(key)).map(|i| &self.cells[i as usize])
    }

    /// The key of the cell containing a point.
    pub fn key_of(&self, p: [f64; 3]) -> [i32; 3] {
        let r = self.options.resolution_m;
        let limit = f64::from(KEY_LIMIT);
        p.map(|v| floor_i32((v / r).clamp(-limit, limit)))
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
        let table = &self.histograms;
        self.cells
            .par_iter_mut()
            .for_each(|c| c.label = label_of(model, table, c.histogram_ref));
    }

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
                    let (rays, misses) = self.cast_rays(*origin, &cloud.positions, scan, &batch);
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

    /// Endpoint updates of sorted points (see [`SrMap::sorted_points`]; `clouds[s]` is scan
    /// `first + s`): each cell is looked up once and gets one hit per scan, then its points
    /// are applied in insertion order. Returns the (cell, scan) pairs touched.
    fn update_endpoints(
        &mut self,
        clouds: &[&PointCloud],
        first: u32,
        (order, codes): (&[Item], &BatchCodes),
        batch: &mut Batch,
    ) -> usize {
        if !batch.hashed {
            return self.update_endpoints_parallel(clouds, first, (order, codes));
        }
        let distinct = order.chunk_by(|a, b| a.code() == b.code()).count();
        self.cells.reserve(distinct);
        batch.last_scan.reserve(distinct);
        if self.coloured {
            self.colours.reserve(distinct);
        }
        let labelled = clouds.iter().any(|c| c.label.is_some());
        let numbering = PointNumbering::new(clouds);
        let mut touched = 0;
        for points in order.chunk_by(|a, b| a.code() == b.code()) {
            let ci = self.cell_for_key(codes.key(points[0].code()), batch) as usize;
            let mut colour = self.colours.get(ci).copied();
            let (t, scan) = apply_points(
                &mut self.cells[ci],
                &mut self.histograms,
                colour.as_mut(),
                points,
                (clouds, &numbering, first),
                &self.options,
            );
            if let Some(c) = colour {
                self.colours[ci] = c;
            }
            touched += t;
            batch.last_scan[ci] = scan;
            if labelled {
                let cell = &mut self.cells[ci];
                cell.label = label_of(
                    self.dirichlet.as_ref(),
                    &self.histograms,
                    cell.histogram_ref,
                );
            }
        }
        touched
    }

    /// [`SrMap::update_endpoints`] without a hash index: slices of whole cell groups are
    /// updated in parallel (existing cells found by binary search and updated on copies,
    /// created cells written in place), then merged in order, so cells and histogram table
    /// come out as a sequential pass makes them.
    fn update_endpoints_parallel(
        &mut self,
        clouds: &[&PointCloud],
        first: u32,
        (order, codes): (&[Item], &BatchCodes),
    ) -> usize {
        let labelled = clouds.iter().any(|c| c.label.is_some());
        let numbering = PointNumbering::new(clouds);
        let slices = group_slices(order, rayon::current_num_threads() * 8, MIN_SLICE);
        // The stored cell of every group ([`NEW_CELL`]: created), per slice.
        let found: Vec<Vec<u32>> = {
            let this = &*self;
            // A map without runs has no cell to find.
            let stored = !this.runs.is_empty();
            slices
                .par_iter()
                .map(|slice| {
                    slice
                        .chunk_by(|a, b| a.code() == b.code())
                        .map(|g| {
                            if stored {
                                this.find(morton(codes.key(g[0].code())))
                            } else {
                                None
                            }
                        })
                        .map(|ci| ci.unwrap_or(NEW_CELL))
                        .collect()
                })
                .collect()
        };
        let created: Vec<usize> = found
            .iter()
            .map(|f| f.iter().filter(|&&c| c == NEW_CELL).count())
            .collect();
        let total: usize = created.iter().sum();
        let old_len = self.cells.len();
        // Room for the created cells, filled in parallel below.
        self.cells.reserve_exact(total);
        self.cells
            .par_extend(rayon::iter::repeat_n(Cell::empty([0; 3]), total));
        if self.coloured {
            self.colours.reserve_exact(total);
            self.colours
                .par_extend(rayon::iter::repeat_n(ColourSum::default(), total));
        }
        let (old_cells, mut new_cells) = self.cells.split_at_mut(old_len);
        let colours_len = self.colours.len();
        let (old_colours, mut new_colours) = self.colours.split_at_mut(old_len.min(colours_len));
        let mut parts = Vec::with_capacity(slices.len());
        for ((slice, found), &n) in slices.into_iter().zip(found).zip(&created) {
            let (cells, rest) = std::mem::take(&mut new_cells).split_at_mut(n);
            new_cells = rest;
            let colours = if self.coloured {
                let (colours, rest) = std::mem::take(&mut new_colours).split_at_mut(n);
                new_colours = rest;
                colours
            } else {
                &mut []
            };
            parts.push((slice, found, cells, colours));
        }
        let (old_cells, old_colours) = (&*old_cells, &*old_colours);
        let (table, options, model) = (&self.histograms, &self.options, self.dirichlet.as_ref());
        let coloured = self.coloured;
        let updates: Vec<SliceUpdates> = parts
            .into_par_iter()
            .map(|(slice, found, cells, colours)| {
                let mut u = SliceUpdates::default();
                let mut next = 0;
                for (points, &ci) in slice.chunk_by(|a, b| a.code() == b.code()).zip(&found) {
                    let (mut cell, mut colour) = if ci == NEW_CELL {
                        (
                            Cell::empty(codes.key(points[0].code())),
                            ColourSum::default(),
                        )
                    } else {
                        let i = ci as usize;
                        (
                            old_cells[i],
                            old_colours.get(i).copied().unwrap_or_default(),
                        )
                    };
                    if cell.histogram_ref & POOLED != 0 {
                        let g = cell.histogram_ref & !POOLED;
                        cell.histogram_ref = POOLED | u.histograms.len() as u32;
                        u.histograms.push(table[g as usize]);
                        u.origin.push(g);
                    }
                    let (t, _) = apply_points(
                        &mut cell,
                        &mut u.histograms,
                        coloured.then_some(&mut colour),
                        points,
                        (clouds, &numbering, first),
                        options,
                    );
                    u.origin.resize(u.histograms.len(), NEW_HISTOGRAM);
                    u.touched += t;
                    if labelled {
                        cell.label = label_of(model, &u.histograms, cell.histogram_ref);
                    }
                    if ci == NEW_CELL {
                        if cell.histogram_ref & POOLED != 0 {
                            u.pooled_created.push(next as u32);
                        }
                        cells[next] = cell;
                        if let Some(c) = colours.get_mut(next) {
                            *c = colour;
                        }
                        next += 1;
                    } else {
                        u.existing.push((ci, cell, colour));
                    }
                }
                u
            })
            .collect();
        let mut touched = 0;
        let mut start = old_len;
        for (u, n) in updates.into_iter().zip(created) {
            touched += u.touched;
            // Local histogram index → map table index; new histograms are appended in the
            // order a sequential pass creates them.
            let remap: Vec<u32> = u
                .histograms
                .iter()
                .zip(&u.origin)
                .map(|(h, &g)| {
                    if g == NEW_HISTOGRAM {
                        assert!(
                            self.histograms.len() < POOLED as usize,
                            "histogram table overflow"
                        );
                        self.histograms.push(*h);
                        (self.histograms.len() - 1) as u32
                    } else {
                        self.histograms[g as usize] = *h;
                        g
                    }
                })
                .collect();
            for (ci, mut cell, colour) in u.existing {
                cell.histogram_ref = global_ref(&remap, cell.histogram_ref);
                self.cells[ci as usize] = cell;
                if self.coloured {
                    self.colours[ci as usize] = colour;
                }
            }
            for j in u.pooled_created {
                let cell = &mut self.cells[start + j as usize];
                cell.histogram_ref = global_ref(&remap, cell.histogram_ref);
            }
            start += n;
        }
        touched
    }

    /// The id of the cell with this key in the batch's hash index, created when missing.
    fn cell_for_key(&mut self, key: [i32; 3], batch: &mut Batch) -> u32 {
        let code = morton(key);
        if let Some(&ci) = batch.index.get(&code) {
            return ci;
        }
        // insert_scans checked that the cell count stays below 2³².
        let ci = self.cells.len() as u32;
        self.cells.push(Cell::empty(key));
        if self.coloured {
            self.colours.push(ColourSum::default());
        }
        batch.last_scan.push(0);
        batch.index.insert(code, ci);
        ci
    }

    /// Free-space updates of one scan: one miss for every existing cell a ray traverses
    /// before its endpoint, unless the cell was hit in this scan. Returns (rays, misses).
    fn cast_rays(
        &mut self,
        origin: [f64; 3],
        points: &[[f64; 3]],
        scan: u32,
        batch: &Batch,
    ) -> (usize, usize) {
        let r = self.options.resolution_m;
        let max_ray = self.options.max_ray_m;
        let (index, last_scan) = (&batch.index, &batch.last_scan);
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

    /// Sorts the cells from `start` on by Morton code (their colour sums with them).
    fn sort_from(&mut self, start: usize) {
        if self.cells[start..].is_sorted_by_key(|c| morton(c.key)) {
            return;
        }
        if !self.coloured {
            self.cells[start..].par_sort_unstable_by_key(|c| morton(c.key));
            return;
        }
        let mut order: Vec<(u64, u32)> = self.cells[start..]
            .iter()
            .enumerate()
            .map(|(i, c)| (morton(c.key), (start + i) as u32))
            .collect();
        order.par_sort_unstable();
        let cells: Vec<Cell> = order.iter().map(|&(_, i)| self.cells[i as usize]).collect();
        let colours: Vec<ColourSum> = order
            .iter()
            .map(|&(_, i)| self.colours[i as usize])
            .collect();
        self.cells[start..].copy_from_slice(&cells);
        self.colours[start..].copy_from_slice(&colours);
    }

    /// Makes the cells from `old_len` on a run and merges it with the runs before it while
    /// the one before is less than twice as large (`sorted`: the new cells are in Morton
    /// order already). Returns whether the whole map was packed anew (which also releases
    /// spare capacity).
    fn index_new_cells(&mut self, old_len: usize, sorted: bool) -> bool {
        let len = self.cells.len();
        if len == old_len {
            return false;
        }
        let mut start = old_len;
        while let Some(last) = self.runs.last() {
            if last.end - last.start < 2 * (len - start) {
                start = last.start;
                self.runs.pop();
            } else {
                break;
            }
        }
        if !(sorted && start == old_len) {
            self.sort_from(start);
        }
        let tree = PackedTree::build(&self.cells[start..], |c| c.key);
        self.runs.push(Run {
            start,
            end: len,
            tree,
        });
        if start == 0 {
            self.cells.shrink_to_fit();
            self.colours.shrink_to_fit();
            self.histograms.shrink_to_fit();
        }
        start == 0
    }

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

    /// Bytes held, by part: every allocation of the map (capacities), the Dirichlet model
    /// and relation graph aside.
    pub fn memory(&self) -> MemoryReport {
        let cells = self.cells.len();
        let cell_bytes = self.cells.capacity() * std::mem::size_of::<Cell>();
        let histogram_bytes = self.histograms.capacity() * std::mem::size_of::<Histogram>();
        let colour_bytes = self.colours.capacity() * std::mem::size_of::<ColourSum>();
        let tree_bytes = self.runs.iter().map(|r| r.tree.bytes()).sum::<usize>()
            + self.runs.capacity() * std::mem::size_of::<Run>();
        let total_bytes = cell_bytes + histogram_bytes + colour_bytes + tree_bytes;
        MemoryReport {
            cells,
            cell_bytes,
            histogram_bytes,
            colour_bytes,
            index_bytes: 0,
            tree_bytes,
            total_bytes,
            bytes_per_cell: total_bytes as f64 / cells.max(1) as f64,
        }
    }

    /// Removes cells that are no longer occupied, compacts the histogram table and packs
    /// the tree anew. Returns the number of cells removed.
    pub fn prune_free(&mut self) -> usize {
        let before = self.cells.len();
        let with_colours = self.coloured;
        let mut kept = 0;
        let mut table = Vec::new();
        for i in 0..before {
            let mut c = self.cells[i];
            if !c.occupied() {
                continue;
            }
            if c.histogram_ref & POOLED != 0 {
                table.push(self.histograms[(c.histogram_ref & !POOLED) as usize]);
                c.histogram_ref = POOLED | (table.len() - 1) as u32;
            }
            self.cells[kept] = c;
            if with_colours {
                self.colours[kept] = self.colours[i];
            }
            kept += 1;
        }
        self.cells.truncate(kept);
        self.colours.truncate(if with_colours { kept } else { 0 });
        self.histograms = table;
        self.runs.clear();
        self.index_new_cells(0, false);
        before - kept
    }

    /// Height of the tallest run's R-tree (a lone leaf = 1; empty map: 0).
    pub fn tree_height(&self) -> usize {
        self.runs.iter().map(|r| r.tree.height()).max().unwrap_or(0)
    }

    /// Number of runs (packed R-trees) the cells are split into.
    pub fn runs(&self) -> usize {
        self.runs.len()
    }
}

/// `⌊q⌋` for `|q| < 2³¹` without a call to libm's `floor`.
fn floor_i32(q: f64) -> i32 {
    let t = q as i32;
    if f64::from(t) > q {
        t - 1
    } else {
        t
    }
}

/// Consecutive points of one cloud in one cell: their cell code, the first one's number
/// ([`PointNumbering`]) and how many follow it, packed in 14 bytes (the sort moves every
/// item several times; a scan's neighbouring points often share a cell, so a run is a
/// third fewer items to sort on the real scans).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
#[repr(C, packed(2))]
struct Item(u64, u32, u16);

const _: () = assert!(std::mem::size_of::<Item>() == 14);

impl Item {
    /// The cell code.
    #[inline]
    fn code(self) -> u64 {
        self.0
    }

    /// The first point's number.
    #[inline]
    fn number(self) -> u32 {
        self.1
    }

    /// Points in the run.
    #[inline]
    fn len(self) -> usize {
        usize::from(self.2) + 1
    }
}

/// Numbers the points of a batch's clouds in insertion order in a `u32`: cloud and index
/// packed into bit fields when they fit, else the running index over the clouds.
struct PointNumbering {
    /// Bits of the index within a cloud (packed numbering).
    index_bits: u32,
    /// Running index of each cloud's first point (`None`: packed numbering).
    starts: Option<Vec<u32>>,
}

impl PointNumbering {
    /// The numbering of these clouds (insert_scans checked that they hold fewer than 2³²
    /// points).
    fn new(clouds: &[&PointCloud]) -> PointNumbering {
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
    fn cloud_and_index(&self, number: u32) -> (usize, usize) {
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

/// Fewest points per slice of a parallel endpoint update (small in tests, to have many).
#[cfg(not(test))]
const MIN_SLICE: usize = 1 << 14;
#[cfg(test)]
const MIN_SLICE: usize = 64;

/// [`SliceUpdates::origin`] of a histogram created in the slice.
const NEW_HISTOGRAM: u32 = u32::MAX;

/// A group of points whose cell is created by the batch.
const NEW_CELL: u32 = u32::MAX;

/// What one slice of cell groups leaves to merge into the map.
#[derive(Default)]
struct SliceUpdates {
    /// Updated copies of existing cells: (cell id, cell, colour sum).
    existing: Vec<(u32, Cell, ColourSum)>,
    /// Created cells (positions in the slice's part) whose histogram is pooled.
    pooled_created: Vec<u32>,
    /// Histograms of the slice's pooled cells (their `histogram_ref`s index this).
    histograms: Vec<Histogram>,
    /// Per histogram, the map table entry it updates ([`NEW_HISTOGRAM`]: a new one).
    origin: Vec<u32>,
    /// (cell, scan) pairs touched.
    touched: usize,
}

/// A cell's `histogram_ref` with a slice-local table index mapped to the map's table.
fn global_ref(remap: &[u32], r: u32) -> u32 {
    if r & POOLED != 0 {
        POOLED | remap[(r & !POOLED) as usize]
    } else {
        r
    }
}

/// Applies one cell's runs of points (sorted by scan, then point; `clouds[s]` is scan
/// `first + s`):
/// one hit per scan, then hit count, label histogram, object vote and colour per point.
/// Returns (scans touching the cell, last scan).
fn apply_points(
    cell: &mut Cell,
    histograms: &mut Vec<Histogram>,
    mut colour: Option<&mut ColourSum>,
    points: &[Item],
    (clouds, numbering, first): (&[&PointCloud], &PointNumbering, u32),
    options: &MapOptions,
) -> (usize, u32) {
    let (hit, max) = (options.log_odds_hit, options.log_odds_max);
    let mut scan = 0;
    let mut touched = 0;
    for x in points {
        let (c, i) = numbering.cloud_and_index(x.number());
        let s = first + c as u32;
        if s != scan {
            // One hit per scan and cell, as OctoMap's insertPointCloud.
            scan = s;
            touched += 1;
            cell.log_odds = (cell.log_odds + hit).min(max);
        }
        let cloud = clouds[c];
        let run = i..i + x.len();
        cell.hits = cell.hits.saturating_add(x.len() as u32);
        if let Some(l) = &cloud.label {
            for &l in &l[run.clone()] {
                add_label(histograms, &mut cell.histogram_ref, l);
            }
        }
        if let Some(o) = &cloud.object {
            for &o in &o[run.clone()] {
                if o != 0 {
                    cell.add_object(o);
                }
            }
        }
        if let (Some(c), Some(sum)) = (&cloud.rgb, colour.as_deref_mut()) {
            for &c in &c[run] {
                sum.add(c);
            }
        }
    }
    (touched, scan)
}

/// Splits sorted items into about `parts` slices (each at least `min_len` items unless it
/// is the last) that never cut a run of equal codes.
fn group_slices(items: &[Item], parts: usize, min_len: usize) -> Vec<&[Item]> {
    let target = (items.len() / parts.max(1)).max(min_len).max(1);
    let mut slices = Vec::new();
    let mut rest = items;
    while !rest.is_empty() {
        let mut end = target.min(rest.len());
        while end < rest.len() && rest[end].code() == rest[end - 1].code() {
            end += 1;
        }
        let (head, tail) = rest.split_at(end);
        slices.push(head);
        rest = tail;
    }
    slices
}

/// Sorts by code, keeping the order of equal codes: radix sort over the bits in which the
/// codes differ, most significant 11-bit digit first while a bucket is larger than the
/// cache ([`IN_CACHE`] items), then least significant digit first inside each bucket.
/// O(p · bits / 11), one scratch copy.
fn radix_sort_by_code(items: &mut [Item]) {
    if items.len() < 2 {
        return;
    }
    let (min, max) = items
        .par_iter()
        .fold(
            || (u64::MAX, 0),
            |(lo, hi), x| (lo.min(x.code()), hi.max(x.code())),
        )
        .reduce(|| (u64::MAX, 0), |a, b| (a.0.min(b.0), a.1.max(b.1)));
    let bits = 64 - (min ^ max).leading_zeros() as usize;
    let mut scratch = vec![Item::default(); items.len()];
    sort_low_bits(items, &mut scratch, bits, false);
}

/// Bits per radix digit.
const DIGIT: usize = 11;
/// Buckets this small are sorted least significant digit first (14 bytes each: 112 KiB).
const IN_CACHE: usize = 1 << 13;

/// Stable sort of `a` by the low `bits` bits of the codes (the others are equal); `b` is
/// scratch of the same length. The result lands in `b` when `to_b`, else in `a`.
fn sort_low_bits(a: &mut [Item], b: &mut [Item], bits: usize, to_b: bool) {
    if bits == 0 || a.len() < 2 {
        if to_b {
            b.copy_from_slice(a);
        }
        return;
    }
    if a.len() <= IN_CACHE {
        sort_in_cache(a, b, bits, to_b);
        return;
    }
    let shift = bits.saturating_sub(DIGIT);
    let counts = digit_counts(a, shift, bits - shift);
    let Some(spans) = scatter_spans(a, b, shift, bits - shift, &counts) else {
        sort_low_bits(a, b, shift, to_b);
        return;
    };
    // The data is in `b` now; the buckets are independent: sorted in parallel, each into
    // the side asked for, by the low bits in which its codes differ.
    let mut buckets = Vec::with_capacity(counts.len());
    let (mut rest_a, mut rest_b) = (a, b);
    for (c, bits) in counts.into_iter().zip(spans) {
        let (head_a, tail_a) = rest_a.split_at_mut(c);
        let (head_b, tail_b) = rest_b.split_at_mut(c);
        if c > 0 {
            buckets.push((head_b, head_a, bits));
        }
        rest_a = tail_a;
        rest_b = tail_b;
    }
    buckets
        .into_par_iter()
        .with_min_len(4)
        .for_each(|(b, a, bits)| sort_low_bits(b, a, bits, !to_b));
}

/// The first position of each bucket (prefix sums of the counts).
fn bucket_starts(counts: &[usize]) -> Vec<usize> {
    counts
        .iter()
        .scan(0, |sum, &c| {
            let start = *sum;
            *sum += c;
            Some(start)
        })
        .collect()
}

/// A stable scatter of `src` into `dst` by one digit that also returns, per bucket, the number of low bits in which its
/// codes differ (so the next pass starts at the highest of them). `None`: nothing moved.
fn scatter_spans(
    src: &[Item],
    dst: &mut [Item],
    shift: usize,
    width: usize,
    counts: &[usize],
) -> Option<Vec<usize>> {
    if counts.contains(&src.len()) {
        return None;
    }
    let mask = (1u64 << width) - 1;
    let mut offset = bucket_starts(counts);
    let (mut lo, mut hi) = (vec![u64::MAX; counts.len()], vec![0u64; counts.len()]);
    for x in src {
        let d = ((x.code() >> shift) & mask) as usize;
        dst[offset[d]] = *x;
        offset[d] += 1;
        lo[d] = lo[d].min(x.code());
        hi[d] = hi[d].max(x.code());
    }
    Some(
        lo.iter()
            .zip(&hi)
            .map(|(&l, &h)| (64 - (l ^ h).leading_zeros() as usize).min(shift))
            .collect(),
    )
}

/// [`sort_low_bits`] for a bucket that fits the cache: insertion sort when tiny, else least
/// significant digit first with digits no wider than the bucket is long (so the counters
/// cost no more than the items), all digit histograms from one read.
fn sort_in_cache(a: &mut [Item], b: &mut [Item], bits: usize, to_b: bool) {
    let n = a.len();
    if n <= 24 {
        for i in 1..n {
            let x = a[i];
            let mut j = i;
            while j > 0 && a[j - 1].code() > x.code() {
                a[j] = a[j - 1];
                j -= 1;
            }
            a[j] = x;
        }
        if to_b {
            b.copy_from_slice(a);
        }
        return;
    }
    let max_width = ((usize::BITS - n.leading_zeros()) as usize).clamp(4, DIGIT);
    let passes = bits.div_ceil(max_width);
    let width = bits.div_ceil(passes);
    let (size, mask) = (1usize << width, (1u64 << width) - 1);
    let mut counts = vec![0u32; passes * size];
    for x in a.iter() {
        let code = x.code();
        for (p, c) in counts.chunks_exact_mut(size).enumerate() {
            c[((code >> (p * width)) & mask) as usize] += 1;
        }
    }
    let mut in_a = true;
    for (p, c) in counts.chunks_exact_mut(size).enumerate() {
        let shift = p * width;
        let src_first = if in_a { a[0] } else { b[0] };
        if c[((src_first.code() >> shift) & mask) as usize] as usize == n {
            continue;
        }
        let mut sum = 0;
        for v in c.iter_mut() {
            let count = *v;
            *v = sum;
            sum += count;
        }
        let (src, dst) = if in_a { (&*a, &mut *b) } else { (&*b, &mut *a) };
        for x in src {
            let d = ((x.code() >> shift) & mask) as usize;
            dst[c[d] as usize] = *x;
            c[d] += 1;
        }
        in_a = !in_a;
    }
    if in_a && to_b {
        b.copy_from_slice(a);
    } else if !in_a && !to_b {
        a.copy_from_slice(b);
    }
}

/// Counts of the digit `(code >> shift) & (2^width − 1)`.
fn digit_counts(a: &[Item], shift: usize, width: usize) -> Vec<usize> {
    let mask = (1u64 << width) - 1;
    let count = |part: &[Item]| {
        let mut counts = vec![0usize; 1 << width];
        for x in part {
            counts[((x.code() >> shift) & mask) as usize] += 1;
        }
        counts
    };
    if a.len() < 1 << 18 {
        return count(a);
    }
    a.par_chunks(1 << 16).map(count).reduce(
        || vec![0usize; 1 << width],
        |mut x, y| {
            x.iter_mut().zip(y).for_each(|(x, y)| *x += y);
            x
        },
    )
}

/// The label of a cell's histogram reference (see [`choose_label`]; without a model, a
/// one-class histogram is its class).
fn label_of(model: Option<&DirichletModel>, table: &[Histogram], r: u32) -> u8 {
    if model.is_none() && r & POOLED == 0 {
        return if r & 0xffff > 0 {
            ((r >> 16) & 0xff) as u8
        } else {
            0
        };
    }
    choose_label(model, &expand_histogram(table, r))
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

    /// The cells as (key, record, full histogram), sorted by key: equal for two maps with
    /// the same content whatever their cell order and histogram table.
    pub(crate) fn canonical(map: &SrMap) -> Vec<([i32; 3], Cell, Histogram)> {
        let mut v: Vec<_> = map
            .cells()
            .iter()
            .map(|c| {
                let mut c2 = *c;
                c2.histogram_ref = 0;
                (c.key, c2, map.histogram(c))
            })
            .collect();
        v.sort_by_key(|x| x.0);
        v
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
    fn floor_without_libm_equals_floor() {
        for q in [
            0.0,
            -0.0,
            0.5,
            -0.5,
            1.0,
            -1.0,
            2.999,
            -2.999,
            1e9,
            -1e9 - 0.5,
            7.0 - 1e-12,
        ] {
            assert_eq!(floor_i32(q), q.floor() as i32, "{q}");
        }
    }

    #[test]
    fn radix_sort_is_a_stable_sort_by_code() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(8);
        for (n, spread) in [
            (0, 1u64),
            (1, 1),
            (5000, 1 << 40),
            (5000, 300),
            (3000, u64::MAX),
            // Above the cache size: most significant digits first, buckets in parallel.
            (60_000, 1 << 40),
            (60_000, 300),
            (60_000, u64::MAX >> 1),
        ] {
            let mut items: Vec<Item> = (0..n)
                .map(|i| Item(rng.gen_range(0..spread) | 7 << 50, i, 0))
                .collect();
            let mut want = items.clone();
            want.sort_by_key(|x| x.code());
            radix_sort_by_code(&mut items);
            assert_eq!(items, want);
        }
    }

    #[test]
    fn histogram_counts_halve_at_saturation() {
        let mut table = Vec::new();
        let mut r = 0u32;
        for _ in 0..u32::from(u16::MAX) {
            add_label(&mut table, &mut r, 3);
        }
        assert_eq!(expand_histogram(&table, r)[3], u16::MAX);
        add_label(&mut table, &mut r, 3);
        assert_eq!(expand_histogram(&table, r)[3], u16::MAX / 2 + 1);
        add_label(&mut table, &mut r, 5);
        let h = expand_histogram(&table, r);
        assert_eq!((h[3], h[5], table.len()), (u16::MAX / 2 + 1, 1, 1));
        assert!(histogram_ref_valid(r, 1) && !histogram_ref_valid(r, 0));
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
    fn parallel_endpoint_updates_equal_the_sequential_pass() {
        // Without ray casting, slices of cells are updated in parallel (existing cells
        // found by binary search); with ray casting (rays too long to be cast), one
        // sequential pass per scan over a hash index. Both must give the same cells, in the same order, and the same
        // histogram table, also when later batches hit cells made by earlier ones.
        let clouds: Vec<PointCloud> = (0..5).map(|s| random_cloud(4000, 1.5, 60 + s)).collect();
        let build = |ray_casting: bool| {
            let mut map = SrMap::new(MapOptions {
                ray_casting,
                max_ray_m: 1.0,
                ..MapOptions::default()
            })
            .unwrap();
            for part in [&clouds[..2], &clouds[2..3], &clouds[3..]] {
                let batch: Vec<(&PointCloud, Option<[f64; 3]>)> = part
                    .iter()
                    .map(|c| (c, ray_casting.then_some([100.0, 100.0, 100.0])))
                    .collect();
                map.insert_scans(&batch).unwrap();
            }
            map
        };
        let (parallel, sequential) = (build(false), build(true));
        // The sequential pass pools histograms scan by scan, so table indices differ;
        // the full histograms, cells and colours must not.
        assert_eq!(canonical(&parallel), canonical(&sequential));
        let keys = |m: &SrMap| m.cells().iter().map(|c| c.key).collect::<Vec<_>>();
        assert_eq!(keys(&parallel), keys(&sequential));
        assert_eq!(parallel.colour_sums(), sequential.colour_sums());
        assert_eq!(
            parallel.histogram_table().len(),
            sequential.histogram_table().len()
        );
        assert!(parallel.histogram_table().len() > 100);
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
