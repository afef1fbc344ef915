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
//! **Files.** This one: the cell, the map and their accessors; `insert.rs`: checks, point
//! numbering and the batch; `sort.rs`: the radix sort by cell code; `endpoints.rs`: a batch's
//! points applied to their cells; `raycast.rs`: free space; `runs.rs`: the sorted runs and
//! their trees; `query.rs`: the queries; `memory.rs`: bytes held, pruning; `label.rs`: class
//! histograms and labels; `packed.rs`: the packed R-tree and Morton codes; `codes.rs`: a
//! batch's short sort codes. The relation graph over the map's objects is not here: see
//! [`crate::semantic::SemanticMap`].
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
mod endpoints;
mod insert;
mod label;
mod memory;
mod packed;
mod query;
mod raycast;
mod runs;
mod sort;

use crate::dirichlet::DirichletModel;
use crate::error::{Result, SrtreeError};
use geodata::classes::Class;
use rayon::prelude::*;
use runs::Run;

pub use insert::InsertStats;
pub use label::choose_label;
pub(crate) use label::histogram_ref_valid;
use label::{expand_histogram, label_of};
pub use memory::MemoryReport;
pub(crate) use packed::morton;
pub use raycast::traverse;

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

/// The semantic R-tree map's cell store.
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
    ) -> Result<SrMap> {
        let mut map = SrMap::new(options)?;
        map.cells = cells;
        map.histograms = histograms;
        map.coloured = !colours.is_empty();
        map.colours = colours;
        map.dirichlet = dirichlet;
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

#[cfg(test)]
pub(crate) mod test_util {
    //! Test helpers shared by the map's submodules (and the file format's tests).

    use super::*;
    use geodata::cloud::{Columns, PointCloud, PointRecord, Precision};
    use rand::{Rng, SeedableRng};

    /// `n` uniform random points in [−e, e)² × [0, e/4) (e = `extent_m`) with random labels,
    /// colours and objects 0–4.
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
}

#[cfg(test)]
mod tests {
    use super::*;

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
}
