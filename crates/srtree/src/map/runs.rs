//! The runs of cells: each a slice of cells sorted by Morton code with its packed R-tree,
//! merged by the logarithmic method; a key is found by binary search in each run.

use super::packed::PackedTree;
use super::{morton, Cell, ColourSum, SrMap};
use rayon::prelude::*;

/// A run of cells sorted by Morton code, with its packed R-tree.
#[derive(Debug, Clone, Default)]
pub(super) struct Run {
    /// First cell of the run.
    pub(super) start: usize,
    /// One past its last cell.
    pub(super) end: usize,
    /// The run's packed R-tree.
    pub(super) tree: PackedTree,
}

impl SrMap {
    /// Id of the cell with this Morton code, by binary search in each run.
    pub(super) fn find(&self, code: u64) -> Option<u32> {
        self.runs.iter().find_map(|run| {
            self.cells[run.start..run.end]
                .binary_search_by_key(&code, |c| morton(c.key))
                .ok()
                .map(|i| (run.start + i) as u32)
        })
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
    pub(super) fn index_new_cells(&mut self, old_len: usize, sorted: bool) -> bool {
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

    /// Height of the tallest run's R-tree (a lone leaf = 1; empty map: 0).
    pub fn tree_height(&self) -> usize {
        self.runs.iter().map(|r| r.tree.height()).max().unwrap_or(0)
    }

    /// Number of runs (packed R-trees) the cells are split into.
    pub fn runs(&self) -> usize {
        self.runs.len()
    }
}
