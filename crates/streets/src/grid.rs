//! A raster of square bins, each holding the ids of the cloud points that fall into it.
//!
//! Bins are stored row-major (`rows × cols`); the point ids of a bin are one contiguous slice
//! (compressed sparse rows), so a grid of B bins over P points costs O(B + P) memory and is
//! built by one counting sort.

/// Square bins with their point ids.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct BinGrid {
    /// Rows (along the street for a corridor).
    pub rows: usize,
    /// Columns (across the street for a corridor).
    pub cols: usize,
    /// Side of a bin, metres.
    pub bin_m: f64,
    /// `start[k] .. start[k+1]` indexes `point_ids` for bin k.
    pub start: Vec<u32>,
    /// Point ids, bin by bin.
    pub point_ids: Vec<u32>,
}

impl BinGrid {
    /// A grid from (bin index, point id) pairs; pairs with a bin index out of range are dropped.
    pub fn from_pairs(rows: usize, cols: usize, bin_m: f64, pairs: &[(u32, u32)]) -> BinGrid {
        let n = rows * cols;
        let mut count = vec![0u32; n + 1];
        for &(b, _) in pairs {
            if (b as usize) < n {
                count[b as usize + 1] += 1;
            }
        }
        for k in 0..n {
            count[k + 1] += count[k];
        }
        let mut fill = count.clone();
        let mut point_ids = vec![0u32; count[n] as usize];
        for &(b, p) in pairs {
            if (b as usize) < n {
                point_ids[fill[b as usize] as usize] = p;
                fill[b as usize] += 1;
            }
        }
        BinGrid {
            rows,
            cols,
            bin_m,
            start: count,
            point_ids,
        }
    }

    /// Number of bins.
    pub fn len(&self) -> usize {
        self.rows * self.cols
    }

    /// Whether the grid has no bins.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The point ids of bin k.
    pub fn points(&self, k: usize) -> &[u32] {
        &self.point_ids[self.start[k] as usize..self.start[k + 1] as usize]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pairs_land_in_their_bins() {
        let g = BinGrid::from_pairs(2, 2, 0.2, &[(3, 7), (0, 1), (3, 2), (9, 5)]);
        assert_eq!(g.points(0), &[1]);
        assert!(g.points(1).is_empty());
        assert_eq!(g.points(3), &[7, 2]);
        assert_eq!(g.point_ids.len(), 3);
    }
}
