//! Tiled maps: a map cut into square tiles, one index per tile holding the buildings and
//! streets around it, searched together exactly as the whole map would be searched.
//!
//! `localize index --map BIG --tile-m 1000 --overlap-m 100 --out DIR` writes
//! `DIR/manifest.json` and per tile `DIR/tiles/c{col}_r{row}.uloc` (an ordinary map index,
//! [`crate::index`]) with its map crop `….umap` (the buildings and streets near the tile, in
//! the whole map's frame; format below).
//!
//! **Why tiled equals untiled.** Every tile's tensor is a window of the lattice the whole map's
//! tensor would have (same anchor, same cells; [`DtTensor::build_window`]), so a tile's cells
//! hold the whole tensor's values bit for bit, given the edges within τ of the window. A tile
//! owns the poses of its *core* (a square of `tile_m`, the cores partition the whole map's
//! pose domain) and its window reaches `overlap_m` beyond the core. Its search returns every
//! pose of its core within the factor of *its own* minimum — a superset of the poses within
//! the factor of the whole map's minimum, since its minimum is no smaller. The union over
//! tiles, cut at the factor times the least minimum and sorted, is the whole map's raw pose
//! list; suppression, the filters, costs, refinement and ranking then run once on it
//! ([`crate::pipeline`]), each candidate seeing the buildings, streets and edges of the tile
//! that owns it. This holds when a scan's samples lie within `overlap_m` of its pose and the
//! visibility range (plus refinement's reach) within `overlap_m` too; [`TiledLocalization`]
//! says whether they did (`exact`). `crates/localize/tests/tiles.rs` checks the ranked
//! candidates against the untiled map's, bit for bit.
//!
//! A crop with no street where the whole map has streets keeps one street of the whole map
//! (a "witness" farther than every feasible distance), so that the street filter stays on as
//! on the whole map without changing any answer.
//!
//! The crop files' format is in [`crate::crop`].

use crate::candidates::{
    limit_of, sample_segment_points, search_capped, Cap, Masks, RawPose, SearchStats,
};
use crate::chamfer::{bounding_box, map_edges, DtTensor};
use crate::codec::index_err;
pub use crate::crop::{read_crop, read_crop_from, write_crop};
use crate::heading::HeadingCache;
use crate::index::{PrepOptions, PreparedMap};
use crate::pipeline::{
    finish, heading_mask, templates_on, Localization, LocalizeOptions, Place, Scan, ScanSegments,
};
use crate::visibility::EdgeGrid;
use crate::{LocalizeError, Result, Segment, WithContext};
use geodata::osm::geometry::ring_bounds;
use geodata::osm::index::MapIndex;
use geodata::osm::model::{Building, StreetSegment};
use geodata::osm::OsmMap;
use geodata::projection::LocalFrame;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use std::path::{Path, PathBuf};
use std::time::Instant;

/// The manifest's `format` value.
pub const MANIFEST_FORMAT: &str = "urbansem-localize-tiles";
/// The manifest version this build reads and writes.
pub const MANIFEST_VERSION: u32 = 1;

/// How a map is cut into tiles.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TileOptions {
    /// Side of a tile's core, metres (a whole number of tensor cells).
    pub tile_m: f64,
    /// How far a tile's tensor and crop reach beyond its core, metres.
    pub overlap_m: f64,
}

impl Default for TileOptions {
    fn default() -> Self {
        TileOptions {
            tile_m: 1000.0,
            overlap_m: 100.0,
        }
    }
}

/// A file the manifest refers to, with its size and checksum.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct FileRef {
    /// Path, relative to the manifest's folder (the source map: as given).
    pub path: String,
    /// Size, bytes.
    pub bytes: u64,
    /// CRC-32 (IEEE) of the content.
    pub crc32: u32,
}

impl FileRef {
    /// The reference of the file at `path` (named `name` in the manifest).
    pub fn of(path: &Path, name: &str) -> Result<FileRef> {
        let bytes = std::fs::read(path).map_err(|e| index_err(path, e.to_string()))?;
        Ok(FileRef {
            path: name.to_owned(),
            bytes: bytes.len() as u64,
            crc32: crc32fast::hash(&bytes),
        })
    }
}

/// One tile of a manifest.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TileEntry {
    /// Column and row of the tile.
    pub key: [i64; 2],
    /// The core's poses in lattice cells: `[i0, j0, i1, j1)`.
    pub core: [i64; 4],
    /// The core in metres, map frame: `[min_x, min_y, max_x, max_y]`.
    pub core_m: [f64; 4],
    /// The core in WGS84: `[min_lon, min_lat, max_lon, max_lat]`.
    pub core_lonlat: [f64; 4],
    /// The tile's index (`.uloc`).
    pub index: FileRef,
    /// The tile's map crop (`.umap`).
    pub crop: FileRef,
    /// Buildings in the crop.
    pub buildings: usize,
    /// Outline edges in the crop.
    pub edges: usize,
    /// Feasible poses of the core.
    pub feasible_cells: u64,
    /// Memory of the tile's tensor, pyramid and mask, bytes (what a search holds per tile).
    pub memory_bytes: u64,
}

/// The manifest of a tiled map (`manifest.json`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Manifest {
    /// Always [`MANIFEST_FORMAT`].
    pub format: String,
    /// Always [`MANIFEST_VERSION`].
    pub version: u32,
    /// The map that was tiled.
    pub map: FileRef,
    /// The map frame's origin (latitude, longitude), degrees.
    pub frame_origin: [f64; 2],
    /// Side of a tile's core, metres.
    pub tile_m: f64,
    /// Reach of a tile beyond its core, metres.
    pub overlap_m: f64,
    /// Tensor cell, metres.
    pub grid_m: f64,
    /// The lattice's anchor (corner of lattice cell (0, 0)), metres, map frame.
    pub lattice_origin: [f64; 2],
    /// The whole map's pose domain in lattice cells `[i0, j0, i1, j1)`.
    pub domain: [i64; 4],
    /// Tensor orientation channels.
    pub channels: usize,
    /// Tensor units per metre.
    pub units_per_m: f64,
    /// λ, metres per radian.
    pub lambda_m_per_rad: f64,
    /// Pyramid levels.
    pub levels: u32,
    /// Buildings of the whole map.
    pub buildings: usize,
    /// Whether the whole map has street segments.
    pub has_streets: bool,
    /// The tiles (only those with a feasible pose in their core), by row then column.
    pub tiles: Vec<TileEntry>,
}

/// What `localize index --tile-m` wrote.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct TilesReport {
    /// The manifest file.
    pub manifest: PathBuf,
    /// The map that was tiled.
    pub map: PathBuf,
    /// Tiles written.
    pub tiles: usize,
    /// Tiles of the grid left out (no feasible pose in their core).
    pub empty_tiles: usize,
    /// Bytes of all tile indexes and crops.
    pub bytes: u64,
    /// The largest tile's tensor, pyramid and mask, bytes.
    pub max_tile_memory_bytes: u64,
    /// Seconds: loading the map, building and writing the tiles.
    pub seconds: TilesSeconds,
}

/// Seconds of `localize index --tile-m`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct TilesSeconds {
    /// Reading the map.
    pub load_map: f64,
    /// Preparing and writing every tile.
    pub tiles: f64,
}

impl TilesReport {
    /// The one-line summary the command line prints.
    pub fn text(&self) -> String {
        format!(
            "{}: {} tiles ({} empty left out), {:.1} MB; largest tile holds {:.1} MB in memory; map read in {:.2} s, tiles built in {:.2} s\n",
            self.manifest.display(),
            self.tiles,
            self.empty_tiles,
            self.bytes as f64 / 1e6,
            self.max_tile_memory_bytes as f64 / 1e6,
            self.seconds.load_map,
            self.seconds.tiles
        )
    }
}

/// True when a `--map` path names a tile manifest (a `.json` file).
pub fn is_manifest(path: &Path) -> bool {
    path.extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("json"))
}

fn crop_box(map: &OsmMap, lo: [f64; 2], hi: [f64; 2]) -> OsmMap {
    let meets =
        |a: [f64; 2], b: [f64; 2]| a[0] <= hi[0] && b[0] >= lo[0] && a[1] <= hi[1] && b[1] >= lo[1];
    let buildings: Vec<Building> = map
        .buildings
        .iter()
        .filter(|b| {
            let (a, c) = ring_bounds(&b.outer);
            meets(a, c)
        })
        .cloned()
        .collect();
    let mut segments: Vec<StreetSegment> = map
        .streets
        .segments
        .iter()
        .filter(|s| {
            meets(
                [s.a[0].min(s.b[0]), s.a[1].min(s.b[1])],
                [s.a[0].max(s.b[0]), s.a[1].max(s.b[1])],
            )
        })
        .cloned()
        .collect();
    if segments.is_empty() {
        // The witness: keeps the street filter on, farther than any feasible distance.
        segments.extend(map.streets.segments.iter().take(1).cloned());
    }
    crate::crop::crop_map(map.frame, map.bbox_lonlat, buildings, segments)
}

/// Cuts the map of `map_path` into tiles and writes their indexes, crops and the manifest
/// to `out_dir`, with the localizer's preparation `options`.
pub fn build_tiles(
    map_path: &Path,
    out_dir: &Path,
    tiles: TileOptions,
    options: &LocalizeOptions,
) -> Result<TilesReport> {
    let t = Instant::now();
    let map = OsmMap::load(map_path)
        .context_with(|| format!("loading the map {}", map_path.display()))?;
    let load_s = t.elapsed().as_secs_f64();
    let t = Instant::now();
    let (ch, se) = (&options.chamfer, &options.search);
    let g = ch.grid_m;
    let per_tile = (tiles.tile_m / g).round();
    if !(per_tile >= 1.0 && (per_tile * g - tiles.tile_m).abs() < 1e-9 * tiles.tile_m.max(1.0)) {
        return Err(LocalizeError::InvalidOption {
            name: "tile_m",
            value: tiles.tile_m,
            expected: "a positive whole number of tensor cells (a multiple of --grid-m)",
        });
    }
    if !(tiles.overlap_m.is_finite() && tiles.overlap_m >= 0.0) {
        return Err(LocalizeError::InvalidOption {
            name: "overlap_m",
            value: tiles.overlap_m,
            expected: "a finite number ≥ 0",
        });
    }
    let per_tile = per_tile as i64;
    let ov = (tiles.overlap_m / g).ceil() as i64;
    let edges = map_edges(&map);
    let Some((min, max)) = bounding_box(&edges) else {
        return Err(LocalizeError::Index {
            path: map_path.to_path_buf(),
            message: "the map has no building outlines; nothing to tile".into(),
        });
    };
    // The anchor and domain of the whole map's tensor (as DtTensor::build and
    // PreparedMap::build would make them).
    let tau = ch.truncation_m;
    let origin = [min[0] - tau - g, min[1] - tau - g];
    let cell = |v: f64, k: usize| ((v - origin[k]) / g).floor() as i64;
    let m = se.pose_margin_m;
    let domain = [
        cell(min[0] - m, 0),
        cell(min[1] - m, 1),
        cell(max[0] + m, 0) + 1,
        cell(max[1] + m, 1) + 1,
    ];
    let cols = (domain[2] - domain[0] + per_tile - 1) / per_tile;
    let rows = (domain[3] - domain[1] + per_tile - 1) / per_tile;
    std::fs::create_dir_all(out_dir.join("tiles"))
        .map_err(|e| index_err(out_dir, format!("creating the folder: {e}")))?;
    let reach = tau.max(se.street_distance_m) + 2.0 * g;
    let mut entries = Vec::new();
    let mut empty = 0;
    let mut bytes = 0;
    for row in 0..rows {
        for col in 0..cols {
            let core = [
                domain[0] + col * per_tile,
                domain[1] + row * per_tile,
                (domain[0] + (col + 1) * per_tile).min(domain[2]),
                (domain[1] + (row + 1) * per_tile).min(domain[3]),
            ];
            let offset = [core[0] - ov, core[1] - ov];
            let size = [
                (core[2] - core[0] + 2 * ov) as usize,
                (core[3] - core[1] + 2 * ov) as usize,
            ];
            let at = |i: i64, k: usize| origin[k] + i as f64 * g;
            let lo = [at(offset[0], 0) - reach, at(offset[1], 1) - reach];
            let hi = [
                at(offset[0] + size[0] as i64, 0) + reach,
                at(offset[1] + size[1] as i64, 1) + reach,
            ];
            let crop = crop_box(&map, lo, hi);
            let crop_edges = map_edges(&crop);
            if crop_edges.is_empty() {
                empty += 1;
                continue;
            }
            let local = crate::candidates::Domain {
                i0: core[0] - offset[0],
                j0: core[1] - offset[1],
                i1: core[2] - offset[0],
                j1: core[3] - offset[1],
            };
            let prepared =
                PreparedMap::build_window(&crop, crop_edges, ch, se, origin, offset, size, local)
                    .context_with(|| format!("preparing tile {col},{row}"))?;
            let feasible_cells = prepared
                .feasible
                .as_ref()
                .map_or(local.cells(), |f| f.feasible_cells);
            if feasible_cells == 0 {
                empty += 1;
                continue;
            }
            let name = format!("tiles/c{col}_r{row}");
            let crop_path = out_dir.join(format!("{name}.umap"));
            let index_path = out_dir.join(format!("{name}.uloc"));
            write_crop(&crop, &crop_path)?;
            prepared.write(&index_path, &crop_path)?;
            let crop_ref = FileRef::of(&crop_path, &format!("{name}.umap"))?;
            let index_ref = FileRef::of(&index_path, &format!("{name}.uloc"))?;
            bytes += crop_ref.bytes + index_ref.bytes;
            let core_m = [
                at(core[0], 0),
                at(core[1], 1),
                at(core[2], 0),
                at(core[3], 1),
            ];
            let (lat0, lon0) = map.frame.to_wgs84([core_m[0], core_m[1]]);
            let (lat1, lon1) = map.frame.to_wgs84([core_m[2], core_m[3]]);
            entries.push(TileEntry {
                key: [col, row],
                core,
                core_m,
                core_lonlat: [lon0, lat0, lon1, lat1],
                index: index_ref,
                crop: crop_ref,
                buildings: crop.buildings.len(),
                edges: prepared.edges.len(),
                feasible_cells,
                memory_bytes: prepared.memory_bytes() as u64,
            });
        }
    }
    let (lat, lon) = map.frame.origin();
    let manifest = Manifest {
        format: MANIFEST_FORMAT.into(),
        version: MANIFEST_VERSION,
        map: FileRef::of(map_path, &map_path.to_string_lossy())?,
        frame_origin: [lat, lon],
        tile_m: tiles.tile_m,
        overlap_m: tiles.overlap_m,
        grid_m: g,
        lattice_origin: origin,
        domain,
        channels: ch.channels,
        units_per_m: 255.0 / tau,
        lambda_m_per_rad: ch.lambda_m_per_rad,
        levels: se.levels,
        buildings: map.buildings.len(),
        has_streets: !map.streets.segments.is_empty(),
        tiles: entries,
    };
    let manifest_path = out_dir.join("manifest.json");
    let json = serde_json::to_vec_pretty(&manifest)
        .map_err(|e| index_err(&manifest_path, e.to_string()))?;
    geodata::fsio::write_atomic(&manifest_path, json)
        .map_err(|e| index_err(&manifest_path, format!("writing: {e}")))?;
    Ok(TilesReport {
        manifest: manifest_path,
        map: map_path.to_path_buf(),
        tiles: manifest.tiles.len(),
        empty_tiles: empty,
        bytes,
        max_tile_memory_bytes: manifest
            .tiles
            .iter()
            .map(|t| t.memory_bytes)
            .max()
            .unwrap_or(0),
        seconds: TilesSeconds {
            load_map: load_s,
            tiles: t.elapsed().as_secs_f64(),
        },
    })
}

impl Manifest {
    /// Reads and checks a manifest.
    pub fn read(path: &Path) -> Result<Manifest> {
        let bytes = std::fs::read(path).map_err(|e| index_err(path, e.to_string()))?;
        let m: Manifest = serde_json::from_slice(&bytes).map_err(|e| {
            index_err(
                path,
                format!(
                    "not a tile manifest (line {}, column {}: {e}); write one with `urbansem localize index --map M --tile-m 1000 --out DIR`",
                    e.line(),
                    e.column()
                ),
            )
        })?;
        if m.format != MANIFEST_FORMAT || m.version != MANIFEST_VERSION {
            return Err(index_err(
                path,
                format!(
                    "format {:?} version {}; this build reads {MANIFEST_FORMAT:?} version {MANIFEST_VERSION}",
                    m.format, m.version
                ),
            ));
        }
        let ok = m.grid_m > 0.0
            && m.grid_m.is_finite()
            && m.units_per_m > 0.0
            && (1..=255).contains(&m.channels)
            && m.levels <= 30
            && m.tiles
                .iter()
                .all(|t| t.core[0] <= t.core[2] && t.core[1] <= t.core[3]);
        if !ok {
            return Err(index_err(
                path,
                "grid, units, channels, levels or a tile's core out of range".into(),
            ));
        }
        Ok(m)
    }

    /// The lattice of the whole map (a tensor geometry without cells).
    pub fn lattice(&self) -> DtTensor {
        DtTensor::lattice(
            self.lattice_origin,
            self.grid_m,
            self.channels,
            self.units_per_m,
            self.lambda_m_per_rad,
        )
    }

    /// The frame of the map.
    pub fn frame(&self, path: &Path) -> Result<LocalFrame> {
        LocalFrame::new(self.frame_origin[0], self.frame_origin[1])
            .map_err(|e| index_err(path, format!("frame origin: {e}")))
    }

    /// The tiles whose core meets the disc of `radius_m` around `center` (map frame).
    pub fn tiles_near(&self, center: [f64; 2], radius_m: f64) -> Vec<usize> {
        self.tiles
            .iter()
            .enumerate()
            .filter(|(_, t)| {
                let c = t.core_m;
                let dx = (c[0] - center[0]).max(center[0] - c[2]).max(0.0);
                let dy = (c[1] - center[1]).max(center[1] - c[3]).max(0.0);
                dx * dx + dy * dy <= radius_m * radius_m
            })
            .map(|(i, _)| i)
            .collect()
    }

    /// The tile owning a position (map frame), if any.
    pub fn owner(&self, p: [f64; 2]) -> Option<usize> {
        // The cell whose centre is nearest (robust to rounding of a cell's corner).
        let g = self.grid_m;
        let i = ((p[0] - self.lattice_origin[0]) / g + 0.5).floor() as i64;
        let j = ((p[1] - self.lattice_origin[1]) / g + 0.5).floor() as i64;
        let found = self
            .tiles
            .iter()
            .position(|t| t.core[0] <= i && i < t.core[2] && t.core[1] <= j && j < t.core[3]);
        found.or_else(|| {
            // Outside every core (a refined pose near the domain's edge): the nearest core.
            let d = |t: &TileEntry| {
                let c = t.core_m;
                let dx = (c[0] - p[0]).max(p[0] - c[2]).max(0.0);
                let dy = (c[1] - p[1]).max(p[1] - c[3]).max(0.0);
                dx * dx + dy * dy
            };
            (0..self.tiles.len()).min_by(|&a, &b| d(&self.tiles[a]).total_cmp(&d(&self.tiles[b])))
        })
    }
}

/// Path of a file named in the manifest at `manifest_path`.
pub fn resolve(manifest_path: &Path, file: &FileRef) -> PathBuf {
    manifest_path
        .parent()
        .unwrap_or(Path::new("."))
        .join(&file.path)
}

/// One tile loaded for searching: its crop and prepared map.
pub struct LoadedTile {
    /// The tile's crop of the map.
    pub crop: OsmMap,
    /// Its prepared map.
    pub prepared: PreparedMap,
    /// Its heading mask for cars' scans, built on first use.
    heading: HeadingCache,
}

impl LoadedTile {
    /// Reads tile `i` of the manifest at `manifest_path` (index and crop, both checked).
    pub fn read(manifest_path: &Path, manifest: &Manifest, i: usize) -> Result<LoadedTile> {
        let entry = manifest.tiles.get(i).ok_or_else(|| {
            index_err(
                manifest_path,
                format!("no tile {i} (the manifest has {})", manifest.tiles.len()),
            )
        })?;
        let (prepared, source) = PreparedMap::read(&resolve(manifest_path, &entry.index))?;
        let crop = source.load(&resolve(manifest_path, &entry.index))?;
        Ok(LoadedTile {
            crop,
            prepared,
            heading: HeadingCache::default(),
        })
    }

    /// Decodes a tile from the bytes of its index and crop files (e.g. from a distributed
    /// object store); `name` names it in errors.
    pub fn from_bytes(index: &[u8], crop: &[u8], name: &Path) -> Result<LoadedTile> {
        let prepared = PreparedMap::read_from(index, index.len() as u64, name)?.0;
        let crop = read_crop_from(crop, crop.len() as u64, name)?;
        Ok(LoadedTile {
            crop,
            prepared,
            heading: HeadingCache::default(),
        })
    }
}

/// One tile's search for one scan: its raw poses in lattice cells.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TileSearch {
    /// The tile's position in the manifest.
    pub tile: usize,
    /// Every pose of the tile's core within the factor of the tile's minimum, as
    /// `[cost, yaw index, i, j]` in lattice cells, sorted.
    pub raw: Vec<[i64; 4]>,
    /// Boxes and leaves the search bounded.
    pub boxes: u64,
    /// Full-resolution poses evaluated.
    pub leaves: u64,
    /// Poses in the tile's exhaustive search space.
    pub space: u64,
    /// Seconds of the search (not serialized: result files are byte-identical across runs).
    #[serde(skip)]
    pub seconds: f64,
    /// The tile's minimum cost when it is within the cap.
    pub minimum: Option<u64>,
}

/// Searches one loaded tile for the scan `segments` under `cap`: with
/// `cap.minimum_only` the tile's minimum (if ≤ `cap.cost`), else every pose of its core within
/// min(factor × its minimum, `cap.cost`), the first `max_raw_poses` of them (the options set
/// `cap.count`).
pub fn search_tile(
    tile: &LoadedTile,
    index: usize,
    segments: &[Segment],
    along_streets: bool,
    options: &LocalizeOptions,
    cap: Cap,
) -> Result<TileSearch> {
    let t = Instant::now();
    let p = &tile.prepared;
    let wanted = PrepOptions::of(&options.chamfer, &options.search);
    let differ = p.options.differences(&wanted);
    if !differ.is_empty() {
        return Err(LocalizeError::PrepMismatch {
            differences: differ.join("; "),
        });
    }
    let templates = templates_on(segments, &p.dt, p.pyramid.top(), options);
    let cap = Cap {
        count: options.search.max_raw_poses,
        ..cap
    };
    // A pose's heading flag needs the streets within the street distance plus two
    // half-diagonals of a base box (≈ 5 m at 0.5 m cells) of it; the crop holds those within
    // the overlap plus the street distance of the core, so the flags are the whole map's
    // whenever the tile is exact (`is_exact`: the overlap exceeds the visibility range).
    let heading = along_streets
        .then(|| {
            heading_mask(
                &tile.heading,
                &tile.crop.streets.segments,
                &p.dt,
                p.domain,
                &templates,
                &options.search,
                p.pyramid.top(),
            )
        })
        .flatten();
    let (raw, stats, minimum) = search_capped(
        &p.dt,
        &p.pyramid,
        &templates,
        p.domain,
        Masks {
            feasible: p.feasible.as_ref(),
            heading: heading.as_deref(),
        },
        options.search.keep_factor,
        cap,
    );
    let [oi, oj] = p.dt.offset;
    Ok(TileSearch {
        tile: index,
        raw: raw
            .iter()
            .map(|r| [r.cost as i64, r.yaw_index as i64, r.i + oi, r.j + oj])
            .collect(),
        boxes: stats.boxes,
        leaves: stats.leaves,
        space: stats.space,
        seconds: t.elapsed().as_secs_f64(),
        minimum,
    })
}

/// The map around a tile for the finishing stages.
pub struct TilePlace<'m> {
    map: &'m OsmMap,
    edges: Vec<Segment>,
    grid: EdgeGrid,
    index: MapIndex<'m>,
}

impl<'m> TilePlace<'m> {
    /// The place of a tile's crop.
    pub fn new(crop: &'m OsmMap) -> TilePlace<'m> {
        let edges = map_edges(crop);
        TilePlace {
            map: crop,
            grid: EdgeGrid::new(&edges, 25.0),
            edges,
            index: MapIndex::new(crop),
        }
    }
}

impl Place for TilePlace<'_> {
    fn map_index(&self) -> &MapIndex<'_> {
        &self.index
    }
    fn has_streets(&self) -> bool {
        !self.map.streets.segments.is_empty()
    }
    fn edges(&self) -> (&[Segment], &EdgeGrid) {
        (&self.edges, &self.grid)
    }
}

/// The merge of tile searches for one scan: the raw poses of the whole map.
pub fn merge_raw(
    searches: &[TileSearch],
    options: &LocalizeOptions,
) -> (Vec<RawPose>, SearchStats) {
    let mut stats = SearchStats::default();
    for s in searches {
        stats.boxes += s.boxes;
        stats.leaves += s.leaves;
        stats.space += s.space;
    }
    let minimum = searches
        .iter()
        .filter_map(|s| s.raw.first().map(|r| r[0]))
        .min();
    let Some(minimum) = minimum else {
        return (Vec::new(), stats);
    };
    let limit = limit_of(minimum as u64, options.search.keep_factor);
    let mut raw: Vec<RawPose> = searches
        .iter()
        .flat_map(|s| s.raw.iter())
        .filter(|r| r[0] as u64 <= limit)
        .map(|r| RawPose {
            cost: r[0] as u64,
            yaw_index: r[1] as usize,
            i: r[2],
            j: r[3],
        })
        .collect();
    raw.sort_unstable();
    (raw, stats)
}

/// The finishing stages on the merged raw poses of one scan: `places[k]` is the place of
/// manifest tile `k` (only the tiles owning a candidate are asked for).
pub fn finish_tiled<'p>(
    manifest: &Manifest,
    searches: &[TileSearch],
    segments: &[Segment],
    along_streets: bool,
    options: &LocalizeOptions,
    place_of: &(dyn Sync + Fn(usize) -> &'p dyn Place),
) -> Localization {
    let mut out = Localization::empty(options.rank_by);
    out.segments = segments.to_vec();
    if segments.is_empty() {
        out.message = Some("the scan has no segments; nothing to match".into());
        return out;
    }
    let lattice = manifest.lattice();
    let t = Instant::now();
    let templates = templates_on(segments, &lattice, manifest.levels, options);
    out.seconds.templates = t.elapsed().as_secs_f64();
    out.seconds.search = searches.iter().map(|s| s.seconds).sum();
    let (raw, stats) = merge_raw(searches, options);
    out.search = stats;
    let fallback = |p: [f64; 2]| manifest.owner(p).unwrap_or(0);
    let place = |p: [f64; 2]| place_of(fallback(p));
    finish(
        &mut out,
        options,
        Scan {
            segments,
            views: &[[0.0, 0.0]],
            templates: &templates,
            along_streets,
        },
        raw,
        &lattice,
        &place,
    );
    out
}

/// Which tiles of a manifest own the candidates-to-be of merged searches (the tiles whose
/// crops the finishing stages need).
pub fn owners(
    manifest: &Manifest,
    searches: &[TileSearch],
    options: &LocalizeOptions,
) -> Vec<usize> {
    let (raw, _) = merge_raw(searches, options);
    let lattice = manifest.lattice();
    let mut out: Vec<usize> = raw
        .iter()
        .filter_map(|r| manifest.owner(lattice.corner_of(r.i, r.j)))
        .collect();
    out.sort_unstable();
    out.dedup();
    out
}

/// The crops of every tile owning a candidate of some scan's merged searches (`per_scan`),
/// each read once, by tile; tile 0's when none does (the map's frame), so never empty. A
/// manifest that lists no tile is an error.
pub fn owner_crops<'a>(
    manifest_path: &Path,
    manifest: &Manifest,
    per_scan: impl IntoIterator<Item = &'a [TileSearch]>,
    options: &LocalizeOptions,
) -> Result<Vec<(usize, OsmMap)>> {
    let mut needed: Vec<usize> = per_scan
        .into_iter()
        .flat_map(|s| owners(manifest, s, options))
        .collect();
    if needed.is_empty() {
        if manifest.tiles.is_empty() {
            return Err(index_err(
                manifest_path,
                "the manifest lists no tile".into(),
            ));
        }
        needed.push(0);
    }
    needed.sort_unstable();
    needed.dedup();
    needed
        .into_iter()
        .map(|k| {
            Ok((
                k,
                read_crop(&resolve(manifest_path, &manifest.tiles[k].crop))?,
            ))
        })
        .collect()
}

/// The place of tile `k` among the places of [`owner_crops`] (the first one when `k` owns no
/// candidate).
pub fn place_in<'p>(places: &'p [(usize, TilePlace<'p>)], k: usize) -> &'p dyn Place {
    match places.iter().find(|(j, _)| *j == k) {
        Some((_, p)) => p,
        None => &places[0].1,
    }
}

/// One scan localized on a tiled map.
pub struct TiledLocalization {
    /// The result, as on the whole map.
    pub result: Localization,
    /// Tiles searched.
    pub tiles_searched: usize,
    /// Whether tiled equals untiled for this scan: its samples and the visibility range
    /// (plus refinement's reach) lie within the overlap.
    pub exact: bool,
    /// The largest memory a tile held (tensor, pyramid, mask), bytes.
    pub max_tile_memory_bytes: u64,
    /// Seconds loading tiles.
    pub load_seconds: f64,
    /// The crop of the first tile (its frame is the map's).
    pub frame_map: OsmMap,
}

/// How far a scan's samples reach from its pose, metres.
pub fn scan_reach_m(segments: &[Segment]) -> f64 {
    segments
        .iter()
        .flat_map(|s| [s.a, s.b])
        .map(|p| p[0].hypot(p[1]))
        .fold(0.0, f64::max)
}

/// Whether a scan reaching `reach_m` is localized on tiles exactly as on the whole map.
pub fn is_exact(manifest: &Manifest, reach_m: f64, options: &LocalizeOptions) -> bool {
    let slack = 2.0 * manifest.grid_m + options.refine.max_shift_m;
    reach_m + manifest.grid_m <= manifest.overlap_m
        && options.visibility.range_m + slack <= manifest.overlap_m
}

/// The caps of the capped `minimum` rounds by default, as d_DCM in metres.
pub const MINIMUM_CAPS_M: [f64; 3] = [0.4, 0.55, 0.8];

/// The cost cap of a `minimum` round of `d_m` metres (d_DCM) for scan `segments` on the
/// lattice of `manifest`.
pub fn round_cap(manifest: &Manifest, segments: &[Segment], d_m: f64) -> u64 {
    let n = sample_segment_points(segments, manifest.grid_m).len();
    (d_m * manifest.units_per_m * n as f64).floor() as u64
}

/// Where a batch on a tiled map is: after each tile of each round.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BatchStep<'a> {
    /// The round: `minimum-{cap}m`, `minimum` or `poses`.
    pub round: &'a str,
    /// Tiles of the round done.
    pub tiles_done: usize,
    /// Tiles of the round.
    pub tiles: usize,
    /// Scans the round searches.
    pub scans: usize,
}

/// Scans localized together on a tiled map ([`localize_tiled_batch`]).
pub struct TiledBatch {
    /// One result per scan, as on the whole map.
    pub results: Vec<Localization>,
    /// Per scan: whether tiled equals untiled for it (see [`is_exact`]).
    pub exact: Vec<bool>,
    /// Tiles searched per round.
    pub tiles_searched: usize,
    /// Tile loads over all rounds.
    pub tile_loads: usize,
    /// The largest memory a tile held (tensor, pyramid, mask), bytes.
    pub max_tile_memory_bytes: u64,
    /// Seconds loading tiles and crops.
    pub load_seconds: f64,
    /// The crop of the first tile owning a candidate (its frame is the map's).
    pub frame_map: OsmMap,
}

/// Localizes several scans (their segments) on the tiled map of `manifest_path`, every tile
/// (or those of `only`) read once per round: `minimum` rounds under the caps `caps_m`
/// (d_DCM, increasing) and a last one uncapped, each only for the scans no earlier round
/// found a pose for and each tile's search capped by the least cost found so far; then every
/// tile's poses within the factor of each scan's least cost; the finishing stages once per
/// scan. The answer does not depend on the caps (they change the time only), and is the
/// whole map's, scan by scan.
pub fn localize_tiled_batch(
    manifest_path: &Path,
    scans: &[Vec<Segment>],
    along_streets: &[bool],
    options: &LocalizeOptions,
    caps_m: &[f64],
    only: Option<&[usize]>,
    progress: &mut dyn FnMut(BatchStep<'_>),
) -> Result<TiledBatch> {
    let bad = caps_m
        .iter()
        .enumerate()
        .find(|&(i, &d)| !(d.is_finite() && d > 0.0) || (i > 0 && caps_m[i - 1] >= d));
    if let Some((_, &value)) = bad {
        return Err(LocalizeError::InvalidOption {
            name: "minimum caps",
            value,
            expected: "increasing positive d_DCM values in metres",
        });
    }
    if along_streets.len() != scans.len() {
        return Err(LocalizeError::InvalidOption {
            name: "along streets",
            value: along_streets.len() as f64,
            expected: "one flag per scan",
        });
    }
    let manifest = Manifest::read(manifest_path)?;
    let all: Vec<usize> = (0..manifest.tiles.len()).collect();
    let which = only.unwrap_or(&all);
    let n = scans.len();
    let mut best: Vec<Option<u64>> = vec![None; n];
    let mut search_s = vec![0.0; n];
    let mut stats = vec![SearchStats::default(); n];
    let mut load_s = 0.0;
    let mut max_mem = 0u64;
    let mut loads = 0usize;
    let mut load = |k: usize| -> Result<LoadedTile> {
        let t = Instant::now();
        let tile = LoadedTile::read(manifest_path, &manifest, k)?;
        load_s += t.elapsed().as_secs_f64();
        max_mem = max_mem.max(tile.prepared.memory_bytes() as u64);
        loads += 1;
        Ok(tile)
    };
    for round in 0..=caps_m.len() {
        let open: Vec<usize> = (0..n)
            .filter(|&s| best[s].is_none() && !scans[s].is_empty())
            .collect();
        if open.is_empty() {
            break;
        }
        let name = caps_m
            .get(round)
            .map_or_else(|| "minimum".to_owned(), |d| format!("minimum-{d}m"));
        let round_caps: Vec<u64> = open
            .iter()
            .map(|&s| {
                caps_m
                    .get(round)
                    .map_or(u64::MAX, |&d| round_cap(&manifest, &scans[s], d))
            })
            .collect();
        let mut found: Vec<Option<u64>> = vec![None; open.len()];
        for (done, &k) in which.iter().enumerate() {
            let tile = load(k)?;
            // The scans in parallel (each search also splits its own work).
            let searched: Vec<TileSearch> = open
                .par_iter()
                .zip(&round_caps)
                .zip(&found)
                .map(|((&s, &c), f)| {
                    let cap = Cap {
                        cost: f.map_or(c, |f| f.min(c)),
                        minimum_only: true,
                        ..Cap::NONE
                    };
                    search_tile(&tile, k, &scans[s], along_streets[s], options, cap)
                })
                .collect::<Result<_>>()?;
            for (x, r) in searched.iter().enumerate() {
                let s = open[x];
                if let Some(m) = r.minimum {
                    found[x] = Some(found[x].map_or(m, |f| f.min(m)));
                }
                search_s[s] += r.seconds;
                stats[s].boxes += r.boxes;
                stats[s].leaves += r.leaves;
            }
            progress(BatchStep {
                round: &name,
                tiles_done: done + 1,
                tiles: which.len(),
                scans: open.len(),
            });
        }
        for (x, &s) in open.iter().enumerate() {
            best[s] = found[x];
        }
    }
    let wanted: Vec<(usize, Cap)> = best
        .iter()
        .enumerate()
        .filter_map(|(s, b)| {
            b.map(|b| {
                let cap = Cap {
                    cost: limit_of(b, options.search.keep_factor),
                    minimum_only: false,
                    ..Cap::NONE
                };
                (s, cap)
            })
        })
        .collect();
    let mut searches: Vec<Vec<TileSearch>> = vec![Vec::new(); n];
    if !wanted.is_empty() {
        for (done, &k) in which.iter().enumerate() {
            let tile = load(k)?;
            let searched: Vec<TileSearch> = wanted
                .par_iter()
                .map(|&(s, cap)| search_tile(&tile, k, &scans[s], along_streets[s], options, cap))
                .collect::<Result<_>>()?;
            for (r, &(s, _)) in searched.into_iter().zip(&wanted) {
                search_s[s] += r.seconds;
                if !r.raw.is_empty() {
                    searches[s].push(r);
                }
            }
            progress(BatchStep {
                round: "poses",
                tiles_done: done + 1,
                tiles: which.len(),
                scans: wanted.len(),
            });
        }
    }
    let t = Instant::now();
    let crops = owner_crops(
        manifest_path,
        &manifest,
        searches.iter().map(|s| &s[..]),
        options,
    )?;
    let places: Vec<(usize, TilePlace<'_>)> =
        crops.iter().map(|(k, c)| (*k, TilePlace::new(c))).collect();
    load_s += t.elapsed().as_secs_f64();
    let place_of = |k: usize| place_in(&places, k);
    let mut results = Vec::with_capacity(n);
    for s in 0..n {
        let mut r = finish_tiled(
            &manifest,
            &searches[s],
            &scans[s],
            along_streets[s],
            options,
            &place_of,
        );
        // The poses round's statistics are in `r.search`; add the minimum rounds'.
        r.search.boxes += stats[s].boxes;
        r.search.leaves += stats[s].leaves;
        r.seconds.search = search_s[s];
        results.push(r);
    }
    Ok(TiledBatch {
        exact: scans
            .iter()
            .map(|s| is_exact(&manifest, scan_reach_m(s), options))
            .collect(),
        results,
        tiles_searched: which.len(),
        tile_loads: loads,
        max_tile_memory_bytes: max_mem,
        load_seconds: load_s,
        frame_map: crops[0].1.clone(),
    })
}

/// Localizes scan segments on the tiled map of `manifest_path`: every tile (or those of
/// `only`), [`localize_tiled_batch`] for one scan with the default caps.
pub fn localize_tiled(
    manifest_path: &Path,
    scan: &ScanSegments,
    options: &LocalizeOptions,
    only: Option<&[usize]>,
) -> Result<TiledLocalization> {
    let batch = localize_tiled_batch(
        manifest_path,
        std::slice::from_ref(&scan.segments),
        &[options.vehicle.along_streets(scan.sensor.as_ref())],
        options,
        &MINIMUM_CAPS_M,
        only,
        &mut |_| {},
    )?;
    let TiledBatch {
        results,
        exact,
        tiles_searched,
        max_tile_memory_bytes,
        load_seconds,
        frame_map,
        ..
    } = batch;
    Ok(TiledLocalization {
        result: results
            .into_iter()
            .next()
            .unwrap_or_else(|| Localization::empty(options.rank_by)),
        tiles_searched,
        exact: exact.first().copied().unwrap_or(true),
        max_tile_memory_bytes,
        load_seconds,
        frame_map,
    })
}
