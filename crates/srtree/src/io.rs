//! The `.srt` file of a [`SemanticMap`] (cells and relation graph): a little-endian binary
//! format with a checksum.
//!
//! | offset | size | field |
//! |---|---|---|
//! | 0 | 8 | magic `SRTREE\0\n` |
//! | 8 | 4 | format version `u32` (= 2; version 1 files are refused, rebuild them) |
//! | 12 | 8 | resolution, metres `f64` |
//! | 20 | 1 | ray casting flag `u8` (0 or 1) |
//! | 21 | 16 | log-odds hit, miss, min, max `f32` ×4 |
//! | 37 | 8 | maximum ray length, metres `f64` |
//! | 45 | 8 | cell count n `u64` |
//! | 53 | 32·n | cells: key `i32`×3, hits `u32`, log-odds `f32`, object `u32`, histogram reference `u32`, object votes `u16`, label `u8`, 1 zero byte |
//! | | 8 | full histograms m `u64` |
//! | | 20·m | full histograms: class counts `u16`×10 |
//! | | 8 | colour sums c `u64` (0, or n: one per cell) |
//! | | 16·c | colour sums: `u32`×3 and coloured points `u32` |
//! | | 4 | Dirichlet classes K `u32` (0: no model) |
//! | | 8 | smoothing `f64` (only if K > 0) |
//! | | K·(1 + 8K) | per class: present `u8`, then K concentrations `f64` if present |
//! | | 8 | relation-graph length L `u64` |
//! | | L | relation graph, UTF-8 JSON ([`crate::graph::RelationGraph`]) |
//! | | 8 | FNV-1a 64-bit checksum of every byte before it |
//!
//! A histogram reference with its top bit set indexes the full histograms (cells that saw
//! two classes or more); otherwise it is `class << 16 | count` for a cell whose labelled
//! points all had one class (count 0: none labelled).
//!
//! The R-tree is not stored: [`read_map`] packs it anew (one run, cells in Morton order).
//! Every read checks lengths, values (finite log-odds, known labels, keys within the
//! grid, unique keys, histogram references in range, positive concentrations) and the
//! checksum, and names the byte offset of what is wrong.

use crate::dirichlet::{Dirichlet, DirichletModel};
use crate::error::{io_err, Result, SrtreeError};
use crate::graph::RelationGraph;
use crate::map::{
    histogram_ref_valid, morton, Cell, ColourSum, Histogram, MapOptions, SrMap, KEY_LIMIT,
};
use crate::semantic::SemanticMap;
use geodata::classes::Class;
use rustc_hash::FxHashSet;
use std::path::Path;

/// The magic bytes at the start of every map file.
pub const MAGIC: &[u8; 8] = b"SRTREE\0\n";
/// The format version written and read.
pub const VERSION: u32 = 2;
/// Bytes of one cell record.
pub const CELL_BYTES: usize = 32;
/// Bytes of one full histogram.
const HISTOGRAM_BYTES: usize = 2 * Class::COUNT;
/// Bytes of one colour sum.
const COLOUR_BYTES: usize = 16;

/// The checksum stored in the last 8 bytes of a map file: FNV-1a 64 of every byte before it.
pub fn checksum(bytes: &[u8]) -> u64 {
    fnv1a(bytes)
}

fn fnv1a(bytes: &[u8]) -> u64 {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for &b in bytes {
        h ^= u64::from(b);
        h = h.wrapping_mul(0x0000_0100_0000_01b3);
    }
    h
}

/// The semantic map as file bytes.
pub fn encode_map(map: &SemanticMap) -> Vec<u8> {
    let cells = &map.cells;
    let o = cells.options();
    let mut out = Vec::with_capacity(64 + cells.len() * CELL_BYTES);
    out.extend_from_slice(MAGIC);
    out.extend_from_slice(&VERSION.to_le_bytes());
    out.extend_from_slice(&o.resolution_m.to_le_bytes());
    out.push(u8::from(o.ray_casting));
    for v in [
        o.log_odds_hit,
        o.log_odds_miss,
        o.log_odds_min,
        o.log_odds_max,
    ] {
        out.extend_from_slice(&v.to_le_bytes());
    }
    out.extend_from_slice(&o.max_ray_m.to_le_bytes());
    out.extend_from_slice(&(cells.len() as u64).to_le_bytes());
    for c in cells.cells() {
        for k in c.key {
            out.extend_from_slice(&k.to_le_bytes());
        }
        out.extend_from_slice(&c.hits.to_le_bytes());
        out.extend_from_slice(&c.log_odds.to_le_bytes());
        out.extend_from_slice(&c.object.to_le_bytes());
        out.extend_from_slice(&c.histogram_ref.to_le_bytes());
        out.extend_from_slice(&c.object_votes.to_le_bytes());
        out.extend_from_slice(&[c.label, 0]);
    }
    let table = cells.histogram_table();
    out.extend_from_slice(&(table.len() as u64).to_le_bytes());
    for h in table {
        for v in h {
            out.extend_from_slice(&v.to_le_bytes());
        }
    }
    let colours = cells.colour_sums();
    out.extend_from_slice(&(colours.len() as u64).to_le_bytes());
    for c in colours {
        for v in c.sum {
            out.extend_from_slice(&v.to_le_bytes());
        }
        out.extend_from_slice(&c.count.to_le_bytes());
    }
    match cells.dirichlet() {
        None => out.extend_from_slice(&0u32.to_le_bytes()),
        Some(m) => {
            out.extend_from_slice(&(m.classes.len() as u32).to_le_bytes());
            out.extend_from_slice(&m.smoothing.to_le_bytes());
            for d in &m.classes {
                match d {
                    None => out.push(0),
                    Some(d) => {
                        out.push(1);
                        for a in &d.alpha {
                            out.extend_from_slice(&a.to_le_bytes());
                        }
                    }
                }
            }
        }
    }
    // Serialising plain data to JSON cannot fail (no maps with non-string keys).
    let graph = serde_json::to_vec(&map.relations).unwrap_or_default();
    out.extend_from_slice(&(graph.len() as u64).to_le_bytes());
    out.extend_from_slice(&graph);
    let sum = fnv1a(&out);
    out.extend_from_slice(&sum.to_le_bytes());
    out
}

/// Writes a map file.
pub fn write_map(path: impl AsRef<Path>, map: &SemanticMap) -> Result<()> {
    let path = path.as_ref();
    geodata::fsio::write_atomic(path, encode_map(map)).map_err(io_err(path))
}

/// A bounds-checked little-endian reader naming the file and offset in its errors.
struct Reader<'a> {
    path: &'a Path,
    bytes: &'a [u8],
    pos: usize,
}

impl<'a> Reader<'a> {
    fn take(&mut self, n: usize, what: &'static str) -> Result<&'a [u8]> {
        if self.bytes.len() - self.pos < n {
            return Err(SrtreeError::Truncated {
                path: self.path.to_path_buf(),
                offset: self.bytes.len(),
                what,
                len: self.bytes.len(),
            });
        }
        let s = &self.bytes[self.pos..self.pos + n];
        self.pos += n;
        Ok(s)
    }
    fn array<const N: usize>(&mut self, what: &'static str) -> Result<[u8; N]> {
        let s = self.take(N, what)?;
        let mut a = [0u8; N];
        a.copy_from_slice(s);
        Ok(a)
    }
    fn u8(&mut self, what: &'static str) -> Result<u8> {
        Ok(self.array::<1>(what)?[0])
    }
    fn u16(&mut self, what: &'static str) -> Result<u16> {
        Ok(u16::from_le_bytes(self.array(what)?))
    }
    fn u32(&mut self, what: &'static str) -> Result<u32> {
        Ok(u32::from_le_bytes(self.array(what)?))
    }
    fn i32(&mut self, what: &'static str) -> Result<i32> {
        Ok(i32::from_le_bytes(self.array(what)?))
    }
    fn u64(&mut self, what: &'static str) -> Result<u64> {
        Ok(u64::from_le_bytes(self.array(what)?))
    }
    fn f32(&mut self, what: &'static str) -> Result<f32> {
        Ok(f32::from_le_bytes(self.array(what)?))
    }
    fn f64(&mut self, what: &'static str) -> Result<f64> {
        Ok(f64::from_le_bytes(self.array(what)?))
    }
    /// Checks that `count` records of `size` bytes fit in the rest of the file.
    fn check_fits(&self, count: u64, size: usize, what: &'static str) -> Result<()> {
        if count > ((self.bytes.len() - self.pos) / size) as u64 {
            return Err(SrtreeError::Truncated {
                path: self.path.to_path_buf(),
                offset: self.bytes.len(),
                what,
                len: self.bytes.len(),
            });
        }
        Ok(())
    }
    fn malformed(&self, offset: usize, message: String) -> SrtreeError {
        SrtreeError::Malformed {
            path: self.path.to_path_buf(),
            offset,
            message,
        }
    }
}

/// Parses map file bytes (`path` only names the source in errors).
pub fn decode_map(bytes: &[u8], path: &Path) -> Result<SemanticMap> {
    let mut r = Reader {
        path,
        bytes,
        pos: 0,
    };
    let head = &bytes[..bytes.len().min(8)];
    if head != MAGIC {
        return Err(SrtreeError::BadMagic {
            path: path.to_path_buf(),
            found: head.to_vec(),
            expected: MAGIC,
        });
    }
    r.pos = 8;
    let version = r.u32("version")?;
    if version != VERSION {
        return Err(SrtreeError::UnsupportedVersion {
            path: path.to_path_buf(),
            version,
            supported: VERSION,
        });
    }
    // The checksum first: a corrupted file is reported as such, not as a bad value.
    if bytes.len() < r.pos + 8 {
        return Err(SrtreeError::Truncated {
            path: path.to_path_buf(),
            offset: bytes.len(),
            what: "header",
            len: bytes.len(),
        });
    }
    let at = r.pos;
    let resolution_m = r.f64("resolution")?;
    if !(resolution_m.is_finite() && resolution_m >= 1e-3) {
        return Err(r.malformed(at, format!("resolution {resolution_m} m, expected ≥ 0.001")));
    }
    let at = r.pos;
    let ray_casting = match r.u8("ray casting flag")? {
        0 => false,
        1 => true,
        v => return Err(r.malformed(at, format!("ray casting flag {v}, expected 0 or 1"))),
    };
    let at = r.pos;
    let lo = [
        r.f32("log-odds hit")?,
        r.f32("log-odds miss")?,
        r.f32("log-odds min")?,
        r.f32("log-odds max")?,
    ];
    let max_ray_m = r.f64("maximum ray length")?;
    let options = MapOptions {
        resolution_m,
        ray_casting,
        log_odds_hit: lo[0],
        log_odds_miss: lo[1],
        log_odds_min: lo[2],
        log_odds_max: lo[3],
        max_ray_m,
    };
    if !(lo[0] > 0.0 && lo[1] < 0.0 && lo[2] < 0.0 && lo[3] > 0.0) {
        return Err(r.malformed(
            at,
            format!("log-odds hit/miss/min/max {lo:?}, expected hit > 0, miss < 0, min < 0 < max"),
        ));
    }
    let at = r.pos;
    let n = r.u64("cell count")?;
    let remaining = bytes.len() - r.pos;
    if n > (remaining / CELL_BYTES) as u64 {
        return Err(SrtreeError::Truncated {
            path: path.to_path_buf(),
            offset: bytes.len(),
            what: "cells",
            len: bytes.len(),
        });
    }
    let stored_sum = u64::from_le_bytes(
        bytes[bytes.len() - 8..]
            .try_into()
            .map_err(|_| r.malformed(bytes.len() - 8, "checksum".into()))?,
    );
    let computed = fnv1a(&bytes[..bytes.len() - 8]);
    if stored_sum != computed {
        return Err(SrtreeError::Checksum {
            path: path.to_path_buf(),
            stored: stored_sum,
            computed,
        });
    }
    let _ = at;
    let mut cells = Vec::with_capacity(n as usize);
    let mut refs_at = Vec::with_capacity(n as usize);
    // Keys in strictly increasing Morton order (as the writer stores a packed map) are
    // distinct; only other orders need the hash set, whose random access at tens of
    // millions of cells would dominate the read.
    let mut prev_code = None;
    let mut increasing = true;
    for _ in 0..n {
        let at = r.pos;
        let key = [r.i32("cell key")?, r.i32("cell key")?, r.i32("cell key")?];
        let hits = r.u32("hits")?;
        let log_odds = r.f32("log-odds")?;
        let object = r.u32("object")?;
        let histogram_ref = r.u32("histogram reference")?;
        let object_votes = r.u16("object votes")?;
        let tail = r.array::<2>("label")?;
        let label = tail[0];
        if key
            .iter()
            .any(|k| k.unsigned_abs() > KEY_LIMIT.unsigned_abs())
        {
            return Err(r.malformed(
                at,
                format!("cell key {key:?} outside the grid (|key| ≤ {KEY_LIMIT})"),
            ));
        }
        if !log_odds.is_finite() {
            return Err(r.malformed(at, format!("cell {key:?} has log-odds {log_odds}")));
        }
        if Class::from_id(label).is_none() {
            return Err(r.malformed(
                at + 30,
                format!(
                    "cell {key:?} has label {label}, expected < {}",
                    Class::COUNT
                ),
            ));
        }
        let code = morton(key);
        increasing &= prev_code.is_none_or(|p| p < code);
        prev_code = Some(code);
        refs_at.push(at + 24);
        cells.push(Cell {
            key,
            hits,
            log_odds,
            object,
            histogram_ref,
            object_votes,
            label,
        });
    }
    if !increasing {
        let mut seen = FxHashSet::with_capacity_and_hasher(cells.len(), Default::default());
        for (c, &at) in cells.iter().zip(&refs_at) {
            if !seen.insert(c.key) {
                return Err(r.malformed(at - 24, format!("cell key {:?} appears twice", c.key)));
            }
        }
    }
    let m = r.u64("full histogram count")?;
    r.check_fits(m, HISTOGRAM_BYTES, "full histograms")?;
    let mut table: Vec<Histogram> = Vec::with_capacity(m as usize);
    for _ in 0..m {
        let mut h = [0u16; Class::COUNT];
        for v in &mut h {
            *v = r.u16("histogram")?;
        }
        table.push(h);
    }
    for (c, &at) in cells.iter().zip(&refs_at) {
        if !histogram_ref_valid(c.histogram_ref, table.len()) {
            return Err(r.malformed(
                at,
                format!(
                    "cell {:?} has histogram reference {:#x}: not a class < {} nor one of {} full histograms",
                    c.key,
                    c.histogram_ref,
                    Class::COUNT,
                    table.len()
                ),
            ));
        }
    }
    let at = r.pos;
    let c = r.u64("colour sum count")?;
    if c != 0 && c != n {
        return Err(r.malformed(
            at,
            format!("{c} colour sums for {n} cells, expected 0 or {n}"),
        ));
    }
    r.check_fits(c, COLOUR_BYTES, "colour sums")?;
    let mut colours = Vec::with_capacity(c as usize);
    for _ in 0..c {
        let sum = [r.u32("colour")?, r.u32("colour")?, r.u32("colour")?];
        let count = r.u32("colour count")?;
        colours.push(ColourSum { sum, count });
    }
    let at = r.pos;
    let k = r.u32("Dirichlet class count")? as usize;
    let dirichlet = if k == 0 {
        None
    } else {
        if k != Class::COUNT {
            return Err(r.malformed(
                at,
                format!("{k} Dirichlet classes, expected {}", Class::COUNT),
            ));
        }
        let at = r.pos;
        let smoothing = r.f64("smoothing")?;
        if !(smoothing > 0.0 && smoothing.is_finite()) {
            return Err(r.malformed(at, format!("smoothing {smoothing}, expected > 0")));
        }
        let mut classes = Vec::with_capacity(k);
        for _ in 0..k {
            let at = r.pos;
            match r.u8("Dirichlet presence flag")? {
                0 => classes.push(None),
                1 => {
                    let mut alpha = Vec::with_capacity(k);
                    for _ in 0..k {
                        let at = r.pos;
                        let a = r.f64("concentration")?;
                        if !(a > 0.0 && a.is_finite()) {
                            return Err(r.malformed(at, format!("concentration {a}, expected > 0")));
                        }
                        alpha.push(a);
                    }
                    classes.push(Some(Dirichlet::new(alpha)));
                }
                v => return Err(r.malformed(at, format!("presence flag {v}, expected 0 or 1"))),
            }
        }
        Some(DirichletModel { smoothing, classes })
    };
    let len = r.u64("relation graph length")?;
    let at = r.pos;
    if len > (bytes.len() - r.pos) as u64 {
        return Err(SrtreeError::Truncated {
            path: path.to_path_buf(),
            offset: bytes.len(),
            what: "relation graph",
            len: bytes.len(),
        });
    }
    let graph_bytes = r.take(len as usize, "relation graph")?;
    let relations: RelationGraph = serde_json::from_slice(graph_bytes)
        .map_err(|e| r.malformed(at, format!("relation graph JSON: {e}")))?;
    if r.pos + 8 != bytes.len() {
        return Err(r.malformed(
            r.pos,
            format!(
                "{} unexpected bytes before the checksum",
                bytes.len() - 8 - r.pos
            ),
        ));
    }
    Ok(SemanticMap {
        cells: SrMap::from_parts(options, cells, table, colours, dirichlet)?,
        relations,
    })
}

/// Reads a map file.
pub fn read_map(path: impl AsRef<Path>) -> Result<SemanticMap> {
    let path = path.as_ref();
    let bytes = std::fs::read(path).map_err(io_err(path))?;
    decode_map(&bytes, path)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::dirichlet::FitOptions;
    use crate::graph::{ObjectNode, Relation, RelationEdge, Viewpoint};
    use crate::map::test_util::random_cloud;
    use crate::objects::OrientedBox;

    fn sample_map() -> SemanticMap {
        let cloud = random_cloud(2000, 5.0, 9);
        let mut map = SrMap::new(MapOptions {
            resolution_m: 0.3,
            ..MapOptions::default()
        })
        .unwrap();
        map.insert_cloud(&cloud, None).unwrap();
        let training: Vec<(Vec<u16>, u8)> = map
            .cells()
            .iter()
            .map(|c| {
                let h = map.histogram(c);
                (h.to_vec(), crate::dirichlet::majority(&h).unwrap_or(0))
            })
            .collect();
        let model = DirichletModel::fit(
            &training,
            &FitOptions {
                min_cells: 3,
                ..FitOptions::default()
            },
        )
        .unwrap();
        map.set_dirichlet(Some(model));
        let mut map = SemanticMap::new(map);
        map.relations.edges.push(RelationEdge {
            a: 1,
            b: 2,
            bits: Relation::On.bit(),
        });
        map
    }

    #[test]
    fn save_load_round_trip() {
        let map = sample_map();
        let bytes = encode_map(&map);
        let back = decode_map(&bytes, Path::new("x.srt")).unwrap();
        assert_eq!(encode_map(&back), bytes);
        assert_eq!(back.relations, map.relations);
        let (map, back) = (map.cells, back.cells);
        assert_eq!(back.cells(), map.cells());
        assert_eq!(back.histogram_table(), map.histogram_table());
        assert_eq!(back.colour_sums(), map.colour_sums());
        assert!(!map.histogram_table().is_empty() && !map.colour_sums().is_empty());
        assert_eq!(back.dirichlet(), map.dirichlet());
        assert_eq!(back.options(), map.options());
        let q = ([-1.0, -1.0, 0.0], [1.0, 1.0, 1.0]);
        let (mut a, mut b) = (map.cells_in_box(q.0, q.1), back.cells_in_box(q.0, q.1));
        a.sort_unstable();
        b.sort_unstable();
        assert_eq!(a, b);
    }

    #[test]
    fn malformed_files_are_clear_errors() {
        let bytes = encode_map(&sample_map());
        let p = Path::new("bad.srt");
        let err = decode_map(b"PLY\nformat", p).unwrap_err();
        assert!(matches!(err, SrtreeError::BadMagic { .. }), "{err}");
        assert!(err.to_string().contains("bad.srt"));
        for cut in [4, 10, 30, 60, 500, bytes.len() - 3] {
            let err = decode_map(&bytes[..cut], p).unwrap_err();
            assert!(
                matches!(
                    err,
                    SrtreeError::Truncated { .. }
                        | SrtreeError::BadMagic { .. }
                        | SrtreeError::Checksum { .. }
                ),
                "cut at {cut}: {err}"
            );
        }
        let mut flipped = bytes.clone();
        flipped[100] ^= 0x40;
        assert!(matches!(
            decode_map(&flipped, p),
            Err(SrtreeError::Checksum { .. })
        ));
        let mut version = bytes.clone();
        version[8] = 9;
        assert!(matches!(
            decode_map(&version, p),
            Err(SrtreeError::UnsupportedVersion { version: 9, .. })
        ));
        // Bad values with a valid checksum are Malformed errors naming their offset.
        let resum = |mut b: Vec<u8>| {
            let n = b.len();
            let sum = fnv1a(&b[..n - 8]);
            b[n - 8..].copy_from_slice(&sum.to_le_bytes());
            b
        };
        let mut label = bytes.clone();
        label[53 + 30] = 42;
        let err = decode_map(&resum(label), p).unwrap_err();
        assert!(
            matches!(err, SrtreeError::Malformed { offset: 83, .. }),
            "{err}"
        );
        let mut reference = bytes.clone();
        reference[53 + 32 + 24..53 + 32 + 28].copy_from_slice(&(u32::MAX).to_le_bytes());
        let err = decode_map(&resum(reference), p).unwrap_err();
        assert!(
            matches!(err, SrtreeError::Malformed { offset: 109, .. }),
            "{err}"
        );
        let mut key = bytes.clone();
        key[53..57].copy_from_slice(&(1i32 << 21).to_le_bytes());
        let err = decode_map(&resum(key), p).unwrap_err();
        assert!(
            matches!(err, SrtreeError::Malformed { offset: 53, .. }),
            "{err}"
        );
        // A key stored twice (the later copy named), whether or not the order is Morton's.
        for (from, to) in [(0usize, 2usize), (2, 1)] {
            let mut twice = bytes.clone();
            let (a, b) = (53 + 32 * from, 53 + 32 * to);
            let k: Vec<u8> = twice[a..a + 12].to_vec();
            twice[b..b + 12].copy_from_slice(&k);
            let err = decode_map(&resum(twice), p).unwrap_err();
            let later = a.max(b);
            assert!(
                matches!(&err, SrtreeError::Malformed { offset, message, .. }
                    if *offset == later && message.contains("appears twice")),
                "{from}->{to}: {err}"
            );
        }
        // Cells out of Morton order (another writer's) are read and re-sorted.
        let mut swapped = bytes.clone();
        let (c0, c1): (Vec<u8>, Vec<u8>) = (bytes[53..85].to_vec(), bytes[85..117].to_vec());
        swapped[53..85].copy_from_slice(&c1);
        swapped[85..117].copy_from_slice(&c0);
        let a = decode_map(&bytes, p).unwrap().cells;
        let b = decode_map(&resum(swapped), p).unwrap().cells;
        assert_eq!(a.len(), b.len());
        let keys = |m: &SrMap| {
            let mut k: Vec<[i32; 3]> = m.cells().iter().map(|c| c.key).collect();
            k.sort_unstable();
            k
        };
        assert_eq!(keys(&a), keys(&b));
        // A version 1 file is refused with the version named.
        let mut old = bytes.clone();
        old[8..12].copy_from_slice(&1u32.to_le_bytes());
        let err = decode_map(&old, p).unwrap_err();
        assert!(
            matches!(
                err,
                SrtreeError::UnsupportedVersion {
                    version: 1,
                    supported: 2,
                    ..
                }
            ),
            "{err}"
        );
        assert!(matches!(
            read_map("/nonexistent/map.srt"),
            Err(SrtreeError::Io { .. })
        ));
    }

    /// Issue 21: moving the relation graph out of `SrMap` into `SemanticMap` left the file
    /// bytes alone. A fixed map (single-class and pooled histograms, colours, a hand-set
    /// Dirichlet model, objects, an edge and a viewpoint) encodes to the length and checksum
    /// the writer gave before the move.
    #[test]
    fn file_bytes_are_those_written_before_the_semantic_map() {
        let mut cells = SrMap::new(MapOptions {
            resolution_m: 0.3,
            ..MapOptions::default()
        })
        .unwrap();
        cells
            .insert_cloud(&random_cloud(2000, 5.0, 9), None)
            .unwrap();
        let alpha = |k: usize| {
            (0..Class::COUNT)
                .map(|j| if j == k { 4.0 } else { 0.5 + j as f64 / 8.0 })
                .collect()
        };
        let classes = (0..Class::COUNT)
            .map(|k| (k % 3 != 1).then(|| Dirichlet::new(alpha(k))))
            .collect();
        cells.set_dirichlet(Some(DirichletModel {
            smoothing: 0.5,
            classes,
        }));
        let mut map = SemanticMap::new(cells);
        map.relations.viewpoint = Some(Viewpoint {
            position: [0.5, -1.0, 1.8],
            yaw_rad: 0.25,
        });
        for id in [1u32, 2] {
            let centre = [f64::from(id), 0.5, 0.25];
            map.relations.objects.push(ObjectNode {
                id,
                class: Class::ALL[id as usize],
                cells: 3 * id as usize,
                centroid: centre,
                bbox: OrientedBox {
                    centre,
                    half_extents: [0.5, 0.25, 1.0],
                    yaw_rad: 0.125,
                },
            });
        }
        map.relations.edges.push(RelationEdge {
            a: 1,
            b: 2,
            bits: Relation::On.bit() | Relation::LeftOf.bit(),
        });
        let bytes = encode_map(&map);
        assert_eq!(
            (bytes.len(), checksum(&bytes)),
            (85_157, 0x0535_cdb7_91c3_8ceb)
        );
    }

    /// Issue 16 (found by the `srt` fuzz target): a cell key of `i32::MIN` overflowed
    /// `abs()` in the grid check (a panic with overflow checks; without them the wrapped
    /// value passed the check and the key went on, outside the grid). It is a Malformed
    /// error naming the cell's offset.
    #[test]
    fn issue_16_cell_key_i32_min_is_refused() {
        let good = encode_map(&sample_map());
        for axis in 0..3 {
            let mut bytes = good.clone();
            let at = 53 + 4 * axis;
            bytes[at..at + 4].copy_from_slice(&i32::MIN.to_le_bytes());
            let n = bytes.len();
            let sum = checksum(&bytes[..n - 8]);
            bytes[n - 8..].copy_from_slice(&sum.to_le_bytes());
            match decode_map(&bytes, Path::new("min.srt")) {
                Err(SrtreeError::Malformed { offset, .. }) => assert_eq!(offset, 53),
                other => panic!("expected a Malformed error at offset 53, got {other:?}"),
            }
        }
    }
}
