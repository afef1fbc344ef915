//! The stable radix sort of a batch's runs of points by cell code.

use rayon::prelude::*;

/// Consecutive points of one cloud in one cell: their cell code, the first one's number
/// ([`PointNumbering`](super::insert::PointNumbering)) and how many follow it, packed in
/// 14 bytes (the sort moves every item several times; a scan's neighbouring points often
/// share a cell, so a run is a third fewer items to sort on the real scans).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
#[repr(C, packed(2))]
pub(super) struct Item(pub(super) u64, pub(super) u32, pub(super) u16);

const _: () = assert!(std::mem::size_of::<Item>() == 14);

impl Item {
    /// The cell code.
    #[inline]
    pub(super) fn code(self) -> u64 {
        self.0
    }

    /// The first point's number.
    #[inline]
    pub(super) fn number(self) -> u32 {
        self.1
    }

    /// Points in the run.
    #[inline]
    pub(super) fn len(self) -> usize {
        usize::from(self.2) + 1
    }
}

/// Sorts by code, keeping the order of equal codes: radix sort over the bits in which the
/// codes differ, most significant 11-bit digit first while a bucket is larger than the
/// cache ([`IN_CACHE`] items), then least significant digit first inside each bucket.
/// O(p · bits / 11), one scratch copy.
pub(super) fn radix_sort_by_code(items: &mut [Item]) {
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
#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};

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
}
