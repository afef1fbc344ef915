//! The map index (`.uloc`): what the search prepares once per map, saved to disk.
//!
//! Preparing a map (outline edges, the directional distance-transform tensor, its lower-bound
//! pyramid, the search domain and the feasible-pose mask) takes seconds on a city map; a
//! [`PreparedMap`] read from an index takes a fraction of that, and a [`Localizer`] built on
//! it searches exactly as one built from the map (tested: same ranked candidates).
//!
//! File layout, little-endian, version 2 (version 1 had no tensor offset):
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
use crate::codec::{close_body, index_err, open_body, write_file, Enc};
use crate::feasible::FeasibleMask;
use crate::{Result, Segment, WithContext};
use geodata::osm::OsmMap;
use std::io::{BufReader, Read};
use std::path::{Path, PathBuf};
use std::time::Instant;

/// The index file's magic bytes.
pub const MAGIC: &[u8; 8] = b"ULOCIDX\0";
/// The index format version this build reads and writes.
pub const VERSION: u32 = 2;

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
        let mut prepared = Self::on_tensor(map, edges, dt, chamfer, search, domain);
        prepared.seconds.edges = edges_s;
        prepared.seconds.distance_transform = dt_s;
        Ok(prepared)
    }

    /// Prepares the window `[offset, offset + size)` of the lattice anchored at `origin` for
    /// the map (crop) `map` with outline `edges`, searching `domain` (this tensor's cells):
    /// a map tile ([`crate::tiles`]).
    #[allow(clippy::too_many_arguments)]
    pub fn build_window(
        map: &OsmMap,
        edges: Vec<Segment>,
        chamfer: &ChamferOptions,
        search: &SearchOptions,
        origin: [f64; 2],
        offset: [i64; 2],
        size: [usize; 2],
        domain: Domain,
    ) -> Result<Self> {
        let t = Instant::now();
        let dt = DtTensor::build_window(&edges, chamfer, origin, offset, size)?;
        let dt_s = t.elapsed().as_secs_f64();
        let mut prepared = Self::on_tensor(map, edges, dt, chamfer, search, domain);
        prepared.seconds.distance_transform = dt_s;
        Ok(prepared)
    }

    /// The rest of a preparation once the tensor is built: its pyramid and the feasible
    /// mask of `domain` (the seconds of both recorded, the others zero).
    fn on_tensor(
        map: &OsmMap,
        edges: Vec<Segment>,
        dt: DtTensor,
        chamfer: &ChamferOptions,
        search: &SearchOptions,
        domain: Domain,
    ) -> PreparedMap {
        let t = Instant::now();
        let pyramid = BoundPyramid::build(&dt, search.levels);
        let pyr_s = t.elapsed().as_secs_f64();
        let t = Instant::now();
        let feasible = search.feasible_only.then(|| {
            FeasibleMask::build(map, &dt, domain, search.street_distance_m, pyramid.top())
        });
        PreparedMap {
            options: PrepOptions::of(chamfer, search),
            edges,
            dt,
            pyramid,
            domain,
            feasible,
            seconds: MapSeconds {
                edges: 0.0,
                distance_transform: 0.0,
                pyramid: pyr_s,
                feasible: t.elapsed().as_secs_f64(),
            },
        }
    }

    /// Memory of the tensor, pyramid and feasible mask, bytes.
    pub fn memory_bytes(&self) -> usize {
        self.dt.bytes() + self.pyramid.bytes() + self.feasible.as_ref().map_or(0, |f| f.bytes())
    }

    /// Writes the index of this prepared map of the map file `source` (atomically).
    pub fn write(&self, path: &Path, source: &Path) -> Result<()> {
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
        self.domain.encode(&mut body);
        match &self.feasible {
            None => body.u8(0),
            Some(f) => {
                body.u8(1);
                f.encode(&mut body);
            }
        }
        write_file(path, MAGIC, VERSION, &body)
    }

    /// Reads an index; returns it with the source map it was built from.
    pub fn read(path: &Path) -> Result<(PreparedMap, MapSource)> {
        let file = std::fs::File::open(path).map_err(|e| index_err(path, e.to_string()))?;
        let file_len = file
            .metadata()
            .map_err(|e| index_err(path, e.to_string()))?
            .len();
        Self::read_from(BufReader::with_capacity(1 << 20, file), file_len, path)
    }

    /// Reads an index from a reader of `file_len` bytes (`path` names it in errors).
    pub fn read_from<R: Read>(
        r: R,
        file_len: u64,
        path: &Path,
    ) -> Result<(PreparedMap, MapSource)> {
        let (mut d, stored_crc) = open_body(
            r,
            file_len,
            path,
            MAGIC,
            VERSION,
            "a urbansem map index (build one with `urbansem localize index --map MAP --out FILE.uloc`)",
        )?;
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
        let domain = Domain::decode(&mut d)?;
        let feasible = match d.u8("feasible mask flag")? {
            0 => None,
            1 => Some(FeasibleMask::decode(&mut d)?),
            v => return Err(d.bad(format!("feasible mask flag {v}, expected 0 or 1"))),
        };
        close_body(d, stored_crc)?;
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
        if found
            .extension()
            .is_some_and(|e| e.eq_ignore_ascii_case("umap"))
        {
            return crate::crop::read_crop(&found);
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
