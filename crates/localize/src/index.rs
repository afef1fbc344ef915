//! The map index (`.uloc`): what the search prepares once per map, saved to disk.
//!
//! Preparing a map (outline edges, the directional distance-transform tensor, its lower-bound
//! pyramid, the search domain and the feasible-pose mask) takes seconds on a city map; a
//! [`PreparedMap`] read from an index takes a fraction of that, and a [`Localizer`] built on
//! it searches exactly as one built from the map (tested: same ranked candidates).
//!
//! File layout, little-endian, version 1:
//!
//! | bytes | field |
//! |---|---|
//! | 8 | magic `ULOCIDX\0` |
//! | 4 | format version (u32) |
//! | 8 | body length (u64; the file is exactly 24 bytes longer) |
//! | 4 | CRC-32 (IEEE) of the body |
//! | … | body |
//!
//! The body: the source map (path as given when indexing, its byte length and CRC-32, so a
//! changed map makes the index stale), the preparation options (grid, channels, λ, τ,
//! pyramid levels, pose margin, feasible-only flag, street distance), the edges (4 × f64
//! each), the tensor (geometry and its `width × height × channels` bytes), the pyramid
//! levels, the domain, and the feasible mask (its levels of flags). Every length is checked
//! against what is left of the body before anything is allocated, and every array against
//! the geometry it belongs to, so a corrupt file is an error naming the file and the byte,
//! never a panic or a wrong answer.
//!
//! [`Localizer`]: crate::pipeline::Localizer

use crate::candidates::{Domain, SearchOptions};
use crate::chamfer::{map_edges, BoundPyramid, ChamferOptions, DtTensor};
use crate::feasible::FeasibleMask;
use crate::{LocalizeError, Result, Segment, WithContext};
use geodata::osm::OsmMap;
use std::io::{BufReader, Read, Write};
use std::path::{Path, PathBuf};
use std::time::Instant;

/// The index file's magic bytes.
pub const MAGIC: &[u8; 8] = b"ULOCIDX\0";
/// The index format version this build reads and writes.
pub const VERSION: u32 = 1;
const HEADER_BYTES: u64 = 24;

/// The map preparation options an index was built with (they must match the search's).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PrepOptions {
    /// Tensor grid, metres.
    pub grid_m: f64,
    /// Orientation channels.
    pub channels: usize,
    /// λ, metres per radian.
    pub lambda_m_per_rad: f64,
    /// τ, metres.
    pub truncation_m: f64,
    /// Pyramid levels.
    pub levels: u32,
    /// Margin of the pose domain around the edges, metres.
    pub pose_margin_m: f64,
    /// Whether the search is restricted to feasible poses.
    pub feasible_only: bool,
    /// Feasible poses lie within this of a street, metres.
    pub street_distance_m: f64,
}

impl PrepOptions {
    /// The preparation part of the chamfer and search options.
    pub fn of(chamfer: &ChamferOptions, search: &SearchOptions) -> PrepOptions {
        PrepOptions {
            grid_m: chamfer.grid_m,
            channels: chamfer.channels,
            lambda_m_per_rad: chamfer.lambda_m_per_rad,
            truncation_m: chamfer.truncation_m,
            levels: search.levels,
            pose_margin_m: search.pose_margin_m,
            feasible_only: search.feasible_only,
            street_distance_m: search.street_distance_m,
        }
    }

    /// The options that differ from `other`, as `name index=… requested=…` texts.
    pub fn differences(&self, other: &PrepOptions) -> Vec<String> {
        let mut out = Vec::new();
        let mut f = |name: &str, a: f64, b: f64| {
            if a != b {
                out.push(format!("{name}: index {a}, requested {b}"));
            }
        };
        f("grid_m", self.grid_m, other.grid_m);
        f("channels", self.channels as f64, other.channels as f64);
        f(
            "lambda_m_per_rad",
            self.lambda_m_per_rad,
            other.lambda_m_per_rad,
        );
        f("truncation_m", self.truncation_m, other.truncation_m);
        f("levels", f64::from(self.levels), f64::from(other.levels));
        f("pose_margin_m", self.pose_margin_m, other.pose_margin_m);
        f(
            "feasible_only",
            f64::from(u8::from(self.feasible_only)),
            f64::from(u8::from(other.feasible_only)),
        );
        f(
            "street_distance_m",
            self.street_distance_m,
            other.street_distance_m,
        );
        out
    }
}

/// Seconds spent preparing each part of a map.
#[derive(Debug, Clone, Copy, Default, PartialEq, serde::Serialize)]
pub struct MapSeconds {
    /// Outline edges and the visibility grid.
    pub edges: f64,
    /// Distance-transform tensor.
    pub distance_transform: f64,
    /// Lower-bound pyramid.
    pub pyramid: f64,
    /// Feasible-pose mask.
    pub feasible: f64,
}

/// What the search prepares once per map.
#[derive(Debug, Clone, PartialEq)]
pub struct PreparedMap {
    /// The options it was prepared with.
    pub options: PrepOptions,
    /// Building outline edges.
    pub edges: Vec<Segment>,
    /// The directional distance-transform tensor.
    pub dt: DtTensor,
    /// Its lower-bound pyramid.
    pub pyramid: BoundPyramid,
    /// The searched poses (cells).
    pub domain: Domain,
    /// The feasible poses of the domain (when the search is restricted to them).
    pub feasible: Option<FeasibleMask>,
    /// Preparation times (zero when read from an index).
    pub seconds: MapSeconds,
}

impl PreparedMap {
    /// Prepares a map for the given options.
    pub fn build(map: &OsmMap, chamfer: &ChamferOptions, search: &SearchOptions) -> Result<Self> {
        let t = Instant::now();
        let edges = map_edges(map);
        let edges_s = t.elapsed().as_secs_f64();
        let t = Instant::now();
        let dt = DtTensor::build(&edges, chamfer)?;
        let dt_s = t.elapsed().as_secs_f64();
        let t = Instant::now();
        let pyramid = BoundPyramid::build(&dt, search.levels);
        let pyr_s = t.elapsed().as_secs_f64();
        let t = Instant::now();
        let domain = match crate::chamfer::bounding_box(&edges) {
            Some((min, max)) => {
                let m = search.pose_margin_m;
                Domain::from_box(&dt, [min[0] - m, min[1] - m], [max[0] + m, max[1] + m])
            }
            None => Domain {
                i0: 0,
                j0: 0,
                i1: 0,
                j1: 0,
            },
        };
        let feasible = search.feasible_only.then(|| {
            FeasibleMask::build(map, &dt, domain, search.street_distance_m, pyramid.top())
        });
        Ok(PreparedMap {
            options: PrepOptions::of(chamfer, search),
            edges,
            dt,
            pyramid,
            domain,
            feasible,
            seconds: MapSeconds {
                edges: edges_s,
                distance_transform: dt_s,
                pyramid: pyr_s,
                feasible: t.elapsed().as_secs_f64(),
            },
        })
    }

    /// Writes the index of this prepared map of the map file `source` (atomically).
    pub fn write(&self, path: &Path, source: &Path) -> Result<()> {
        let err = |e: std::io::Error| index_err(path, format!("writing: {e}"));
        let map_bytes = std::fs::read(source)
            .map_err(|e| index_err(path, format!("reading its map {}: {e}", source.display())))?;
        let mut body = Enc::default();
        body.str(&source.to_string_lossy());
        body.u64(map_bytes.len() as u64);
        body.u32(crc32fast::hash(&map_bytes));
        let o = &self.options;
        body.f64(o.grid_m);
        body.u64(o.channels as u64);
        body.f64(o.lambda_m_per_rad);
        body.f64(o.truncation_m);
        body.u32(o.levels);
        body.f64(o.pose_margin_m);
        body.u8(u8::from(o.feasible_only));
        body.f64(o.street_distance_m);
        body.u64(self.edges.len() as u64);
        for e in &self.edges {
            for v in [e.a[0], e.a[1], e.b[0], e.b[1]] {
                body.f64(v);
            }
        }
        self.dt.encode(&mut body);
        self.pyramid.encode(&mut body);
        encode_domain(&mut body, self.domain);
        match &self.feasible {
            None => body.u8(0),
            Some(f) => {
                body.u8(1);
                f.encode(&mut body);
            }
        }
        let mut w = geodata::fsio::AtomicFile::create(path).map_err(err)?;
        w.write_all(MAGIC).map_err(err)?;
        w.write_all(&VERSION.to_le_bytes()).map_err(err)?;
        w.write_all(&(body.len() as u64).to_le_bytes())
            .map_err(err)?;
        w.write_all(&body.crc().to_le_bytes()).map_err(err)?;
        body.write_to(&mut w).map_err(err)?;
        w.commit().map_err(err)
    }

    /// Reads an index; returns it with the source map it was built from.
    pub fn read(path: &Path) -> Result<(PreparedMap, MapSource)> {
        let file = std::fs::File::open(path).map_err(|e| index_err(path, e.to_string()))?;
        let file_len = file
            .metadata()
            .map_err(|e| index_err(path, e.to_string()))?
            .len();
        let mut r = BufReader::with_capacity(1 << 20, file);
        let mut head = [0u8; HEADER_BYTES as usize];
        if file_len < HEADER_BYTES || r.read_exact(&mut head).is_err() {
            return Err(index_err(
                path,
                format!(
                    "{file_len} bytes: too short for a map index (header of {HEADER_BYTES} bytes)"
                ),
            ));
        }
        if &head[..8] != MAGIC {
            return Err(index_err(
                path,
                "not a urbansem map index (build one with `urbansem localize index --map MAP --out FILE.uloc`)".into(),
            ));
        }
        let version = u32::from_le_bytes(head[8..12].try_into().unwrap_or_default());
        if version != VERSION {
            return Err(index_err(
                path,
                format!("index format version {version}; this build reads version {VERSION}: rebuild the index with `urbansem localize index`"),
            ));
        }
        let body_len = u64::from_le_bytes(head[12..20].try_into().unwrap_or_default());
        let stored_crc = u32::from_le_bytes(head[20..24].try_into().unwrap_or_default());
        if body_len != file_len - HEADER_BYTES {
            return Err(index_err(
                path,
                format!(
                    "the header announces {body_len} bytes of body, the file holds {}: truncated or not an index",
                    file_len - HEADER_BYTES
                ),
            ));
        }
        let mut d = Dec {
            r,
            path,
            pos: HEADER_BYTES,
            end: file_len,
            crc: crc32fast::Hasher::new(),
        };
        let source = MapSource {
            path: PathBuf::from(d.string("map path")?),
            len: d.u64("map length")?,
            crc: d.u32("map checksum")?,
        };
        let options = PrepOptions {
            grid_m: d.f64("grid_m")?,
            channels: d.usize("channels")?,
            lambda_m_per_rad: d.f64("lambda")?,
            truncation_m: d.f64("truncation")?,
            levels: d.u32("levels")?,
            pose_margin_m: d.f64("pose margin")?,
            feasible_only: d.u8("feasible flag")? != 0,
            street_distance_m: d.f64("street distance")?,
        };
        let n = d.count(32, "edges")?;
        let mut edges = Vec::with_capacity(n);
        for _ in 0..n {
            let v: [f64; 4] = d.f64s("edge")?;
            edges.push(Segment::new([v[0], v[1]], [v[2], v[3]]));
        }
        let dt = DtTensor::decode(&mut d)?;
        let pyramid = BoundPyramid::decode(&mut d)?;
        let domain = decode_domain(&mut d)?;
        let feasible = match d.u8("feasible mask flag")? {
            0 => None,
            1 => Some(FeasibleMask::decode(&mut d)?),
            v => return Err(d.bad(format!("feasible mask flag {v}, expected 0 or 1"))),
        };
        if d.pos != d.end {
            return Err(d.bad(format!("{} bytes after the last section", d.end - d.pos)));
        }
        let crc = d.crc.clone().finalize();
        if crc != stored_crc {
            return Err(index_err(
                path,
                format!("checksum mismatch (stored {stored_crc:#010x}, computed {crc:#010x}): the file is corrupt; rebuild it"),
            ));
        }
        if dt.channels != options.channels || dt.grid_m != options.grid_m {
            return Err(index_err(
                path,
                "the tensor's grid or channels differ from the recorded options".into(),
            ));
        }
        if pyramid.top() != options.levels.max(1) || options.feasible_only != feasible.is_some() {
            return Err(index_err(
                path,
                "the pyramid or feasible mask does not match the recorded options".into(),
            ));
        }
        Ok((
            PreparedMap {
                options,
                edges,
                dt,
                pyramid,
                domain,
                feasible,
                seconds: MapSeconds::default(),
            },
            source,
        ))
    }
}

/// The map file an index was built from.
#[derive(Debug, Clone, PartialEq)]
pub struct MapSource {
    /// Its path as given when indexing.
    pub path: PathBuf,
    /// Its length, bytes.
    pub len: u64,
    /// Its CRC-32.
    pub crc: u32,
}

impl MapSource {
    /// Finds and loads the map: the recorded path, else the same path relative to the index's
    /// folder; an error when it is missing or changed since indexing (a stale index).
    pub fn load(&self, index: &Path) -> Result<OsmMap> {
        let beside = index
            .parent()
            .map(|p| p.join(self.path.file_name().unwrap_or_default()));
        let found = std::iter::once(self.path.clone())
            .chain(index.parent().map(|p| p.join(&self.path)))
            .chain(beside)
            .find(|p| p.is_file())
            .ok_or_else(|| {
                index_err(
                    index,
                    format!(
                        "its map {} is not found (looked at the recorded path and beside the index)",
                        self.path.display()
                    ),
                )
            })?;
        let bytes = std::fs::read(&found).map_err(|e| index_err(&found, e.to_string()))?;
        let crc = crc32fast::hash(&bytes);
        if bytes.len() as u64 != self.len || crc != self.crc {
            return Err(index_err(
                index,
                format!(
                    "stale: its map {} changed since the index was built ({} bytes, CRC {crc:#010x}; indexed {} bytes, CRC {:#010x}); rebuild it with `urbansem localize index`",
                    found.display(),
                    bytes.len(),
                    self.len,
                    self.crc
                ),
            ));
        }
        Ok(OsmMap::load(&found)?)
    }
}

/// The map of a `--map` argument: an OSM file, or an index (`.uloc`) with the map it was
/// built from.
pub fn load_map_or_index(path: &Path) -> Result<(OsmMap, Option<PreparedMap>)> {
    if is_index(path) {
        let (prepared, source) = PreparedMap::read(path)?;
        let map = source.load(path)?;
        return Ok((map, Some(prepared)));
    }
    let map = OsmMap::load(path).context_with(|| format!("loading the map {}", path.display()))?;
    Ok((map, None))
}

/// True when a `--map` path names an index rather than a map.
pub fn is_index(path: &Path) -> bool {
    path.extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("uloc"))
}

fn index_err(path: &Path, message: String) -> LocalizeError {
    LocalizeError::Index {
        path: path.to_path_buf(),
        message,
    }
}

fn encode_domain(e: &mut Enc<'_>, d: Domain) {
    for v in [d.i0, d.j0, d.i1, d.j1] {
        e.i64(v);
    }
}

pub(crate) fn decode_domain<R: Read>(d: &mut Dec<'_, R>) -> Result<Domain> {
    let v: [i64; 4] = d.i64s("domain")?;
    if v.iter().any(|x| x.unsigned_abs() > 1 << 40) || v[2] < v[0] || v[3] < v[1] {
        return Err(d.bad(format!("domain {v:?} is not a cell box")));
    }
    Ok(Domain {
        i0: v[0],
        j0: v[1],
        i1: v[2],
        j1: v[3],
    })
}

/// An index body being written: scalars and byte arrays in order.
#[derive(Default)]
pub(crate) struct Enc<'a> {
    small: Vec<u8>,
    /// (position in `small` before which the array comes, the array).
    parts: Vec<(usize, &'a [u8])>,
}

impl<'a> Enc<'a> {
    pub(crate) fn u8(&mut self, v: u8) {
        self.small.push(v);
    }
    pub(crate) fn u32(&mut self, v: u32) {
        self.small.extend_from_slice(&v.to_le_bytes());
    }
    pub(crate) fn u64(&mut self, v: u64) {
        self.small.extend_from_slice(&v.to_le_bytes());
    }
    pub(crate) fn i64(&mut self, v: i64) {
        self.small.extend_from_slice(&v.to_le_bytes());
    }
    pub(crate) fn f64(&mut self, v: f64) {
        self.small.extend_from_slice(&v.to_le_bytes());
    }
    fn str(&mut self, s: &str) {
        self.u64(s.len() as u64);
        self.small.extend_from_slice(s.as_bytes());
    }
    /// A length-prefixed byte array (borrowed until the body is written).
    pub(crate) fn bytes(&mut self, v: &'a [u8]) {
        self.u64(v.len() as u64);
        self.parts.push((self.small.len(), v));
    }
    fn len(&self) -> usize {
        self.small.len() + self.parts.iter().map(|(_, p)| p.len()).sum::<usize>()
    }
    fn pieces(&self) -> impl Iterator<Item = &[u8]> {
        let mut at = 0;
        let mut out = Vec::new();
        for (pos, part) in &self.parts {
            out.push(&self.small[at..*pos]);
            out.push(*part);
            at = *pos;
        }
        out.push(&self.small[at..]);
        out.into_iter()
    }
    fn crc(&self) -> u32 {
        let mut h = crc32fast::Hasher::new();
        for p in self.pieces() {
            h.update(p);
        }
        h.finalize()
    }
    fn write_to(&self, w: &mut impl Write) -> std::io::Result<()> {
        for p in self.pieces() {
            w.write_all(p)?;
        }
        Ok(())
    }
}

/// An index body being read: every read checked against the bytes left, checksummed.
pub(crate) struct Dec<'p, R: Read> {
    r: R,
    path: &'p Path,
    pos: u64,
    end: u64,
    crc: crc32fast::Hasher,
}

impl<R: Read> Dec<'_, R> {
    pub(crate) fn bad(&self, message: String) -> LocalizeError {
        index_err(self.path, format!("byte {}: {message}", self.pos))
    }
    fn fill(&mut self, buf: &mut [u8], what: &str) -> Result<()> {
        if (buf.len() as u64) > self.end - self.pos {
            return Err(self.bad(format!(
                "{what}: {} bytes needed, {} left: truncated or corrupt",
                buf.len(),
                self.end - self.pos
            )));
        }
        self.r
            .read_exact(buf)
            .map_err(|e| self.bad(format!("{what}: {e}")))?;
        self.crc.update(buf);
        self.pos += buf.len() as u64;
        Ok(())
    }
    fn arr<const N: usize>(&mut self, what: &str) -> Result<[u8; N]> {
        let mut b = [0u8; N];
        self.fill(&mut b, what)?;
        Ok(b)
    }
    pub(crate) fn u8(&mut self, what: &str) -> Result<u8> {
        Ok(self.arr::<1>(what)?[0])
    }
    pub(crate) fn u32(&mut self, what: &str) -> Result<u32> {
        Ok(u32::from_le_bytes(self.arr(what)?))
    }
    pub(crate) fn u64(&mut self, what: &str) -> Result<u64> {
        Ok(u64::from_le_bytes(self.arr(what)?))
    }
    pub(crate) fn i64(&mut self, what: &str) -> Result<i64> {
        Ok(i64::from_le_bytes(self.arr(what)?))
    }
    /// `N` consecutive i64 values.
    pub(crate) fn i64s<const N: usize>(&mut self, what: &str) -> Result<[i64; N]> {
        let mut out = [0i64; N];
        for v in &mut out {
            *v = self.i64(what)?;
        }
        Ok(out)
    }
    /// `N` consecutive finite f64 values.
    pub(crate) fn f64s<const N: usize>(&mut self, what: &str) -> Result<[f64; N]> {
        let mut out = [0f64; N];
        for v in &mut out {
            *v = self.f64(what)?;
        }
        Ok(out)
    }
    pub(crate) fn f64(&mut self, what: &str) -> Result<f64> {
        let v = f64::from_le_bytes(self.arr(what)?);
        if !v.is_finite() {
            return Err(self.bad(format!("{what} is {v}")));
        }
        Ok(v)
    }
    /// A size that must fit in memory and in the file (at least one byte per unit).
    pub(crate) fn usize(&mut self, what: &str) -> Result<usize> {
        let v = self.u64(what)?;
        if v > self.end - self.pos + (1 << 20) {
            return Err(self.bad(format!("{what} {v} is larger than the file")));
        }
        Ok(v as usize)
    }
    /// A count of items of `unit` bytes each that must fit in the bytes left.
    pub(crate) fn count(&mut self, unit: u64, what: &str) -> Result<usize> {
        let n = self.u64(what)?;
        if n.saturating_mul(unit) > self.end - self.pos {
            return Err(self.bad(format!(
                "{n} {what} of {unit} bytes do not fit in the {} bytes left",
                self.end - self.pos
            )));
        }
        Ok(n as usize)
    }
    /// A length-prefixed byte array of exactly `expected` bytes.
    pub(crate) fn bytes(&mut self, expected: usize, what: &str) -> Result<Vec<u8>> {
        let n = self.count(1, what)?;
        if n != expected {
            return Err(self.bad(format!("{what}: {n} bytes, its geometry needs {expected}")));
        }
        let mut v = vec![0u8; n];
        self.fill(&mut v, what)?;
        Ok(v)
    }
    fn string(&mut self, what: &str) -> Result<String> {
        let n = self.count(1, what)?;
        let mut v = vec![0u8; n];
        self.fill(&mut v, what)?;
        String::from_utf8(v).map_err(|_| self.bad(format!("{what} is not UTF-8")))
    }
}
