//! Short sort codes for the cells of one insertion batch, ordered as their Morton codes.
//!
//! A Morton code interleaves the 21-bit biased keys: `morton(p·2ˢ + l) = interleave(p)·2³ˢ +
//! interleave(l)` for the high parts `p` and low parts `l < 2ˢ` of the three keys. Replacing
//! `interleave(p)` by its rank among the high parts a key box holds keeps the order and drops
//! the bits the batch does not use: a map around the origin straddles 2²⁰ in every biased key,
//! so its Morton codes differ in all 63 bits, while its sort codes need ≈ 3·log₂(extent).

use super::packed::{compact, spread, MORTON_BIAS};

/// Most high-part combinations a batch ranks (a table of 16 KiB).
const MAX_PREFIXES: u64 = 1 << 12;

/// The sort codes of the keys in one box.
#[derive(Debug, Clone)]
pub(crate) struct BatchCodes {
    /// Key bits below the high part.
    shift: u32,
    /// Smallest high part per axis.
    lo: [u64; 3],
    /// High parts per axis.
    dims: [u64; 3],
    /// Rank of each high-part combination (indexed x-major) in Morton order.
    rank: Vec<u32>,
    /// The high parts of each rank.
    prefix: Vec<[u64; 3]>,
}

/// A key as an unsigned 21-bit value.
fn biased(k: i32) -> u64 {
    (i64::from(k) + MORTON_BIAS) as u64
}

impl BatchCodes {
    /// Codes for the keys in `[min, max]` (inclusive, components in `(−2²⁰, 2²⁰)`).
    pub fn new(min: [i32; 3], max: [i32; 3]) -> BatchCodes {
        let (lo_b, hi_b) = (min.map(biased), max.map(biased));
        let dims_at = |s: u32| -> [u64; 3] {
            std::array::from_fn(|a| (hi_b[a] >> s).saturating_sub(lo_b[a] >> s) + 1)
        };
        let shift = (0..21)
            .find(|&s| dims_at(s).iter().product::<u64>() <= MAX_PREFIXES)
            .unwrap_or(21);
        let dims = dims_at(shift);
        let lo = lo_b.map(|b| b >> shift);
        let mut prefix = Vec::with_capacity(dims.iter().product::<u64>() as usize);
        for x in 0..dims[0] {
            for y in 0..dims[1] {
                for z in 0..dims[2] {
                    prefix.push([lo[0] + x, lo[1] + y, lo[2] + z]);
                }
            }
        }
        let interleave = |p: &[u64; 3]| spread(p[0]) | spread(p[1]) << 1 | spread(p[2]) << 2;
        let mut by_code: Vec<u32> = (0..prefix.len() as u32).collect();
        by_code.sort_unstable_by_key(|&i| interleave(&prefix[i as usize]));
        let mut rank = vec![0; prefix.len()];
        for (r, &i) in by_code.iter().enumerate() {
            rank[i as usize] = r as u32;
        }
        let prefix = by_code.iter().map(|&i| prefix[i as usize]).collect();
        BatchCodes {
            shift,
            lo,
            dims,
            rank,
            prefix,
        }
    }

    /// The code of a key inside the box.
    #[inline]
    pub fn code(&self, key: [i32; 3]) -> u64 {
        let s = self.shift;
        let b = key.map(biased);
        let p: [u64; 3] = std::array::from_fn(|a| (b[a] >> s) - self.lo[a]);
        let i = (p[0] * self.dims[1] + p[1]) * self.dims[2] + p[2];
        let m = (1u64 << s) - 1;
        u64::from(self.rank[i as usize]) << (3 * s)
            | spread(b[0] & m)
            | spread(b[1] & m) << 1
            | spread(b[2] & m) << 2
    }

    /// The key of a code (inverse of [`BatchCodes::code`]).
    pub fn key(&self, code: u64) -> [i32; 3] {
        let s = self.shift;
        let p = self.prefix[(code >> (3 * s)) as usize];
        let low = code & ((1u64 << (3 * s)) - 1);
        std::array::from_fn(|a| ((p[a] << s | compact(low >> a)) as i64 - MORTON_BIAS) as i32)
    }
}

#[cfg(test)]
mod tests {
    use super::super::packed::morton;
    use super::*;
    use rand::{Rng, SeedableRng};

    #[test]
    fn codes_order_as_morton_codes_and_invert() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        let limit = (1 << 20) - 1;
        for case in 0..200 {
            // Boxes from one cell to the whole grid, often straddling 0.
            let extent = 1i32 << rng.gen_range(0..21);
            let min: [i32; 3] = std::array::from_fn(|_| {
                rng.gen_range(-limit..=limit - extent.min(limit))
                    .max(-limit)
            });
            let max: [i32; 3] =
                std::array::from_fn(|a| (min[a] + rng.gen_range(0..=extent)).min(limit));
            let codes = BatchCodes::new(min, max);
            let keys: Vec<[i32; 3]> = (0..200)
                .map(|_| std::array::from_fn(|a| rng.gen_range(min[a]..=max[a])))
                .collect();
            for k in &keys {
                assert_eq!(codes.key(codes.code(*k)), *k, "case {case}");
            }
            for w in keys.windows(2) {
                assert_eq!(
                    codes.code(w[0]).cmp(&codes.code(w[1])),
                    morton(w[0]).cmp(&morton(w[1])),
                    "case {case}: {w:?}"
                );
            }
        }
    }

    #[test]
    fn a_box_straddling_zero_needs_few_bits() {
        let codes = BatchCodes::new([-563, -2269, -279], [10916, 1531, 361]);
        let (lo, hi) = (
            codes.code([-563, -2269, -279]),
            codes.code([10916, 1531, 361]),
        );
        let bits = |c: u64| 64 - c.leading_zeros();
        assert!(bits(lo.max(hi)) <= 40, "{} bits", bits(lo.max(hi)));
        let m = morton([10916, 1531, 361]) ^ morton([-563, -2269, -279]);
        assert_eq!(bits(m), 63);
    }
}
