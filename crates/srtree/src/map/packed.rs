//! A packed R-tree over cells sorted in Morton (Z) order, and the Morton code of a cell key.
//!
//! The cells of one run lie in a slice sorted by the Morton code of their keys. Leaf node
//! `j` covers the cells `[j·M, (j+1)·M)`, inner node `j` of level `l` covers the nodes
//! `[j·M, (j+1)·M)` of level `l − 1` (M = [`super::NODE_CAPACITY`]); each node stores only
//! its minimum bounding cuboid in integer cell keys (24 bytes), so the tree costs
//! ≈ 24 / (M − 1) bytes per cell and needs no pointers: children are found by index
//! arithmetic (Kamel & Faloutsos 1993, packed R-trees, with a Z-order instead of a Hilbert
//! order). Building is O(n) after the sort; a box query is O(log n + cells reported),
//! since a node inside the query box reports its whole cell range without testing it.

use rayon::prelude::*;
use std::ops::Range;

/// Children per node (M).
const M: usize = super::NODE_CAPACITY;

/// Offset added to a key before interleaving (keys are in `(−2²⁰, 2²⁰)`).
pub(super) const MORTON_BIAS: i64 = 1 << 20;

/// The bits of each byte value spread to every third bit.
static SPREAD_BYTE: [u64; 256] = {
    let mut table = [0u64; 256];
    let mut v = 0;
    while v < 256 {
        let mut bit = 0;
        while bit < 8 {
            table[v] |= ((v as u64 >> bit) & 1) << (3 * bit);
            bit += 1;
        }
        v += 1;
    }
    table
};

/// Spreads the low 21 bits of `v` to every third bit.
#[inline]
pub(super) fn spread(v: u64) -> u64 {
    SPREAD_BYTE[(v & 0xff) as usize]
        | SPREAD_BYTE[((v >> 8) & 0xff) as usize] << 24
        | SPREAD_BYTE[((v >> 16) & 0x1f) as usize] << 48
}

/// Inverse of [`spread`].
pub(super) fn compact(v: u64) -> u64 {
    let mut x = v & 0x1249_2492_4924_9249;
    x = (x | x >> 2) & 0x10c3_0c30_c30c_30c3;
    x = (x | x >> 4) & 0x100f_00f0_0f00_f00f;
    x = (x | x >> 8) & 0x001f_0000_ff00_00ff;
    x = (x | x >> 16) & 0x001f_0000_0000_ffff;
    x = (x | x >> 32) & 0x1f_ffff;
    x
}

/// The Morton code of a key whose components lie in `(−2²⁰, 2²⁰)`.
pub(crate) fn morton(key: [i32; 3]) -> u64 {
    let b = key.map(|k| (i64::from(k) + MORTON_BIAS) as u64);
    spread(b[0]) | spread(b[1]) << 1 | spread(b[2]) << 2
}

/// The key of a Morton code (inverse of [`morton`]).
#[cfg(test)]
pub(crate) fn unmorton(code: u64) -> [i32; 3] {
    [0, 1, 2].map(|k| (compact(code >> k) as i64 - MORTON_BIAS) as i32)
}

/// An inclusive box of integer cell keys.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct KeyBox {
    /// Smallest key per axis.
    pub min: [i32; 3],
    /// Largest key per axis.
    pub max: [i32; 3],
}

impl KeyBox {
    /// The box holding nothing.
    pub const EMPTY: KeyBox = KeyBox {
        min: [i32::MAX; 3],
        max: [i32::MIN; 3],
    };

    fn add_key(&mut self, k: [i32; 3]) {
        self.add_box(&KeyBox { min: k, max: k });
    }

    fn add_box(&mut self, b: &KeyBox) {
        self.min = std::array::from_fn(|a| self.min[a].min(b.min[a]));
        self.max = std::array::from_fn(|a| self.max[a].max(b.max[a]));
    }

    /// Whether the two boxes share a key.
    pub fn intersects(&self, o: &KeyBox) -> bool {
        (0..3).all(|a| self.min[a] <= o.max[a] && o.min[a] <= self.max[a])
    }

    /// Whether `inner` lies inside this box.
    pub fn contains_box(&self, inner: &KeyBox) -> bool {
        (0..3).all(|a| self.min[a] <= inner.min[a] && inner.max[a] <= self.max[a])
    }

    /// What a box query (this box) does with a node of box `node`.
    pub fn visit_node(&self, node: &KeyBox) -> Visit {
        if !self.intersects(node) {
            Visit::Skip
        } else if self.contains_box(node) {
            Visit::All
        } else {
            Visit::Descend
        }
    }

    /// Whether the key lies inside this box.
    pub fn contains(&self, k: [i32; 3]) -> bool {
        (0..3).all(|a| self.min[a] <= k[a] && k[a] <= self.max[a])
    }
}

/// What a traversal does with a node.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Visit {
    /// Nothing below the node matches.
    Skip,
    /// Every cell below the node matches.
    All,
    /// Some may match: look at the children.
    Descend,
}

/// A packed R-tree over `cells` keys in Morton order; level 0 holds the leaves.
#[derive(Debug, Clone, Default)]
pub(crate) struct PackedTree {
    levels: Vec<Vec<KeyBox>>,
    cells: usize,
}

impl PackedTree {
    /// Packs the tree over items already sorted by the Morton code of `key`. O(n).
    pub fn build<T: Sync>(items: &[T], key: impl Fn(&T) -> [i32; 3] + Sync) -> PackedTree {
        let mut levels = Vec::new();
        if items.is_empty() {
            return PackedTree { levels, cells: 0 };
        }
        let mut level: Vec<KeyBox> = items
            .par_chunks(M)
            .map(|chunk| {
                let mut b = KeyBox::EMPTY;
                for it in chunk {
                    b.add_key(key(it));
                }
                b
            })
            .collect();
        while level.len() > 1 {
            let up: Vec<KeyBox> = level
                .chunks(M)
                .map(|chunk| {
                    let mut b = KeyBox::EMPTY;
                    for c in chunk {
                        b.add_box(c);
                    }
                    b
                })
                .collect();
            levels.push(level);
            level = up;
        }
        levels.push(level);
        PackedTree {
            levels,
            cells: items.len(),
        }
    }

    /// Number of node levels (a tree of one leaf has height 1; empty: 0).
    pub fn height(&self) -> usize {
        self.levels.len()
    }

    /// Bytes of the node boxes.
    pub fn bytes(&self) -> usize {
        self.levels
            .iter()
            .map(|l| l.capacity() * std::mem::size_of::<KeyBox>())
            .sum::<usize>()
            + self.levels.capacity() * std::mem::size_of::<Vec<KeyBox>>()
    }

    /// The box of node `j` of `level`.
    pub fn node_box(&self, level: usize, j: usize) -> &KeyBox {
        &self.levels[level][j]
    }

    /// The root's level and index, if the tree is not empty.
    pub fn root(&self) -> Option<(usize, usize)> {
        self.levels.len().checked_sub(1).map(|l| (l, 0))
    }

    /// The children of node `j` of `level`: node indices of `level − 1`, or cell positions
    /// when `level` is 0.
    pub fn children(&self, level: usize, j: usize) -> Range<usize> {
        let len = match level {
            0 => self.cells,
            l => self.levels[l - 1].len(),
        };
        (j * M).min(len)..((j + 1) * M).min(len)
    }

    /// The cell positions below node `j` of `level`.
    pub fn cell_range(&self, level: usize, j: usize) -> Range<usize> {
        let span = M.pow(level as u32 + 1);
        (j * span).min(self.cells)..((j + 1) * span).min(self.cells)
    }

    /// Depth-first traversal: `test` decides per node; `report` gets each cell range below
    /// an [`Visit::All`] node (`true`) and each leaf's cells reached by descending (`false`:
    /// the caller tests them one by one).
    pub fn visit(
        &self,
        mut test: impl FnMut(&KeyBox) -> Visit,
        mut report: impl FnMut(Range<usize>, bool),
    ) {
        let Some(root) = self.root() else {
            return;
        };
        let mut stack = vec![root];
        while let Some((level, j)) = stack.pop() {
            match test(&self.levels[level][j]) {
                Visit::Skip => {}
                Visit::All => report(self.cell_range(level, j), true),
                Visit::Descend if level == 0 => report(self.children(0, j), false),
                Visit::Descend => {
                    // Reversed so the leftmost child is visited first (cells come out in order).
                    stack.extend(self.children(level, j).rev().map(|c| (level - 1, c)));
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    #[test]
    fn morton_codes_round_trip_and_order_by_octant() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
        for _ in 0..1000 {
            let k: [i32; 3] = std::array::from_fn(|_| rng.gen_range(-(1 << 20) + 1..1 << 20));
            assert_eq!(unmorton(morton(k)), k);
        }
        assert_eq!(morton([1, 0, 0]) - morton([0, 0, 0]), 1);
        assert_eq!(morton([0, 1, 0]) - morton([0, 0, 0]), 2);
        assert_eq!(morton([0, 0, 1]) - morton([0, 0, 0]), 4);
        assert!(morton([-1, 0, 0]) < morton([0, 0, 0]));
        for _ in 0..1000 {
            let v: u64 = rng.gen_range(0..1 << 21);
            let bit_by_bit = (0..21).fold(0, |x, b| x | ((v >> b) & 1) << (3 * b));
            assert_eq!(spread(v), bit_by_bit);
            assert_eq!(compact(bit_by_bit), v);
        }
    }

    #[test]
    fn box_traversal_equals_a_linear_scan() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(6);
        let mut keys: Vec<[i32; 3]> = (0..5000)
            .map(|_| std::array::from_fn(|_| rng.gen_range(-60..60)))
            .collect();
        keys.sort_by_key(|k| morton(*k));
        keys.dedup();
        let tree = PackedTree::build(&keys, |k| *k);
        assert!(tree.height() >= 3);
        for _ in 0..100 {
            let a: [i32; 3] = std::array::from_fn(|_| rng.gen_range(-70..70));
            let b: [i32; 3] = std::array::from_fn(|_| rng.gen_range(-70..70));
            let q = KeyBox {
                min: std::array::from_fn(|k| a[k].min(b[k])),
                max: std::array::from_fn(|k| a[k].max(b[k])),
            };
            let mut got = Vec::new();
            tree.visit(
                |b| q.visit_node(b),
                |range, all| got.extend(range.filter(|&i| all || q.contains(keys[i]))),
            );
            let want: Vec<usize> = (0..keys.len()).filter(|&i| q.contains(keys[i])).collect();
            assert_eq!(got, want);
        }
    }
}
