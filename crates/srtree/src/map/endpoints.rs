//! Endpoint updates of one batch: each cell of the sorted points is found once (binary
//! search, or the batch's hash index with ray casting) or created, and gets its points in
//! insertion order; without ray casting, slices of cells in parallel, merged in order.

use super::codes::BatchCodes;
use super::insert::{Batch, PointNumbering};
use super::label::{add_label, label_of};
use super::sort::Item;
use super::{morton, Cell, ColourSum, Histogram, MapOptions, SrMap, POOLED};
use geodata::cloud::PointCloud;
use rayon::prelude::*;

impl SrMap {
    /// Endpoint updates of sorted points (see [`SrMap::sorted_points`]; `clouds[s]` is scan
    /// `first + s`): each cell is looked up once and gets one hit per scan, then its points
    /// are applied in insertion order. Returns the (cell, scan) pairs touched.
    pub(super) fn update_endpoints(
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
}

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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::map::test_util::{canonical, random_cloud};

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
}
