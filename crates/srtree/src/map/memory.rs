//! The bytes the map holds, and pruning of the cells that are no longer occupied.

use super::runs::Run;
use super::{Cell, ColourSum, Histogram, SrMap, POOLED};

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

impl SrMap {
    /// Bytes held, by part: every allocation of the map (capacities), the Dirichlet model
    /// aside.
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
}
