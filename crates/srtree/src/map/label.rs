//! Class histograms of the cells (one class in the record, else pooled in the map's table)
//! and the label chosen from them.

use super::{Histogram, POOLED};
use crate::dirichlet::{majority, DirichletModel};
use geodata::classes::Class;

/// The full histogram of a cell's `histogram_ref`.
pub(super) fn expand_histogram(table: &[Histogram], r: u32) -> Histogram {
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
pub(super) fn add_label(table: &mut Vec<Histogram>, r: &mut u32, label: u8) {
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

/// The label of a cell's histogram reference (see [`choose_label`]; without a model, a
/// one-class histogram is its class).
pub(super) fn label_of(model: Option<&DirichletModel>, table: &[Histogram], r: u32) -> u8 {
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
#[cfg(test)]
mod tests {
    use super::*;

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
}
