//! A map crop file (`.umap`): the buildings and street segments around a map tile, in the
//! whole map's frame, bit for bit ([`crate::tiles`]).
//!
//! Little-endian: magic `ULOCMAP\0`, version (u32), body length (u64),
//! CRC-32 of the body (u32), then the body: frame origin (lat, lon), bounds (4 × f64), the
//! buildings (id, kind, tag, outer ring, inner rings, height, levels, name) and the street
//! segments (way, index in way, end nodes, ends, length, highway tag). Every count is checked
//! against the bytes left before anything is allocated.

use crate::codec::{close_body, index_err, open_body, write_file, Dec, Enc};
use crate::Result;
use geodata::osm::model::{Building, ElementKind, OsmStats, StreetNetwork, StreetSegment};
use geodata::osm::OsmMap;
use geodata::projection::LocalFrame;
use std::io::{BufReader, Read};
use std::path::Path;

/// The crop file's magic bytes.
pub const CROP_MAGIC: &[u8; 8] = b"ULOCMAP\0";
/// The crop format version this build reads and writes.
pub const CROP_VERSION: u32 = 1;

fn ring(e: &mut Enc<'_>, r: &[[f64; 2]]) {
    e.u64(r.len() as u64);
    for p in r {
        e.f64(p[0]);
        e.f64(p[1]);
    }
}

fn opt_f64(e: &mut Enc<'_>, v: Option<f64>) {
    e.u8(u8::from(v.is_some()));
    e.f64(v.unwrap_or(0.0));
}

/// Writes a map crop (`.umap`) atomically.
pub fn write_crop(map: &OsmMap, path: &Path) -> Result<()> {
    let mut e = Enc::default();
    let (lat, lon) = map.frame.origin();
    e.f64(lat);
    e.f64(lon);
    for v in map.bbox_lonlat {
        e.f64(v);
    }
    e.u64(map.buildings.len() as u64);
    for b in &map.buildings {
        e.i64(b.osm_id);
        e.u8(match b.kind {
            ElementKind::Way => 0,
            ElementKind::Relation => 1,
        });
        e.str(&b.building);
        ring(&mut e, &b.outer);
        e.u64(b.inners.len() as u64);
        for r in &b.inners {
            ring(&mut e, r);
        }
        opt_f64(&mut e, b.height_m);
        opt_f64(&mut e, b.levels);
        e.u8(u8::from(b.name.is_some()));
        e.str(b.name.as_deref().unwrap_or(""));
    }
    e.u64(map.streets.segments.len() as u64);
    for s in &map.streets.segments {
        e.u64(s.way_index as u64);
        e.u64(s.index_in_way as u64);
        e.i64(s.from_node);
        e.i64(s.to_node);
        for v in [s.a[0], s.a[1], s.b[0], s.b[1], s.length_m] {
            e.f64(v);
        }
        e.str(&s.highway);
    }
    write_file(path, CROP_MAGIC, CROP_VERSION, &e)
}

/// Reads a map crop (`.umap`).
pub fn read_crop(path: &Path) -> Result<OsmMap> {
    let file = std::fs::File::open(path).map_err(|e| index_err(path, e.to_string()))?;
    let len = file
        .metadata()
        .map_err(|e| index_err(path, e.to_string()))?
        .len();
    read_crop_from(BufReader::new(file), len, path)
}

fn read_ring<R: Read>(d: &mut Dec<'_, R>, what: &str) -> Result<Vec<[f64; 2]>> {
    let n = d.count(16, what)?;
    let mut v = Vec::with_capacity(n);
    for _ in 0..n {
        v.push(d.f64s::<2>(what)?);
    }
    Ok(v)
}

fn read_opt<R: Read>(d: &mut Dec<'_, R>, what: &str) -> Result<Option<f64>> {
    let flag = d.u8(what)?;
    let v = d.f64(what)?;
    Ok((flag != 0).then_some(v))
}

/// Reads a map crop from a reader of `len` bytes (`path` names it in errors).
pub fn read_crop_from<R: Read>(r: R, len: u64, path: &Path) -> Result<OsmMap> {
    let (mut d, crc) = open_body(
        r,
        len,
        path,
        CROP_MAGIC,
        CROP_VERSION,
        "a urbansem map crop",
    )?;
    let [lat, lon] = d.f64s::<2>("frame origin")?;
    let frame = LocalFrame::new(lat, lon).map_err(|e| d.bad(format!("frame origin: {e}")))?;
    let bbox_lonlat = d.f64s::<4>("bounds")?;
    let n = d.count(8 + 1 + 8 + 8 + 8 + 18 + 18 + 1 + 8, "buildings")?;
    let mut buildings = Vec::with_capacity(n);
    for _ in 0..n {
        let osm_id = d.i64("building id")?;
        let kind = match d.u8("building kind")? {
            0 => ElementKind::Way,
            1 => ElementKind::Relation,
            v => return Err(d.bad(format!("building kind {v}, expected 0 or 1"))),
        };
        let building = d.string("building tag")?;
        let outer = read_ring(&mut d, "outer ring")?;
        let k = d.count(8, "inner rings")?;
        let mut inners = Vec::with_capacity(k);
        for _ in 0..k {
            inners.push(read_ring(&mut d, "inner ring")?);
        }
        let height_m = read_opt(&mut d, "height")?;
        let levels = read_opt(&mut d, "levels")?;
        let has_name = d.u8("name flag")? != 0;
        let name = d.string("name")?;
        buildings.push(Building {
            osm_id,
            kind,
            building,
            outer,
            inners,
            height_m,
            levels,
            name: has_name.then_some(name),
        });
    }
    let n = d.count(8 * 4 + 8 * 5 + 8, "street segments")?;
    let mut segments = Vec::with_capacity(n);
    for _ in 0..n {
        let way_index = d.usize("way index")?;
        let index_in_way = d.usize("index in way")?;
        let from_node = d.i64("from node")?;
        let to_node = d.i64("to node")?;
        let v = d.f64s::<5>("segment")?;
        let highway = d.string("highway tag")?;
        segments.push(StreetSegment {
            way_index,
            index_in_way,
            from_node,
            to_node,
            a: [v[0], v[1]],
            b: [v[2], v[3]],
            length_m: v[4],
            highway,
        });
    }
    close_body(d, crc)?;
    Ok(crop_map(frame, bbox_lonlat, buildings, segments))
}

/// A crop: buildings and street segments in `frame`, without highway ways or intersections.
pub(crate) fn crop_map(
    frame: LocalFrame,
    bbox_lonlat: [f64; 4],
    buildings: Vec<Building>,
    segments: Vec<StreetSegment>,
) -> OsmMap {
    OsmMap {
        frame,
        bbox_lonlat,
        buildings,
        highways: Vec::new(),
        streets: StreetNetwork {
            segments,
            intersections: Vec::new(),
            neighbour_pairs: Vec::new(),
        },
        stats: OsmStats::default(),
    }
}
