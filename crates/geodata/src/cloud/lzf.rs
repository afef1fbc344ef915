//! LZF compression (Marc Lehmann's liblzf format), used by PCD `DATA binary_compressed`.
//!
//! The stream is a sequence of chunks, each starting with a control byte `c`:
//! `c < 32` is a literal run of `c + 1` bytes that follow; otherwise `len = c >> 5`
//! (7 means "add the next byte"), the back-reference distance is
//! `((c & 31) << 8 | next byte) + 1`, and `len + 2` bytes are copied from that distance
//! back (the copy may overlap the output being written). The compressor is a greedy
//! single-hash matcher (3-byte hash, window 8 KiB, matches up to 264 bytes): O(n).

/// The most bytes one byte of LZF data can decompress to.
///
/// A literal chunk of 1 + k bytes yields k bytes, a 2-byte back reference at most 8 and a
/// 3-byte one at most 7 + 255 + 2 = 264 bytes: each chunk yields at most 88 bytes per input
/// byte, so an honest uncompressed size is at most 88 × the compressed size.
pub const MAX_EXPANSION: usize = 88;

/// Why an LZF stream could not be decompressed; `at` is the input offset of the bad chunk.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum LzfError {
    /// The input ends inside a chunk.
    #[error("the LZF data ends inside the chunk at compressed byte {at}")]
    Truncated {
        /// Input offset of the chunk.
        at: usize,
    },
    /// A back reference points before the start of the output.
    #[error("the LZF chunk at compressed byte {at} refers to data before the start")]
    BadReference {
        /// Input offset of the chunk.
        at: usize,
    },
    /// The output would exceed the announced size.
    #[error("the LZF chunk at compressed byte {at} decompresses past the header's size")]
    Overflow {
        /// Input offset of the chunk.
        at: usize,
    },
}

/// Decompresses `input` into exactly `out_len` bytes.
///
/// O(`input.len()` + `out_len`); allocates `out_len` bytes, so a caller reading sizes from a
/// file checks `out_len` ≤ [`MAX_EXPANSION`] × `input.len()` first.
pub fn decompress(input: &[u8], out_len: usize) -> Result<Vec<u8>, LzfError> {
    let mut out: Vec<u8> = Vec::with_capacity(out_len);
    let mut ip = 0usize;
    while let Some(&ctrl) = input.get(ip) {
        let at = ip;
        ip += 1;
        if ctrl < 32 {
            let n = usize::from(ctrl) + 1;
            let lit = input.get(ip..ip + n).ok_or(LzfError::Truncated { at })?;
            if out.len() + n > out_len {
                return Err(LzfError::Overflow { at });
            }
            out.extend_from_slice(lit);
            ip += n;
        } else {
            let mut len = usize::from(ctrl >> 5);
            if len == 7 {
                len += usize::from(*input.get(ip).ok_or(LzfError::Truncated { at })?);
                ip += 1;
            }
            let low = usize::from(*input.get(ip).ok_or(LzfError::Truncated { at })?);
            ip += 1;
            let back = ((usize::from(ctrl & 31) << 8) | low) + 1;
            let len = len + 2;
            let start = out
                .len()
                .checked_sub(back)
                .ok_or(LzfError::BadReference { at })?;
            if out.len() + len > out_len {
                return Err(LzfError::Overflow { at });
            }
            for k in 0..len {
                let b = out
                    .get(start + k)
                    .copied()
                    .ok_or(LzfError::BadReference { at })?;
                out.push(b);
            }
        }
    }
    if out.len() != out_len {
        return Err(LzfError::Truncated { at: input.len() });
    }
    Ok(out)
}

const HASH_BITS: u32 = 14;
const MAX_OFFSET: usize = 1 << 13;
const MAX_LITERAL: usize = 32;
const MAX_MATCH: usize = 7 + 255 + 2;

/// Compresses `input` (any length; an empty input gives an empty stream).
pub fn compress(input: &[u8]) -> Vec<u8> {
    let mut out = Vec::with_capacity(input.len() / 2 + 16);
    let mut table = vec![usize::MAX; 1 << HASH_BITS];
    let mut lit_start = 0usize;
    let mut i = 0usize;
    let flush = |out: &mut Vec<u8>, from: usize, to: usize| {
        let mut s = from;
        while s < to {
            let n = (to - s).min(MAX_LITERAL);
            out.push((n - 1) as u8);
            out.extend_from_slice(&input[s..s + n]);
            s += n;
        }
    };
    while i + 2 < input.len() {
        let key =
            u32::from(input[i]) << 16 | u32::from(input[i + 1]) << 8 | u32::from(input[i + 2]);
        let h = (key.wrapping_mul(2_654_435_761) >> (32 - HASH_BITS)) as usize;
        let cand = table[h];
        table[h] = i;
        if cand != usize::MAX && i - cand <= MAX_OFFSET && input[cand..cand + 3] == input[i..i + 3]
        {
            let max = (input.len() - i).min(MAX_MATCH);
            let mut len = 3;
            while len < max && input[cand + len] == input[i + len] {
                len += 1;
            }
            flush(&mut out, lit_start, i);
            let off = i - cand - 1;
            let code = len - 2;
            if code < 7 {
                out.push(((code << 5) | (off >> 8)) as u8);
            } else {
                out.push(((7 << 5) | (off >> 8)) as u8);
                out.push((code - 7) as u8);
            }
            out.push((off & 0xff) as u8);
            i += len;
            lit_start = i;
        } else {
            i += 1;
        }
    }
    flush(&mut out, lit_start, input.len());
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    #[test]
    fn hand_made_stream() {
        // Literal "ab", then copy 4 bytes from distance 2: "ababab".
        let s = [1, b'a', b'b', (2 << 5), 1];
        assert_eq!(decompress(&s, 6).unwrap(), b"ababab");
        assert_eq!(decompress(&s, 5), Err(LzfError::Overflow { at: 3 }));
        assert_eq!(decompress(&s[..4], 6), Err(LzfError::Truncated { at: 3 }));
        assert_eq!(
            decompress(&[(1 << 5), 9], 3),
            Err(LzfError::BadReference { at: 0 })
        );
    }

    #[test]
    fn round_trips_random_and_repetitive_data() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(4);
        for n in [0usize, 1, 2, 3, 31, 32, 33, 1000, 70_000] {
            let random: Vec<u8> = (0..n).map(|_| rng.gen()).collect();
            let runs: Vec<u8> = (0..n).map(|i| (i / 300 % 7) as u8).collect();
            let text: Vec<u8> = (0..n).map(|i| b"point cloud "[i % 12]).collect();
            for data in [random, runs, text] {
                let c = compress(&data);
                assert_eq!(decompress(&c, data.len()).unwrap(), data);
            }
        }
        let zeros = vec![0u8; 100_000];
        assert!(compress(&zeros).len() < 1500);
    }

    #[test]
    fn longest_back_references_reach_the_expansion_bound() {
        // One literal, then back references of the longest length (7 + 255 + 2 = 264 bytes
        // from 3 input bytes) at distance 1: the best ratio LZF has.
        let mut s = vec![0u8, b'a'];
        for _ in 0..1000 {
            s.extend_from_slice(&[7 << 5, 255, 0]);
        }
        let n = 1 + 264 * 1000;
        let out = decompress(&s, n).unwrap();
        assert!(out.iter().all(|&b| b == b'a'));
        assert!(n <= MAX_EXPANSION * s.len());
        assert!(n > (MAX_EXPANSION - 1) * s.len());
    }
}
