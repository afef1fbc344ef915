//! ASPRS LAS 1.4 and LASzip LAZ through the `las` crate (format by extension).
//!
//! Written files use point format 6 (7 when the cloud has `rgb`) and a 0.1 mm integer grid
//! (scale 10⁻⁴ m, offset a multiple of 100 km), so positions come back within 0.05 mm and
//! a LAS → cloud → LAS trip reproduces the same file byte for byte. Other columns are exact:
//!
//! * `label` ↔ classification, by this table (LAS 1.4 R15 classes; 64–68 are
//!   user-definable classes taken for urbansem's classes LAS has no code for):
//!
//!   | urbansem | LAS written | LAS read back as urbansem |
//!   |---|---|---|
//!   | unlabelled | 0 never classified | 0, 1 (unclassified), 2 (ground: street, sidewalk or grass) |
//!   | car | 64 | 64 |
//!   | building | 6 | 6 |
//!   | street | 11 road surface | 11 |
//!   | sidewalk | 65 | 65 |
//!   | bicycle | 66 | 66 |
//!   | other | 67 | 67 and every other code |
//!   | tree | 5 high vegetation | 4, 5 |
//!   | pole | 68 | 68, 15 (transmission tower) |
//!   | grass | 3 low vegetation | 3 |
//!
//! * `intensity` (f32) is stored exactly in 4 extra bytes; the LAS u16 intensity field holds
//!   it rounded (scaled by 65535 when all values are in [0, 1]) for other tools.
//! * `raw_label` and `object` (u32) are stored in 4 extra bytes each.
//! * `rgb` is stored as 16-bit colour (value × 257) and read back as the high byte.
//!
//! Before the `las` crate sees a file, the header's counts and offsets are checked against the
//! file's length (the crate allocates by them): uncompressed point data must hold the point
//! count, the first EVLR (which the crate reads whole) must fit, and a LAZ chunk table must not
//! announce more chunks than the compressed data can hold. So an inflated count is an error
//! naming the byte, never an allocation, and reading is linear in the file (times the
//! decompression ratio for LAZ).
//!
//! The extra bytes are described by a standard Extra Bytes VLR (`LASF_Spec`, record 4).
//! A VLR (`user_id` "urbansem", record 1) lists the columns and the extra-byte layout; a
//! LAS file without it (another tool's) is read as intensity (u16), rgb (if the format has
//! colour), `label` from the table and `raw_label` = the classification code.

use super::{io_err, path_buf, CloudError, Location, PointCloud, PointRecord};
use super::{Columns, Precision, ReadOptions, ReadReport, Result, Sink};
use crate::classes::Class;
use crate::fsio::AtomicFile;
use las::point::{Classification, Format};
use las::{Builder, Color, Point, Reader, Transform, Vector, Version, Vlr, Writer};
use std::io::{Read, Seek, SeekFrom};
use std::path::Path;

/// Grid step of written LAS positions, metres.
pub const LAS_SCALE_M: f64 = 1e-4;
const VLR_USER: &str = "urbansem";
const VLR_RECORD: u16 = 1;

/// The LAS classification code written for an urbansem class.
pub fn las_code_of(class: Class) -> u8 {
    match class {
        Class::Unlabelled => 0,
        Class::Car => 64,
        Class::Building => 6,
        Class::Street => 11,
        Class::Sidewalk => 65,
        Class::Bicycle => 66,
        Class::Other => 67,
        Class::Tree => 5,
        Class::Pole => 68,
        Class::Grass => 3,
    }
}

/// The urbansem class of a LAS classification code (see the module table).
pub fn class_of_las_code(code: u8) -> Class {
    match code {
        0..=2 => Class::Unlabelled,
        3 => Class::Grass,
        4 | 5 => Class::Tree,
        6 => Class::Building,
        11 => Class::Street,
        15 | 68 => Class::Pole,
        64 => Class::Car,
        65 => Class::Sidewalk,
        66 => Class::Bicycle,
        _ => Class::Other,
    }
}

fn las_err(path: &Path, at: Location) -> impl Fn(las::Error) -> CloudError + '_ {
    move |source| CloudError::Las {
        path: path_buf(path),
        at,
        source,
    }
}

fn descriptor(c: &Columns, precision: Precision) -> String {
    let names: Vec<&str> = c.names().into_iter().skip(3).collect();
    let p = match precision {
        Precision::F32 => "f32",
        Precision::F64 => "f64",
    };
    format!("columns={};precision={p}", names.join(","))
}

fn parse_descriptor(data: &[u8]) -> Option<(Columns, Precision)> {
    let text = std::str::from_utf8(data).ok()?;
    let mut columns = Columns::default();
    let mut precision = None;
    for part in text.trim_end_matches('\0').split(';') {
        let (k, v) = part.split_once('=')?;
        match k {
            "columns" => {
                for name in v.split(',').filter(|s| !s.is_empty()) {
                    match name {
                        "intensity" => columns.intensity = true,
                        "rgb" => columns.rgb = true,
                        "label" => columns.label = true,
                        "raw_label" => columns.raw_label = true,
                        "object" => columns.object = true,
                        _ => return None,
                    }
                }
            }
            "precision" => {
                precision = Some(match v {
                    "f32" => Precision::F32,
                    "f64" => Precision::F64,
                    _ => return None,
                })
            }
            _ => return None,
        }
    }
    Some((columns, precision?))
}

fn extra_len(c: &Columns) -> usize {
    4 * (usize::from(c.intensity) + usize::from(c.raw_label) + usize::from(c.object))
}

/// The LAS 1.4 Extra Bytes VLR (`LASF_Spec`, record 4) describing our extra bytes, so
/// that other tools (PDAL, LAStools) see `intensity_f32`, `raw_label` and `object` by name.
fn extra_bytes_vlr(c: &Columns) -> Vlr {
    // (name, LAS data type: 5 = u32, 9 = f32)
    let mut fields: Vec<(&str, u8)> = Vec::new();
    if c.intensity {
        fields.push(("intensity_f32", 9));
    }
    if c.raw_label {
        fields.push(("raw_label", 5));
    }
    if c.object {
        fields.push(("object", 5));
    }
    let mut data = Vec::with_capacity(192 * fields.len());
    for (name, data_type) in fields {
        let mut d = [0u8; 192];
        d[2] = data_type;
        d[4..4 + name.len()].copy_from_slice(name.as_bytes());
        let description = b"urbansem column";
        d[160..160 + description.len()].copy_from_slice(description);
        data.extend_from_slice(&d);
    }
    Vlr {
        user_id: "LASF_Spec".into(),
        record_id: 4,
        description: "Extra Bytes".into(),
        data,
    }
}

/// Byte offset of `offset_to_point_data` in a LAS header.
const OFFSET_TO_POINT_DATA_AT: u64 = 96;
/// Bytes of an EVLR header; its u64 record length is at byte 20 of it.
const EVLR_HEADER_BYTES: u64 = 60;
/// Fewest bytes a LAZ chunk takes: its arithmetic decoder starts by reading 4 bytes.
const LAZ_MIN_CHUNK_BYTES: u64 = 4;

/// What [`check_layout`] learnt: the point count and record length the crate will use.
struct Layout {
    data_start: u64,
    points: u64,
    record_bytes: u64,
}

fn read_at<const N: usize>(path: &Path, r: &mut (impl Read + Seek), at: u64) -> Result<[u8; N]> {
    let mut b = [0u8; N];
    r.seek(SeekFrom::Start(at)).map_err(io_err(path))?;
    r.read_exact(&mut b).map_err(io_err(path))?;
    Ok(b)
}

/// Checks the counts and offsets of a LAS/LAZ header against the file's length, before the
/// `las` crate allocates or loops by them (see the module doc).
fn check_layout(path: &Path, r: &mut (impl Read + Seek), file_len: u64) -> Result<Layout> {
    let raw = las::raw::Header::read_from(&mut *r).map_err(las_err(path, Location::Byte(0)))?;
    let header_err = |at: u64, message: String| CloudError::Header {
        path: path_buf(path),
        at: Location::Byte(at),
        message,
    };
    let data_start = u64::from(raw.offset_to_point_data);
    if data_start > file_len {
        return Err(header_err(
            OFFSET_TO_POINT_DATA_AT,
            format!("the point data starts at byte {data_start}, past the end of the file ({file_len} bytes)"),
        ));
    }
    // The crate's rule: the legacy count unless it is 0 in a LAS 1.4 header.
    let legacy = u64::from(raw.number_of_point_records);
    let points = match raw.large_file {
        Some(large) if legacy == 0 => large.number_of_point_records,
        _ => legacy,
    };
    let record_bytes = u64::from(raw.point_data_record_length);
    let compressed = raw.point_data_record_format & 0x80 != 0;
    let available = file_len - data_start;
    let need = points.checked_mul(record_bytes);
    if !compressed && need.is_none_or(|need| need > available) {
        let whole = available / record_bytes.max(1);
        return Err(CloudError::Truncated {
            path: path_buf(path),
            at: Location::Byte(data_start + whole * record_bytes),
            point: usize::try_from(whole).unwrap_or(usize::MAX),
            expected: usize::try_from(points).unwrap_or(usize::MAX),
        });
    }
    if need.and_then(|need| need.checked_add(data_start)).is_none() {
        return Err(header_err(
            OFFSET_TO_POINT_DATA_AT,
            format!("{points} points of {record_bytes} bytes overflow a file offset"),
        ));
    }
    if let Some(evlr) = raw.evlr.filter(|e| e.number_of_evlrs > 0) {
        let start = evlr.start_of_first_evlr;
        let fits = |len: u64| {
            start
                .checked_add(EVLR_HEADER_BYTES)
                .and_then(|end| end.checked_add(len))
                .is_some_and(|end| end <= file_len)
        };
        let len = if fits(0) {
            u64::from_le_bytes(read_at(path, r, start + 20)?)
        } else {
            0
        };
        if !fits(0) || !fits(len) {
            return Err(header_err(
                start,
                format!(
                    "the first EVLR (at byte {start}, {len} bytes of data) does not fit in the file ({file_len} bytes)"
                ),
            ));
        }
    }
    if compressed && available >= 8 {
        // Where the laz crate looks for the chunk table: an offset at the start of the point
        // data or, when that one is not past it, in the file's last 8 bytes.
        let mut table = i64::from_le_bytes(read_at(path, r, data_start)?);
        if table <= data_start as i64 {
            table = i64::from_le_bytes(read_at(path, r, file_len - 8)?);
        }
        let table = u64::try_from(table).unwrap_or(0);
        if table > data_start && table.saturating_add(8) <= file_len {
            let chunks = u64::from(u32::from_le_bytes(read_at(path, r, table + 4)?));
            let room = table - data_start;
            if chunks.saturating_mul(LAZ_MIN_CHUNK_BYTES) > room {
                return Err(header_err(
                    table + 4,
                    format!(
                        "the LAZ chunk table announces {chunks} chunks, but the compressed points take only {room} bytes"
                    ),
                ));
            }
        }
    }
    r.seek(SeekFrom::Start(0)).map_err(io_err(path))?;
    Ok(Layout {
        data_start,
        points,
        record_bytes,
    })
}

/// Checks, chunk by chunk, that the layers of a layered LAZ file (point formats 6–10) fit in
/// the file: the `laz` crate allocates each layer's announced size before reading it, so a
/// corrupt size would otherwise allocate up to 4 GiB per layer (`fuzz/artifacts/las/oom-*`).
/// Mirrors the crate's walk: a chunk is the raw first point, its point count, one `u32` size
/// per layer, then the layers; the next chunk follows. Reads O(file size) bytes.
fn check_laz_layers(
    path: &Path,
    vlr: &laz::LazVlr,
    data_start: u64,
    file_len: u64,
    points: u64,
) -> Result<()> {
    use laz::LazItemType as T;
    if vlr.items().first().is_none_or(|i| i.version() < 3) {
        return Ok(()); // point-wise compression reads its stream directly
    }
    // Per item: its layers, and the bytes of its part of the raw first point as the crate's
    // field decoders read them (fixed per item type; a corrupt VLR may declare other sizes).
    let (layers, record) = vlr
        .items()
        .iter()
        .map(|i| match i.item_type() {
            T::Point14 => (9, 30),
            T::RGB14 => (1, 6),
            T::RGBNIR14 => (2, 8),
            T::WavePacket14 => (1, 29),
            T::Byte14(n) => (u64::from(n), u64::from(n)),
            _ => (1, u64::from(i.size())),
        })
        .fold((0u64, 0u64), |(l, r), (a, b)| (l + a, r + b));
    let mut r = std::io::BufReader::new(std::fs::File::open(path).map_err(io_err(path))?);
    // Variable-size chunks take their point counts from the chunk table when it reads.
    let table = if vlr.uses_variable_size_chunks() {
        r.seek(SeekFrom::Start(data_start)).map_err(io_err(path))?;
        laz::laszip::ChunkTable::read_from(&mut r, vlr).ok()
    } else {
        None
    };
    let head = record + 4 + 4 * layers;
    let mut sizes = Vec::new();
    let (mut pos, mut left, mut chunk) = (data_start + 8, points, 0usize);
    while left > 0 && pos.saturating_add(head) <= file_len {
        r.seek(SeekFrom::Start(pos + record))
            .map_err(io_err(path))?;
        sizes.resize(4 + 4 * layers as usize, 0u8);
        r.read_exact(&mut sizes).map_err(io_err(path))?;
        let own_count = u64::from(u32::from_le_bytes([sizes[0], sizes[1], sizes[2], sizes[3]]));
        let total: u64 = sizes[4..]
            .chunks_exact(4)
            .map(|b| u64::from(u32::from_le_bytes([b[0], b[1], b[2], b[3]])))
            .sum();
        let body = pos + head;
        if total > file_len - body {
            return Err(CloudError::Header {
                path: path_buf(path),
                at: Location::Byte(pos + record + 4),
                message: format!(
                    "LAZ chunk {chunk} announces layers of {total} bytes, but only {} bytes follow in the file",
                    file_len - body
                ),
            });
        }
        pos = body + total;
        let in_chunk = match &table {
            Some(t) => t.as_ref().get(chunk).map_or(own_count, |e| e.point_count),
            None if vlr.uses_variable_size_chunks() => own_count,
            None => u64::from(vlr.chunk_size()),
        };
        if in_chunk == 0 {
            break; // the crate then reads every remaining point from this chunk
        }
        left = left.saturating_sub(in_chunk);
        chunk += 1;
    }
    Ok(())
}

/// Reads a LAS or LAZ file.
pub fn read_las(path: &Path, options: &ReadOptions) -> Result<(PointCloud, ReadReport)> {
    let mut file = std::fs::File::open(path).map_err(io_err(path))?;
    let file_len = file.metadata().map_err(io_err(path))?.len();
    let layout = check_layout(path, &mut file, file_len)?;
    let mut reader = super::guard::catch_silently(|| {
        Reader::new(std::io::BufReader::with_capacity(1 << 16, file))
    })
    .ok_or_else(|| CloudError::Corrupt {
        path: path_buf(path),
        at: Location::Byte(0),
        message: "the LAZ chunk table reader failed".into(),
    })?
    .map_err(las_err(path, Location::Byte(0)))?;
    let header = reader.header();
    if let Some(v) = header
        .all_vlrs()
        .find(|v| v.user_id == laz::LazVlr::USER_ID && v.record_id == laz::LazVlr::RECORD_ID)
    {
        if let Ok(vlr) = laz::LazVlr::from_buffer(&v.data) {
            check_laz_layers(path, &vlr, layout.data_start, file_len, layout.points)?;
        }
    }
    let ours = header
        .all_vlrs()
        .find(|v| v.user_id == VLR_USER && v.record_id == VLR_RECORD)
        .map(|v| {
            parse_descriptor(&v.data).ok_or_else(|| CloudError::Header {
                path: path_buf(path),
                at: Location::Byte(0),
                message: format!("bad urbansem VLR {:?}", String::from_utf8_lossy(&v.data)),
            })
        })
        .transpose()?;
    let format = *header.point_format();
    let n = usize::try_from(header.number_of_points()).unwrap_or(usize::MAX);
    if header.number_of_points() != layout.points {
        // check_layout mirrors the crate's rule for the count; never trust a count it did not check.
        return Err(CloudError::Header {
            path: path_buf(path),
            at: Location::Byte(0),
            message: format!(
                "the las crate reads {} points where the header checks found {}",
                header.number_of_points(),
                layout.points
            ),
        });
    }
    // A LAS record takes `record_bytes` in the file (LAZ: fewer; the vector then grows).
    let capacity = n.min(usize::try_from(file_len / layout.record_bytes.max(1)).unwrap_or(0));
    let (columns, precision) = ours.unwrap_or((
        Columns {
            intensity: true,
            rgb: format.has_color,
            label: true,
            raw_label: true,
            object: false,
        },
        Precision::F64,
    ));
    if ours.is_some() {
        let need = extra_len(&columns);
        if usize::from(format.extra_bytes) < need || (columns.rgb && !format.has_color) {
            return Err(CloudError::Header {
                path: path_buf(path),
                at: Location::Byte(0),
                message: format!(
                    "urbansem VLR announces {need} extra bytes and colour={} but the point format has {} and colour={}",
                    columns.rgb, format.extra_bytes, format.has_color
                ),
            });
        }
    }
    let mut sink = Sink::new(
        path,
        PointCloud::with_columns(columns, precision, capacity),
        options,
    );
    for i in 0..n {
        // The laz decoder panics on some corrupt data (see `guard`): a format error here.
        let read = super::guard::catch_silently(|| reader.read_point()).ok_or_else(|| {
            CloudError::Corrupt {
                path: path_buf(path),
                at: Location::Point(i),
                message: "the LAZ decoder failed".into(),
            }
        })?;
        let point = match read {
            Ok(Some(p)) => p,
            Ok(None) => {
                return Err(CloudError::Truncated {
                    path: path_buf(path),
                    at: Location::Point(i),
                    point: i,
                    expected: n,
                })
            }
            Err(e) => return Err(las_err(path, Location::Point(i))(e)),
        };
        let code = u8::from(point.classification);
        let mut rec = PointRecord {
            position: [point.x, point.y, point.z],
            intensity: f32::from(point.intensity),
            rgb: point
                .color
                .map(|c| {
                    [
                        (c.red >> 8) as u8,
                        (c.green >> 8) as u8,
                        (c.blue >> 8) as u8,
                    ]
                })
                .unwrap_or([0; 3]),
            label: class_of_las_code(code).id(),
            raw_label: u32::from(code),
            object: 0,
        };
        if ours.is_some() {
            let mut extra = point
                .extra_bytes
                .chunks_exact(4)
                .map(|c| [c[0], c[1], c[2], c[3]]);
            let mut next = || extra.next().unwrap_or([0; 4]);
            if columns.intensity {
                rec.intensity = f32::from_le_bytes(next());
            }
            if columns.raw_label {
                rec.raw_label = u32::from_le_bytes(next());
            }
            if columns.object {
                rec.object = u32::from_le_bytes(next());
            }
        }
        sink.push(&rec)?;
    }
    Ok(sink.finish())
}

/// Writes a LAS (or, for a `.laz` path, LAZ) 1.4 file; see the module doc for the mapping.
pub fn write_las(path: &Path, cloud: &PointCloud) -> Result<()> {
    cloud.check_columns()?;
    let c = cloud.columns();
    let mut builder = Builder::from(Version::new(1, 4));
    let mut format =
        Format::new(if c.rgb { 7 } else { 6 }).map_err(las_err(path, Location::Byte(0)))?;
    format.extra_bytes = extra_len(&c) as u16;
    builder.point_format = format;
    // LAZ by extension, as `las::Writer::from_path` decides.
    builder.point_format.is_compressed = path
        .extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| e.eq_ignore_ascii_case("laz"));
    builder.generating_software = "urbansem".into();
    let bounds = cloud.bounds();
    let offset = |k: usize| {
        bounds
            .map(|b| ((b.min[k] + b.max[k]) / 2.0 / 1e5).round() * 1e5)
            .filter(|v| v.is_finite())
            .unwrap_or(0.0)
    };
    let t = |k: usize| Transform {
        scale: LAS_SCALE_M,
        offset: offset(k),
    };
    let grid = Vector {
        x: t(0),
        y: t(1),
        z: t(2),
    };
    builder.transforms = grid;
    builder.vlrs.push(Vlr {
        user_id: VLR_USER.into(),
        record_id: VLR_RECORD,
        description: "urbansem columns".into(),
        data: descriptor(&c, cloud.precision).into_bytes(),
    });
    if extra_len(&c) > 0 {
        builder.vlrs.push(extra_bytes_vlr(&c));
    }
    let header = builder
        .into_header()
        .map_err(las_err(path, Location::Byte(0)))?;
    // Written beside the target and renamed into place when complete.
    let file = AtomicFile::create(path).map_err(io_err(path))?;
    let mut writer = Writer::new(file, header).map_err(las_err(path, Location::Byte(0)))?;
    let unit = cloud
        .intensity
        .as_ref()
        .is_some_and(|v| v.iter().all(|x| (0.0..=1.0).contains(x)));
    for i in 0..cloud.len() {
        let Some(p) = cloud.get(i) else { break };
        let class = Class::from_id(p.label).unwrap_or(Class::Unlabelled);
        let mut extra = Vec::with_capacity(12);
        if c.intensity {
            extra.extend_from_slice(&p.intensity.to_le_bytes());
        }
        if c.raw_label {
            extra.extend_from_slice(&p.raw_label.to_le_bytes());
        }
        if c.object {
            extra.extend_from_slice(&p.object.to_le_bytes());
        }
        let scaled = if unit {
            p.intensity * 65535.0
        } else {
            p.intensity
        };
        // Snap to the integer grid here, so the header bounds are those of the stored
        // points and LAS → cloud → LAS gives the same bytes.
        let mut q = [0.0; 3];
        for (k, t) in [grid.x, grid.y, grid.z].iter().enumerate() {
            let v = p.position.get(k).copied().unwrap_or(0.0);
            q[k] = t.direct(t.inverse(v).map_err(las_err(path, Location::Point(i)))?);
        }
        let point = Point {
            x: q[0],
            y: q[1],
            z: q[2],
            intensity: scaled.round().clamp(0.0, 65535.0) as u16,
            classification: Classification::new(las_code_of(class))
                .map_err(las_err(path, Location::Point(i)))?,
            color: c.rgb.then(|| Color {
                red: u16::from(p.rgb[0]) * 257,
                green: u16::from(p.rgb[1]) * 257,
                blue: u16::from(p.rgb[2]) * 257,
            }),
            gps_time: format.has_gps_time.then_some(0.0),
            return_number: 1,
            number_of_returns: 1,
            extra_bytes: extra,
            ..Point::default()
        };
        writer
            .write_point(point)
            .map_err(las_err(path, Location::Point(i)))?;
    }
    let file = writer
        .into_inner()
        .map_err(las_err(path, Location::Byte(0)))?;
    file.commit().map_err(io_err(path))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn class_table_round_trips() {
        for c in Class::ALL {
            assert_eq!(class_of_las_code(las_code_of(c)), c);
        }
    }

    #[test]
    fn descriptor_round_trips() {
        let c = Columns {
            intensity: true,
            object: true,
            ..Columns::default()
        };
        assert_eq!(
            parse_descriptor(descriptor(&c, Precision::F64).as_bytes()),
            Some((c, Precision::F64))
        );
        assert_eq!(parse_descriptor(b"columns=foo;precision=f32"), None);
    }

    /// A small LAS (or LAZ) file written by [`write_las`], as bytes.
    fn small_file(name: &str, n: usize) -> (std::path::PathBuf, Vec<u8>) {
        let dir = std::env::temp_dir().join(format!("urbansem-las-unit-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let p = dir.join(name);
        let mut c = PointCloud::with_columns(
            Columns {
                intensity: true,
                ..Columns::default()
            },
            Precision::F64,
            n,
        );
        for i in 0..n {
            c.push(&PointRecord {
                position: [i as f64, 0.5 * i as f64, -1.0],
                intensity: i as f32,
                ..PointRecord::default()
            });
        }
        write_las(&p, &c).unwrap();
        let bytes = std::fs::read(&p).unwrap();
        (p, bytes)
    }

    /// Sets the point count of a LAS 1.4 header: legacy field (byte 107) 0, u64 field (247).
    fn set_count(bytes: &mut [u8], n: u64) {
        bytes[107..111].copy_from_slice(&0u32.to_le_bytes());
        bytes[247..255].copy_from_slice(&n.to_le_bytes());
    }

    fn read(p: &Path, bytes: &[u8]) -> Result<(PointCloud, ReadReport)> {
        std::fs::write(p, bytes).unwrap();
        read_las(p, &ReadOptions::default())
    }

    #[test]
    fn inflated_counts_and_truncated_files_are_errors() {
        // Each returns at once with an error, never allocating for or looping over the count.
        let (p, bytes) = small_file("a.las", 10);
        let start = u64::from(u32::from_le_bytes(bytes[96..100].try_into().unwrap()));
        let record = u64::from(u16::from_le_bytes(bytes[105..107].try_into().unwrap()));
        assert_eq!(read(&p, &bytes).unwrap().0.len(), 10);
        for n in [11, 1 << 40, u64::MAX] {
            let mut b = bytes.clone();
            set_count(&mut b, n);
            match read(&p, &b) {
                Err(CloudError::Truncated {
                    at: Location::Byte(at),
                    point: 10,
                    ..
                }) => assert_eq!(at, start + 10 * record),
                other => panic!("count {n}: {other:?}"),
            }
        }
        // Cut inside the seventh point.
        match read(&p, &bytes[..(start + 6 * record + 3) as usize]) {
            Err(CloudError::Truncated {
                at: Location::Byte(at),
                point: 6,
                expected: 10,
                ..
            }) => assert_eq!(at, start + 6 * record),
            other => panic!("{other:?}"),
        }
        // A first EVLR announcing 2⁶² bytes (the crate would allocate them).
        let mut b = bytes.clone();
        b[235..243].copy_from_slice(&(bytes.len() as u64).to_le_bytes());
        b[243..247].copy_from_slice(&1u32.to_le_bytes());
        let mut evlr = [0u8; 60];
        evlr[20..28].copy_from_slice(&(1u64 << 62).to_le_bytes());
        b.extend_from_slice(&evlr);
        match read(&p, &b) {
            Err(CloudError::Header {
                at: Location::Byte(at),
                ..
            }) => assert_eq!(at, bytes.len() as u64),
            other => panic!("{other:?}"),
        }
        // The point data starting past the end of the file.
        let mut b = bytes.clone();
        b[96..100].copy_from_slice(&u32::MAX.to_le_bytes());
        assert!(matches!(
            read(&p, &b),
            Err(CloudError::Header {
                at: Location::Byte(96),
                ..
            })
        ));
    }

    #[test]
    fn inflated_laz_counts_are_errors() {
        let (p, bytes) = small_file("a.laz", 100);
        assert_eq!(read(&p, &bytes).unwrap().0.len(), 100);
        // More points than the compressed data holds: the decompressor runs out of data.
        for n in [101, 1 << 40, u64::MAX / 2] {
            let mut b = bytes.clone();
            set_count(&mut b, n);
            assert!(read(&p, &b).is_err(), "count {n}");
        }
        // A chunk table announcing 2³² - 1 chunks (the laz crate would allocate 64 GiB).
        let start = u32::from_le_bytes(bytes[96..100].try_into().unwrap()) as usize;
        let table = i64::from_le_bytes(bytes[start..start + 8].try_into().unwrap()) as usize;
        let mut b = bytes.clone();
        b[table + 4..table + 8].copy_from_slice(&u32::MAX.to_le_bytes());
        match read(&p, &b) {
            Err(CloudError::Header {
                at: Location::Byte(at),
                ..
            }) => assert_eq!(at, table as u64 + 4),
            other => panic!("{other:?}"),
        }
        // A layer size of 0xF000_0000 in the first chunk (the laz crate would allocate it):
        // the chunk is the raw first point, the point count, then 9 point layers and one
        // layer per extra byte (4 here, the f32 intensity).
        let record = u64::from(u16::from_le_bytes(bytes[105..107].try_into().unwrap())) as usize;
        let sizes = start + 8 + record + 4;
        assert_eq!(
            u32::from_le_bytes(bytes[sizes - 4..sizes].try_into().unwrap()),
            100
        );
        for layer in [0, 3, 8, 9, 12] {
            let mut b = bytes.clone();
            let at = sizes + 4 * layer;
            b[at..at + 4].copy_from_slice(&0xF000_0000u32.to_le_bytes());
            match read(&p, &b) {
                Err(CloudError::Header {
                    at: Location::Byte(at),
                    message,
                    ..
                }) => {
                    assert_eq!(at as usize, sizes, "layer {layer}");
                    assert!(message.contains("LAZ chunk 0"), "{message}");
                }
                other => panic!("layer {layer}: {other:?}"),
            }
        }
        // Truncated anywhere: an error, never a panic.
        for cut in [0, 100, start, start + 8, start + 40, bytes.len() - 1] {
            assert!(read(&p, &bytes[..cut]).is_err(), "cut at {cut}");
        }
    }
}
