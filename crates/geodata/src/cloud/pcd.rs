//! PCL's PCD format (v0.5–0.7), `DATA ascii`, `binary` and `binary_compressed`: read as PCL
//! reads it, written by [`write_pcd`].
//!
//! # PCL conformance
//!
//! The reader follows `pcl::PCDReader` (PCL 1.14, `io/src/pcd_io.cpp`): a file PCL reads gives
//! the same points with the same values, and a file PCL refuses is refused with an error naming
//! the file and the line or byte. Checked on files PCL wrote (`../shared/data/pcd-pcl`, test
//! `crates/geodata/tests/pcd_pcl.rs`). The rules:
//!
//! * **Header.** Blank lines and `#` comments are skipped. The keywords are `VERSION`, `FIELDS`
//!   (or `COLUMNS`), `SIZE`, `TYPE`, `COUNT`, `WIDTH`, `HEIGHT`, `VIEWPOINT` (7 numbers; metadata,
//!   not applied, as in PCL) and `POINTS`; the body starts right after the `DATA` line.
//!   A `SIZE`/`TYPE` pair is one of PCL's types: `I` or `U` with 1, 2, 4 or 8 bytes, `F` with 4
//!   or 8, `B` (bool) with 1; only the type's first letter counts, in either case. Without
//!   `SIZE` and `TYPE` every field is F4 (PCL's default for old files); without `COUNT` every
//!   count is 1; a field with `COUNT 0` is dropped.
//! * **Point count.** `POINTS` is the number of points. Without `HEIGHT` the cloud is one row
//!   (`WIDTH` = `POINTS` when absent or 0); `WIDTH` × `HEIGHT` must equal `POINTS`. A missing
//!   `POINTS` counts as 0, as in PCL, so it is an error unless `WIDTH` × `HEIGHT` is 0.
//! * **Fields.** `x y z` (COUNT 1, any numeric type) are the position. `intensity`; `rgb` or
//!   `rgba` (COUNT 1) packed 0x00RRGGBB (alpha in the high byte ignored), as U4 or as the bits
//!   of an F4 (PCL's convention); or separate U1 fields `r g b` / `red green blue`. `label` U1
//!   is urbansem's class id (what [`write_pcd`] writes); a wider `label`, such as the U4 of
//!   PCL's `PointXYZL`, is a dataset's own id and fills `raw_label`. `raw_label` and `object`
//!   are urbansem's. Every other field (normals, descriptors, any COUNT > 1 array, and the `_`
//!   fields PCL writes for struct padding) is skipped by its size.
//! * **`DATA binary`.** POINTS records of Σ SIZE × COUNT little-endian bytes (`_` included),
//!   one point after another.
//! * **`DATA binary_compressed`.** A little-endian u32 compressed size, a u32 uncompressed
//!   size, then one LZF block ([`super::lzf`]) that holds the fields column by column: all
//!   points' `x`, then all `y`, …, a point's COUNT values of a field together. `_` padding
//!   fields are not stored (PCL's writer drops them and its reader skips them), so the
//!   uncompressed size must be POINTS × Σ SIZE × COUNT over the other fields.
//! * **`DATA ascii`.** One point per line, values separated by spaces or tabs, `nan` for an
//!   invalid value, an `F4` `rgb` read by its bits; blank lines are skipped and the last line
//!   needs no newline.
//! * **After the data.** PCL pads the binary files it writes to a memory page and reads only
//!   what the header announces: bytes after the last binary point and lines after the last
//!   ASCII point are ignored.
//! * **NaN.** PCL writes NaN coordinates for the invalid points of organized clouds
//!   (`HEIGHT` > 1). The file is valid; like in every format such points are an error by
//!   default and are skipped and counted in [`ReadReport::dropped_non_finite`] with
//!   [`ReadOptions::drop_non_finite`].
//!
//! Where PCL reads a malformed file anyway, this reader refuses it rather than guess: an ASCII
//! line with the wrong number of values (PCL warns and keeps a zero point), a value that does
//! not parse, a `SIZE`/`TYPE` pair PCL has no type for, an uncompressed size other than the
//! header's, an unknown header keyword (PCL stops reading the header there).
//!
//! # Cost
//!
//! Time linear in the file. Header counts are checked against the file's length before
//! anything is allocated or looped over for them: a binary body must hold POINTS records, an
//! ASCII body at least two bytes per value, and the uncompressed size of a compressed body at
//! most [`super::lzf::MAX_EXPANSION`] times its compressed size. ASCII and binary bodies are
//! streamed; a compressed block is decompressed in memory.

use super::ply::{assign, Role, Scalar};
use super::{io_err, path_buf, read_full, CloudError, Encoding, Location, PointCloud, PointRecord};
use super::{write_ascii_position, Columns, Precision, ReadOptions, ReadReport, Result, Sink};
use crate::fsio::AtomicFile;
use std::fs::File;
use std::io::{BufRead, BufReader, Read, Write};
use std::path::Path;

/// Longest header line accepted, bytes (a garbled header must not eat memory).
const MAX_HEADER_LINE: u64 = 65_536;

/// What a field fills.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum PcdRole {
    /// A column value (or [`Role::Skip`]).
    Column(Role),
    /// Packed 0x00RRGGBB colour.
    Rgb,
}

/// One field of the header (fields with `COUNT 0` are already dropped).
#[derive(Debug, Clone)]
struct Field {
    name: String,
    ty: Scalar,
    count: u64,
    role: PcdRole,
    /// A `_` field: struct padding, absent from `binary_compressed` data.
    padding: bool,
}

impl Field {
    /// Bytes of one point's values of this field (checked at header time not to overflow).
    fn bytes(&self) -> u64 {
        self.ty.size() as u64 * self.count
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Data {
    Ascii,
    Binary,
    Compressed,
}

/// A parsed header and the sizes derived from it.
struct Header {
    fields: Vec<Field>,
    points: usize,
    data: Data,
    /// Bytes before the body.
    len: u64,
    /// Lines in the header.
    lines: usize,
    /// Line of `POINTS` (of `DATA` when there is none).
    points_line: usize,
    /// Bytes of one `binary` point, `_` fields included.
    stride: u64,
    /// Bytes of one point in `binary_compressed` data, `_` fields excluded.
    packed: u64,
    /// Values on one ASCII line.
    values: u64,
}

fn header_err(path: &Path, line: usize, message: impl Into<String>) -> CloudError {
    CloudError::Header {
        path: path_buf(path),
        at: Location::Line(line),
        message: message.into(),
    }
}

/// A header entry's values and the line they were on.
type Entry<T> = Option<(Vec<T>, usize)>;

/// The header lines before `DATA`, as read.
#[derive(Default)]
struct RawHeader {
    names: Entry<String>,
    sizes: Entry<u64>,
    types: Entry<char>,
    counts: Entry<u64>,
    width: Option<u64>,
    height: Option<u64>,
    points: Option<(u64, usize)>,
}

fn read_header(path: &Path, r: &mut impl BufRead) -> Result<Header> {
    let mut raw = RawHeader::default();
    let mut buf = Vec::new();
    let mut len = 0u64;
    let mut line_no = 0usize;
    loop {
        line_no += 1;
        buf.clear();
        let n = r
            .by_ref()
            .take(MAX_HEADER_LINE)
            .read_until(b'\n', &mut buf)
            .map_err(io_err(path))?;
        if n == 0 || buf.last() != Some(&b'\n') {
            return Err(header_err(
                path,
                line_no,
                format!(
                    "file ends (or a line is longer than {MAX_HEADER_LINE} bytes) before the DATA line"
                ),
            ));
        }
        len += n as u64;
        let text = std::str::from_utf8(&buf)
            .map_err(|_| header_err(path, line_no, "header is not UTF-8"))?;
        // PCL splits header lines at spaces, tabs and carriage returns.
        let mut tok = text.split_ascii_whitespace();
        let Some(key) = tok.next() else { continue };
        if key.starts_with('#') {
            continue;
        }
        let rest: Vec<&str> = tok.collect();
        let numbers = |what: &str| -> Result<Vec<u64>> {
            rest.iter()
                .map(|s| {
                    s.parse::<u64>().map_err(|_| {
                        header_err(
                            path,
                            line_no,
                            format!("bad {what} value {s:?}; expected a non-negative integer"),
                        )
                    })
                })
                .collect()
        };
        let one = |what: &str| -> Result<u64> {
            match numbers(what)?.as_slice() {
                [v] => Ok(*v),
                _ => Err(header_err(
                    path,
                    line_no,
                    format!("{what} takes one number"),
                )),
            }
        };
        match key {
            "VERSION" => {}
            "FIELDS" | "COLUMNS" => {
                raw.names = Some((rest.iter().map(|s| s.to_string()).collect(), line_no))
            }
            "SIZE" => raw.sizes = Some((numbers("SIZE")?, line_no)),
            // PCL reads the first letter of each type, in either case.
            "TYPE" => {
                raw.types = Some((
                    rest.iter()
                        .filter_map(|s| s.chars().next())
                        .map(|c| c.to_ascii_uppercase())
                        .collect(),
                    line_no,
                ))
            }
            "COUNT" => raw.counts = Some((numbers("COUNT")?, line_no)),
            "WIDTH" => raw.width = Some(one("WIDTH")?),
            "HEIGHT" => raw.height = Some(one("HEIGHT")?),
            "POINTS" => raw.points = Some((one("POINTS")?, line_no)),
            "VIEWPOINT" => {
                if rest.len() < 7 {
                    return Err(header_err(
                        path,
                        line_no,
                        "VIEWPOINT needs 7 numbers (tx ty tz qw qx qy qz)",
                    ));
                }
            }
            "DATA" => {
                let data = match rest.first().map(|s| s.to_ascii_lowercase()).as_deref() {
                    Some("ascii") => Data::Ascii,
                    Some("binary") => Data::Binary,
                    Some("binary_compressed") => Data::Compressed,
                    _ => {
                        return Err(header_err(
                            path,
                            line_no,
                            format!(
                                "unknown DATA {:?}; expected ascii, binary or binary_compressed",
                                rest.first().copied().unwrap_or("")
                            ),
                        ))
                    }
                };
                return finish_header(path, raw, data, len, line_no);
            }
            other => {
                return Err(header_err(
                    path,
                    line_no,
                    format!(
                        "unknown header keyword {other:?}; a PCD header has VERSION, FIELDS, SIZE, \
                         TYPE, COUNT, WIDTH, HEIGHT, VIEWPOINT, POINTS and DATA"
                    ),
                ))
            }
        }
    }
}

/// PCL's scalar type for a `TYPE` letter and a `SIZE` (`getFieldType`).
fn scalar_of(letter: char, size: u64) -> Option<Scalar> {
    Some(match (letter, size) {
        ('I', 1) => Scalar::I8,
        ('I', 2) => Scalar::I16,
        ('I', 4) => Scalar::I32,
        ('I', 8) => Scalar::I64,
        ('U', 1) | ('B', 1) => Scalar::U8,
        ('U', 2) => Scalar::U16,
        ('U', 4) => Scalar::U32,
        ('U', 8) => Scalar::U64,
        ('F', 4) => Scalar::F32,
        ('F', 8) => Scalar::F64,
        _ => return None,
    })
}

/// Which column a (non-padding) field fills.
fn role_of(path: &Path, line: usize, name: &str, ty: Scalar, count: u64) -> Result<PcdRole> {
    Ok(match (name, count) {
        ("rgb" | "rgba", 1) => PcdRole::Rgb,
        // urbansem writes its class id as U1; PCL's PointXYZL label (U4) is a dataset's id.
        ("label", 1) if ty != Scalar::U8 => PcdRole::Column(Role::RawLabel),
        (n, 1) => PcdRole::Column(Role::from_name(n)),
        ("x" | "y" | "z", _) => {
            return Err(header_err(
                path,
                line,
                format!("field {name} has COUNT {count}; a coordinate needs COUNT 1"),
            ))
        }
        _ => PcdRole::Column(Role::Skip),
    })
}

/// Checks the header lines against each other, as PCL's `readHeader` does.
fn finish_header(
    path: &Path,
    raw: RawHeader,
    data: Data,
    len: u64,
    data_line: usize,
) -> Result<Header> {
    let Some((names, names_line)) = raw.names else {
        return Err(header_err(path, data_line, "no FIELDS line before DATA"));
    };
    let n = names.len();
    if n == 0 {
        return Err(header_err(path, names_line, "FIELDS names no field"));
    }
    let same_length = |what: &str, got: usize, line: usize| -> Result<()> {
        if got == n {
            Ok(())
        } else {
            Err(header_err(
                path,
                line,
                format!("{what} has {got} values but FIELDS names {n} fields"),
            ))
        }
    };
    let (sizes, types, types_line) = match (raw.sizes, raw.types) {
        // PCL's default for old files: every field F4.
        (None, None) => (vec![4; n], vec!['F'; n], data_line),
        (Some((sizes, sizes_line)), Some((types, types_line))) => {
            same_length("SIZE", sizes.len(), sizes_line)?;
            same_length("TYPE", types.len(), types_line)?;
            (sizes, types, types_line)
        }
        (Some((_, line)), None) => return Err(header_err(path, line, "SIZE without a TYPE line")),
        (None, Some((_, line))) => return Err(header_err(path, line, "TYPE without a SIZE line")),
    };
    let (counts, counts_line) = raw.counts.unwrap_or_else(|| (vec![1; n], data_line));
    same_length("COUNT", counts.len(), counts_line)?;

    let mut fields: Vec<Field> = Vec::with_capacity(n);
    let (mut stride, mut packed, mut values) = (0u64, 0u64, 0u64);
    let overflow = || header_err(path, counts_line, "SIZE × COUNT overflows");
    for (((name, &size), &letter), &count) in names.iter().zip(&sizes).zip(&types).zip(&counts) {
        // PCL drops a field with COUNT 0 (its header reader warns).
        if count == 0 {
            continue;
        }
        let ty = scalar_of(letter, size).ok_or_else(|| {
            header_err(
                path,
                types_line,
                format!(
                    "field {name}: TYPE {letter} with SIZE {size} is not a PCL type \
                     (I1 I2 I4 I8 U1 U2 U4 U8 F4 F8 B1)"
                ),
            )
        })?;
        let padding = name == "_";
        let role = if padding {
            PcdRole::Column(Role::Skip)
        } else {
            role_of(path, counts_line, name, ty, count)?
        };
        let is_colour = |r: PcdRole| {
            matches!(
                r,
                PcdRole::Rgb | PcdRole::Column(Role::Red | Role::Green | Role::Blue)
            )
        };
        let clash = fields.iter().find(|f| {
            role != PcdRole::Column(Role::Skip)
                && (f.role == role
                    || (role == PcdRole::Rgb && is_colour(f.role))
                    || (f.role == PcdRole::Rgb && is_colour(role)))
        });
        if let Some(other) = clash {
            return Err(header_err(
                path,
                names_line,
                format!("fields {:?} and {name:?} fill the same column", other.name),
            ));
        }
        let field = Field {
            name: name.clone(),
            ty,
            count,
            role,
            padding,
        };
        let bytes = (ty.size() as u64).checked_mul(count).ok_or_else(overflow)?;
        stride = stride.checked_add(bytes).ok_or_else(overflow)?;
        if !padding {
            packed = packed.checked_add(bytes).ok_or_else(overflow)?;
        }
        values = values.checked_add(count).ok_or_else(overflow)?;
        fields.push(field);
    }
    for (role, axis) in [(Role::X, "x"), (Role::Y, "y"), (Role::Z, "z")] {
        if !fields.iter().any(|f| f.role == PcdRole::Column(role)) {
            return Err(header_err(
                path,
                names_line,
                format!(
                    "no field {axis} (FIELDS {}); urbansem takes point positions from x, y and z",
                    names.join(" ")
                ),
            ));
        }
    }

    // WIDTH, HEIGHT and POINTS as PCL reconciles them.
    let (points, points_line) = raw.points.unwrap_or((0, data_line));
    let (width, height) = match (raw.width, raw.height) {
        (None, None) => (points, 1),
        (width, None) => (width.filter(|&w| w != 0).unwrap_or(points), 1),
        (width, Some(height)) => {
            let width = width.unwrap_or(0);
            if width == 0 && points != 0 {
                return Err(header_err(
                    path,
                    points_line,
                    format!("HEIGHT {height} given but no WIDTH"),
                ));
            }
            (width, height)
        }
    };
    if width.checked_mul(height) != Some(points) {
        let message = if raw.points.is_none() {
            format!("no POINTS line; PCL needs POINTS = WIDTH × HEIGHT ({width} × {height})")
        } else {
            format!("WIDTH {width} × HEIGHT {height} ≠ POINTS {points}")
        };
        return Err(header_err(path, points_line, message));
    }
    let points = usize::try_from(points).map_err(|_| {
        header_err(
            path,
            points_line,
            format!("POINTS {points} does not fit in memory"),
        )
    })?;
    Ok(Header {
        fields,
        points,
        data,
        len,
        lines: data_line,
        points_line,
        stride,
        packed,
        values,
    })
}

fn set(
    rec: &mut PointRecord,
    f: &Field,
    v: f64,
    raw: &[u8],
    path: &Path,
    at: Location,
) -> Result<()> {
    match f.role {
        PcdRole::Rgb => {
            let bits = match f.ty {
                // The float's bits, from the bytes (a round trip through f64 could quiet a
                // signalling-NaN pattern and change the red byte).
                Scalar::F32 => u32::from_le_bytes(
                    raw.get(..4)
                        .and_then(|s| s.try_into().ok())
                        .unwrap_or((v as f32).to_le_bytes()),
                ),
                Scalar::F64 => v as u32,
                // An integer's low 32 bits: an I4 rgb with its alpha byte set is negative.
                _ => (v as i64) as u32,
            };
            rec.rgb = [(bits >> 16) as u8, (bits >> 8) as u8, bits as u8];
            Ok(())
        }
        PcdRole::Column(role) => assign(rec, role, v, path, at, &f.name),
    }
}

/// Reads a PCD file (`DATA ascii`, `binary` or `binary_compressed`) as PCL does; see the
/// module doc for the rules.
pub fn read_pcd(path: &Path, options: &ReadOptions) -> Result<(PointCloud, ReadReport)> {
    let file = File::open(path).map_err(io_err(path))?;
    let file_len = file.metadata().map_err(io_err(path))?.len();
    let mut r = BufReader::with_capacity(1 << 16, file);
    let h = read_header(path, &mut r)?;
    let body = file_len.saturating_sub(h.len);
    let has = |role: PcdRole| h.fields.iter().any(|f| f.role == role);
    let columns = Columns {
        intensity: has(PcdRole::Column(Role::Intensity)),
        rgb: [
            PcdRole::Rgb,
            PcdRole::Column(Role::Red),
            PcdRole::Column(Role::Green),
            PcdRole::Column(Role::Blue),
        ]
        .into_iter()
        .any(has),
        label: has(PcdRole::Column(Role::Label)),
        raw_label: has(PcdRole::Column(Role::RawLabel)),
        object: has(PcdRole::Column(Role::Object)),
    };
    let double = h.fields.iter().any(|f| {
        matches!(f.role, PcdRole::Column(Role::X | Role::Y | Role::Z)) && f.ty != Scalar::F32
    });
    let precision = if double {
        Precision::F64
    } else {
        Precision::F32
    };
    let sink = |capacity: usize| {
        Sink::new(
            path,
            PointCloud::with_columns(columns, precision, capacity.min(h.points)),
            options,
        )
    };
    let sink = match h.data {
        Data::Binary => read_binary_body(path, &mut r, &h, body, sink)?,
        Data::Compressed => read_compressed_body(path, &mut r, &h, body, sink)?,
        Data::Ascii => read_ascii_body(path, &mut r, &h, body, sink)?,
    };
    Ok(sink.finish())
}

/// The fields that fill a column, with their byte offset in a record built by `bytes`.
fn layout(h: &Header, skip_padding: bool) -> Vec<(u64, &Field)> {
    let mut at = 0u64;
    let mut out = Vec::new();
    for f in &h.fields {
        if skip_padding && f.padding {
            continue;
        }
        if f.role != PcdRole::Column(Role::Skip) {
            out.push((at, f));
        }
        at += f.bytes();
    }
    out
}

fn read_binary_body<'a>(
    path: &'a Path,
    r: &mut impl Read,
    h: &Header,
    body: u64,
    sink: impl FnOnce(usize) -> Sink<'a>,
) -> Result<Sink<'a>> {
    // x, y and z take at least one byte each, so a point has at least 3.
    let stride = h.stride.max(1);
    let fits = (h.points as u64)
        .checked_mul(stride)
        .is_some_and(|need| need <= body);
    if !fits {
        let whole = body / stride;
        return Err(CloudError::Truncated {
            path: path_buf(path),
            at: Location::Byte(h.len + whole * stride),
            point: usize::try_from(whole).unwrap_or(usize::MAX),
            expected: h.points,
        });
    }
    let mut sink = sink(h.points);
    if h.points == 0 {
        return Ok(sink);
    }
    // stride ≤ body ≤ the file's length, so it is addressable.
    let record = usize::try_from(stride).unwrap_or(usize::MAX);
    let plan = layout(h, false);
    let mut buf = vec![0u8; record];
    for i in 0..h.points {
        let start = h.len + i as u64 * stride;
        if !read_full(r, &mut buf).map_err(io_err(path))? {
            // The file shrank while we read it.
            return Err(CloudError::Truncated {
                path: path_buf(path),
                at: Location::Byte(start),
                point: i,
                expected: h.points,
            });
        }
        let mut rec = PointRecord::default();
        for &(at, f) in &plan {
            let from = at as usize;
            let raw = buf.get(from..from + f.ty.size()).unwrap_or(&[]);
            let v = f.ty.decode(raw, false);
            set(&mut rec, f, v, raw, path, Location::Byte(start + at))?;
        }
        sink.push(&rec)?;
    }
    // Whatever follows is PCL's page padding: not read.
    Ok(sink)
}

fn read_compressed_body<'a>(
    path: &'a Path,
    r: &mut impl Read,
    h: &Header,
    body: u64,
    sink: impl FnOnce(usize) -> Sink<'a>,
) -> Result<Sink<'a>> {
    if h.points == 0 && body == 0 {
        return Ok(sink(0));
    }
    let mut sizes = [0u8; 8];
    if body < 8 || !read_full(r, &mut sizes).map_err(io_err(path))? {
        return Err(CloudError::Truncated {
            path: path_buf(path),
            at: Location::Byte(h.len),
            point: 0,
            expected: h.points,
        });
    }
    let compressed = u64::from(u32::from_le_bytes([sizes[0], sizes[1], sizes[2], sizes[3]]));
    let raw_len = u64::from(u32::from_le_bytes([sizes[4], sizes[5], sizes[6], sizes[7]]));
    let expected = (h.points as u64).checked_mul(h.packed);
    if expected != Some(raw_len) {
        return Err(CloudError::BadValue {
            path: path_buf(path),
            at: Location::Byte(h.len + 4),
            field: "uncompressed size".into(),
            value: format!(
                "{raw_len}; POINTS {} × {} bytes per point (fields without `_` padding) = {}",
                h.points,
                h.packed,
                expected.map_or_else(|| "overflow".to_string(), |e| e.to_string())
            ),
        });
    }
    if compressed > body - 8 {
        return Err(CloudError::BadValue {
            path: path_buf(path),
            at: Location::Byte(h.len),
            field: "compressed size".into(),
            value: format!(
                "{compressed} bytes, but {} follow; the file is truncated",
                body - 8
            ),
        });
    }
    if raw_len > compressed.saturating_mul(super::lzf::MAX_EXPANSION as u64) {
        return Err(CloudError::BadValue {
            path: path_buf(path),
            at: Location::Byte(h.len),
            field: "compressed size".into(),
            value: format!(
                "{compressed} bytes of LZF cannot hold {raw_len} bytes (LZF expands at most {}-fold)",
                super::lzf::MAX_EXPANSION
            ),
        });
    }
    // Both sizes are now bounded by (a multiple of) the file's length.
    let data_start = h.len + 8;
    let mut packed = vec![0u8; compressed as usize];
    if !read_full(r, &mut packed).map_err(io_err(path))? {
        // The file shrank while we read it.
        return Err(CloudError::Truncated {
            path: path_buf(path),
            at: Location::Byte(data_start),
            point: 0,
            expected: h.points,
        });
    }
    let soa = super::lzf::decompress(&packed, raw_len as usize).map_err(|e| {
        let at = match e {
            super::lzf::LzfError::Truncated { at }
            | super::lzf::LzfError::BadReference { at }
            | super::lzf::LzfError::Overflow { at } => at,
        };
        CloudError::BadValue {
            path: path_buf(path),
            at: Location::Byte(data_start + at as u64),
            field: "LZF data".into(),
            value: e.to_string(),
        }
    })?;
    drop(packed);
    // Column-major: a field's values start at POINTS × (bytes of the fields before it).
    let n = h.points as u64;
    let plan: Vec<(usize, &Field)> = layout(h, true)
        .into_iter()
        .map(|(at, f)| ((at * n) as usize, f))
        .collect();
    let mut sink = sink(h.points);
    for i in 0..h.points {
        let mut rec = PointRecord::default();
        for &(start, f) in &plan {
            let at = start + i * f.bytes() as usize;
            let raw = soa.get(at..at + f.ty.size()).unwrap_or(&[]);
            let v = f.ty.decode(raw, false);
            set(&mut rec, f, v, raw, path, Location::Point(i))?;
        }
        sink.push(&rec)?;
    }
    // Whatever follows the LZF block is PCL's page padding: not read.
    Ok(sink)
}

fn read_ascii_body<'a>(
    path: &'a Path,
    r: &mut impl BufRead,
    h: &Header,
    body: u64,
    sink: impl FnOnce(usize) -> Sink<'a>,
) -> Result<Sink<'a>> {
    // A value takes at least one character and one separator (the last line may lack its newline).
    let per_point = h.values.saturating_mul(2).max(1);
    let need = (h.points as u64).saturating_mul(per_point);
    if h.points > 0 && need - 1 > body {
        return Err(header_err(
            path,
            h.points_line,
            format!(
                "POINTS {} of {} values each need at least {} bytes of text, but {body} follow \
                 the header; the file is truncated or POINTS is wrong",
                h.points,
                h.values,
                need - 1
            ),
        ));
    }
    let mut sink = sink(usize::try_from(body / per_point).unwrap_or(usize::MAX));
    let mut buf = Vec::new();
    let mut line_no = h.lines;
    let mut i = 0usize;
    while i < h.points {
        buf.clear();
        if r.read_until(b'\n', &mut buf).map_err(io_err(path))? == 0 {
            return Err(CloudError::Truncated {
                path: path_buf(path),
                at: Location::Line(line_no + 1),
                point: i,
                expected: h.points,
            });
        }
        line_no += 1;
        let at = Location::Line(line_no);
        let text = std::str::from_utf8(&buf).map_err(|_| CloudError::BadValue {
            path: path_buf(path),
            at,
            field: "point".into(),
            value: "non-UTF-8 text".into(),
        })?;
        let mut tokens = text.split_ascii_whitespace().peekable();
        // PCL skips empty lines.
        if tokens.peek().is_none() {
            continue;
        }
        let mut rec = PointRecord::default();
        for f in &h.fields {
            for _ in 0..f.count {
                let tok = tokens.next().ok_or_else(|| CloudError::BadValue {
                    path: path_buf(path),
                    at,
                    field: f.name.clone(),
                    value: format!(
                        "missing: the line has fewer than the {} values FIELDS and COUNT give",
                        h.values
                    ),
                })?;
                if f.role == PcdRole::Column(Role::Skip) {
                    continue;
                }
                // `nan` parses as NaN; an F4 rgb is taken by its bits in `set`.
                let v = f.ty.parse(tok).ok_or_else(|| CloudError::BadValue {
                    path: path_buf(path),
                    at,
                    field: f.name.clone(),
                    value: tok.to_string(),
                })?;
                let raw = (v as f32).to_le_bytes();
                set(&mut rec, f, v, &raw, path, at)?;
            }
        }
        if let Some(extra) = tokens.next() {
            return Err(CloudError::BadValue {
                path: path_buf(path),
                at,
                field: "end of line".into(),
                value: format!(
                    "{extra} (more than the {} values FIELDS and COUNT give)",
                    h.values
                ),
            });
        }
        sink.push(&rec)?;
        i += 1;
    }
    // PCL reads POINTS points and ignores the rest of the file.
    Ok(sink)
}

/// Writes a PCD v0.7 file: `Ascii`, `BinaryCompressed` (LZF) or binary (little-endian; PCD
/// has no big-endian variant, so `BinaryBigEndian` writes binary too).
pub fn write_pcd(path: &Path, cloud: &PointCloud, encoding: Encoding) -> Result<()> {
    cloud.check_columns()?;
    let mut w = AtomicFile::create(path).map_err(io_err(path))?;
    let data = match encoding {
        Encoding::Ascii => Data::Ascii,
        Encoding::BinaryCompressed => Data::Compressed,
        Encoding::BinaryLittleEndian | Encoding::BinaryBigEndian => Data::Binary,
    };
    write_pcd_to(&mut w, cloud, data).map_err(io_err(path))?;
    w.commit().map_err(io_err(path))
}

fn write_pcd_to(w: &mut impl Write, cloud: &PointCloud, data: Data) -> std::io::Result<()> {
    let binary = data != Data::Ascii;
    let c = cloud.columns();
    let (xs, xt) = match cloud.precision {
        Precision::F32 => ("4", "F"),
        Precision::F64 => ("8", "F"),
    };
    let mut fields = vec![("x", xs, xt), ("y", xs, xt), ("z", xs, xt)];
    if c.intensity {
        fields.push(("intensity", "4", "F"));
    }
    if c.rgb {
        fields.push(("rgb", "4", "U"));
    }
    if c.label {
        fields.push(("label", "1", "U"));
    }
    if c.raw_label {
        fields.push(("raw_label", "4", "U"));
    }
    if c.object {
        fields.push(("object", "4", "U"));
    }
    let join = |k: usize| {
        fields
            .iter()
            .map(|f| match k {
                0 => f.0,
                1 => f.1,
                _ => f.2,
            })
            .collect::<Vec<_>>()
            .join(" ")
    };
    writeln!(w, "# .PCD v0.7 - Point Cloud Data file format (urbansem)")?;
    writeln!(
        w,
        "VERSION 0.7\nFIELDS {}\nSIZE {}\nTYPE {}",
        join(0),
        join(1),
        join(2)
    )?;
    writeln!(w, "COUNT {}", vec!["1"; fields.len()].join(" "))?;
    writeln!(
        w,
        "WIDTH {}\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS {}",
        cloud.len(),
        cloud.len()
    )?;
    let name = match data {
        Data::Ascii => "ascii",
        Data::Binary => "binary",
        Data::Compressed => "binary_compressed",
    };
    writeln!(w, "DATA {name}")?;
    let field_sizes: Vec<usize> = fields
        .iter()
        .map(|f| f.1.parse::<usize>().unwrap_or(0))
        .collect();
    let mut aos = Vec::new();
    let mut rec = Vec::with_capacity(64);
    for i in 0..cloud.len() {
        let Some(p) = cloud.get(i) else { break };
        let rgb = (u32::from(p.rgb[0]) << 16) | (u32::from(p.rgb[1]) << 8) | u32::from(p.rgb[2]);
        if !binary {
            write_ascii_position(w, cloud.precision, p.position)?;
            if c.intensity {
                write!(w, " {}", p.intensity)?;
            }
            if c.rgb {
                write!(w, " {rgb}")?;
            }
            if c.label {
                write!(w, " {}", p.label)?;
            }
            if c.raw_label {
                write!(w, " {}", p.raw_label)?;
            }
            if c.object {
                write!(w, " {}", p.object)?;
            }
            writeln!(w)?;
            continue;
        }
        rec.clear();
        for k in 0..3 {
            match cloud.precision {
                Precision::F32 => rec.extend_from_slice(&(p.position[k] as f32).to_le_bytes()),
                Precision::F64 => rec.extend_from_slice(&p.position[k].to_le_bytes()),
            }
        }
        if c.intensity {
            rec.extend_from_slice(&p.intensity.to_le_bytes());
        }
        if c.rgb {
            rec.extend_from_slice(&rgb.to_le_bytes());
        }
        if c.label {
            rec.push(p.label);
        }
        if c.raw_label {
            rec.extend_from_slice(&p.raw_label.to_le_bytes());
        }
        if c.object {
            rec.extend_from_slice(&p.object.to_le_bytes());
        }
        if data == Data::Compressed {
            aos.extend_from_slice(&rec);
        } else {
            w.write_all(&rec)?;
        }
    }
    if data == Data::Compressed {
        let n = cloud.len();
        let record: usize = field_sizes.iter().sum();
        let mut soa = Vec::with_capacity(aos.len());
        let mut offset = 0usize;
        for &size in &field_sizes {
            for i in 0..n {
                let at = i * record + offset;
                soa.extend_from_slice(aos.get(at..at + size).unwrap_or(&[]));
            }
            offset += size;
        }
        let packed = super::lzf::compress(&soa);
        let too_big = || {
            std::io::Error::new(
                std::io::ErrorKind::InvalidInput,
                "PCD binary_compressed holds at most 4 GiB",
            )
        };
        w.write_all(
            &u32::try_from(packed.len())
                .map_err(|_| too_big())?
                .to_le_bytes(),
        )?;
        w.write_all(
            &u32::try_from(soa.len())
                .map_err(|_| too_big())?
                .to_le_bytes(),
        )?;
        w.write_all(&packed)?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reads_pcl_style_ascii_with_float_rgb_and_normals() {
        let dir = std::env::temp_dir().join(format!("urbansem-pcd-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let p = dir.join("a.pcd");
        let rgb = f32::from_bits(0x00ff_8001);
        std::fs::write(
            &p,
            format!(
                "# .PCD v.7\nVERSION .7\nFIELDS x y z rgb normal\nSIZE 4 4 4 4 4\nTYPE F F F F F\nCOUNT 1 1 1 1 3\n\
                 WIDTH 1\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS 1\nDATA ascii\n1 2 3 {rgb:e} 0 0 1\n"
            ),
        )
        .unwrap();
        let (c, _) = read_pcd(&p, &ReadOptions::default()).unwrap();
        assert_eq!(c.positions, vec![[1.0, 2.0, 3.0]]);
        assert_eq!(c.rgb, Some(vec![[0xff, 0x80, 0x01]]));
    }

    #[test]
    fn compressed_round_trip_and_bad_sizes() {
        let dir = std::env::temp_dir().join(format!("urbansem-pcd-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let p = dir.join("c.pcd");
        let columns = Columns {
            intensity: true,
            ..Columns::default()
        };
        let mut c = PointCloud::with_columns(columns, Precision::F32, 3);
        for i in 0..3 {
            c.push(&PointRecord {
                position: [i as f64, 1.0, 2.0],
                intensity: 0.5,
                ..PointRecord::default()
            });
        }
        write_pcd(&p, &c, Encoding::BinaryCompressed).unwrap();
        assert_eq!(read_pcd(&p, &ReadOptions::default()).unwrap().0, c);
        let mut bytes = std::fs::read(&p).unwrap();
        let data = b"DATA binary_compressed\n";
        let at = bytes.windows(data.len()).position(|w| w == data).unwrap() + data.len();
        bytes[at + 4] ^= 1; // the uncompressed size
        std::fs::write(&p, &bytes).unwrap();
        let e = read_pcd(&p, &ReadOptions::default()).unwrap_err();
        assert!(matches!(e, CloudError::BadValue { .. }), "{e}");
    }

    /// Writes `bytes` to a scratch file and reads it with `options`.
    fn read_bytes(
        name: &str,
        bytes: &[u8],
        options: &ReadOptions,
    ) -> Result<(PointCloud, ReadReport)> {
        let dir = std::env::temp_dir().join(format!("urbansem-pcd-unit-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let p = dir.join(name);
        std::fs::write(&p, bytes).unwrap();
        read_pcd(&p, options)
    }

    fn read(name: &str, bytes: &[u8]) -> Result<PointCloud> {
        read_bytes(name, bytes, &ReadOptions::default()).map(|(c, _)| c)
    }

    fn header(
        fields: &str,
        size: &str,
        ty: &str,
        count: &str,
        points: &str,
        data: &str,
    ) -> Vec<u8> {
        format!(
            "# .PCD v0.7\nVERSION 0.7\nFIELDS {fields}\nSIZE {size}\nTYPE {ty}\nCOUNT {count}\n\
             WIDTH {points}\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS {points}\nDATA {data}\n"
        )
        .into_bytes()
    }

    fn is_header_error_at(r: Result<PointCloud>, line: usize) -> bool {
        matches!(r, Err(CloudError::Header { at: Location::Line(l), .. }) if l == line)
    }

    #[test]
    fn width_height_and_points_follow_pcl() {
        let body = "DATA ascii\n1 2 3\n4 5 6\n";
        let ok = |name: &str, head: &str| {
            let c = read(
                name,
                format!("FIELDS x y z\nSIZE 4 4 4\nTYPE F F F\n{head}{body}").as_bytes(),
            )
            .unwrap_or_else(|e| panic!("{head:?}: {e}"));
            assert_eq!(c.len(), 2, "{head:?}");
        };
        // No HEIGHT: one row; no WIDTH either: WIDTH = POINTS; HEIGHT 2 × WIDTH 1 (organized).
        ok("h1.pcd", "POINTS 2\n");
        ok("h2.pcd", "WIDTH 2\nPOINTS 2\n");
        ok("h3.pcd", "WIDTH 0\nPOINTS 2\n");
        ok("h4.pcd", "WIDTH 1\nHEIGHT 2\nPOINTS 2\n");
        let bad = |name: &str, head: &str, line: usize| {
            let r = read(
                name,
                format!("FIELDS x y z\nSIZE 4 4 4\nTYPE F F F\n{head}{body}").as_bytes(),
            );
            assert!(is_header_error_at(r, line), "{head:?}");
        };
        bad("b1.pcd", "WIDTH 3\nHEIGHT 1\nPOINTS 2\n", 6);
        // HEIGHT without WIDTH, and no POINTS line (PCL counts 0 points then).
        bad("b2.pcd", "HEIGHT 2\nPOINTS 2\n", 5);
        bad("b3.pcd", "WIDTH 2\nHEIGHT 1\n", 6);
        // An empty cloud is fine.
        let c = read(
            "e.pcd",
            b"FIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nWIDTH 0\nHEIGHT 0\nPOINTS 0\nDATA binary\n",
        )
        .unwrap();
        assert!(c.is_empty());
    }

    #[test]
    fn pcl_types_counts_and_padding_fields() {
        // Lower-case types, U8/I8/B1/F8, a COUNT 0 field (dropped), a descriptor array and
        // a `_` padding field in ASCII (PCL skips its values), blank lines, no final newline.
        let mut b = header(
            "x y z flag big neg gone desc _ intensity",
            "8 8 8 1 8 8 4 4 1 2",
            "f F f b U i F F U u",
            "1 1 1 1 1 1 0 3 2 1",
            "2",
            "ascii",
        );
        b.extend_from_slice(b"\n1.5 -2 3 1 18446744073709551615 -9 0.1 0.2 0.3 7 7 65535\n\n  \n4 5 6 0 0 0 0 0 0 0 0 12");
        let c = read("t.pcd", &b).unwrap();
        assert_eq!(c.positions, vec![[1.5, -2.0, 3.0], [4.0, 5.0, 6.0]]);
        assert_eq!(c.precision, Precision::F64);
        assert_eq!(c.intensity, Some(vec![65535.0, 12.0]));
        // TYPE/SIZE pairs PCL has no type for.
        for (size, ty) in [("2", "F"), ("3", "U"), ("2", "B"), ("4", "X")] {
            let b = header(
                "x y z",
                &format!("4 4 {size}"),
                &format!("F F {ty}"),
                "1 1 1",
                "0",
                "ascii",
            );
            assert!(is_header_error_at(read("ty.pcd", &b), 5), "{size} {ty}");
        }
        // A coordinate with COUNT 3, and no z at all.
        let b = header("x y z", "4 4 4", "F F F", "1 1 3", "0", "ascii");
        assert!(is_header_error_at(read("c3.pcd", &b), 6));
        let b = header("x y intensity", "4 4 4", "F F F", "1 1 1", "0", "ascii");
        let e = read("noz.pcd", &b).unwrap_err();
        assert!(
            e.to_string().contains("line 3: bad header: no field z"),
            "{e}"
        );
    }

    #[test]
    fn binary_padding_fields_take_their_bytes() {
        // PCL's binary writer pads PointXYZ to 16 bytes with `_`: x y z _ (4 × U1).
        let mut b = header(
            "x y z _ rgb",
            "4 4 4 1 4",
            "F F F U F",
            "1 1 1 4 1",
            "2",
            "binary",
        );
        for (p, rgb) in [
            ([1.0f32, 2.0, 3.0], 0x00ff_8001u32),
            ([-1.0, 0.5, 8.0], 0x0001_0203),
        ] {
            for v in p {
                b.extend_from_slice(&v.to_le_bytes());
            }
            b.extend_from_slice(&[9, 9, 9, 9]);
            b.extend_from_slice(&rgb.to_le_bytes());
        }
        b.extend_from_slice(&[0; 100]); // PCL's page padding
        let c = read("pad.pcd", &b).unwrap();
        assert_eq!(c.positions, vec![[1.0, 2.0, 3.0], [-1.0, 0.5, 8.0]]);
        assert_eq!(c.rgb, Some(vec![[0xff, 0x80, 0x01], [1, 2, 3]]));
        // rgba as I4 with alpha 255 (negative), and as the bits of an F4 that are a
        // signalling NaN (0x7f8a0b0c: red 0x8a).
        let mut b = header("x y z rgba", "4 4 4 4", "F F F I", "1 1 1 1", "1", "binary");
        b.extend_from_slice(&[0; 12]);
        b.extend_from_slice(&0xff10_2030u32.to_le_bytes());
        assert_eq!(
            read("i4.pcd", &b).unwrap().rgb,
            Some(vec![[0x10, 0x20, 0x30]])
        );
        let mut b = header("x y z rgb", "4 4 4 4", "F F F F", "1 1 1 1", "1", "binary");
        b.extend_from_slice(&[0; 12]);
        b.extend_from_slice(&0x7f8a_0b0cu32.to_le_bytes());
        assert_eq!(
            read("snan.pcd", &b).unwrap().rgb,
            Some(vec![[0x8a, 0x0b, 0x0c]])
        );
    }

    /// A `binary_compressed` body holding `columns` (already column-major) for `points` points.
    fn compressed(head: Vec<u8>, columns: &[u8], raw_len: u32) -> Vec<u8> {
        let packed = super::super::lzf::compress(columns);
        let mut b = head;
        b.extend_from_slice(&(packed.len() as u32).to_le_bytes());
        b.extend_from_slice(&raw_len.to_le_bytes());
        b.extend_from_slice(&packed);
        b
    }

    #[test]
    fn compressed_columns_skip_padding_and_keep_counts_together() {
        // x y z, a `_` pad (absent from compressed data), normal (COUNT 3), label U4 (PCL's
        // PointXYZL: a dataset id, kept as raw_label).
        let head = header(
            "x y z _ normal label",
            "4 4 4 1 4 4",
            "F F F U F U",
            "1 1 1 4 3 1",
            "2",
            "binary_compressed",
        );
        let mut cols = Vec::new();
        for v in [1.0f32, 2.0, 10.0, 20.0, 100.0, 200.0] {
            cols.extend_from_slice(&v.to_le_bytes());
        }
        for v in [0.0f32, 0.0, 1.0, 0.0, 1.0, 0.0] {
            cols.extend_from_slice(&v.to_le_bytes());
        }
        for v in [42u32, 7] {
            cols.extend_from_slice(&v.to_le_bytes());
        }
        assert_eq!(cols.len(), 2 * (12 + 12 + 4));
        let mut b = compressed(head.clone(), &cols, cols.len() as u32);
        b.extend_from_slice(&[0xAB; 3000]); // PCL's page padding
        let c = read("cc.pcd", &b).unwrap();
        assert_eq!(c.positions, vec![[1.0, 10.0, 100.0], [2.0, 20.0, 200.0]]);
        assert_eq!(c.raw_label, Some(vec![42, 7]));
        assert_eq!(c.label, None);
        // The size with padding (2 × 32 bytes) is not PCL's layout.
        let b = compressed(head, &cols, 64);
        assert!(matches!(
            read("cc64.pcd", &b),
            Err(CloudError::BadValue { .. })
        ));
    }

    #[test]
    fn non_finite_points_of_organized_clouds_are_reported_not_lost() {
        // PCL marks the invalid points of an organized cloud with NaN coordinates.
        let mut b = b"VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH 2\nHEIGHT 2\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS 4\nDATA binary\n".to_vec();
        for p in [
            [1.0f32, 2.0, 3.0],
            [f32::NAN; 3],
            [4.0, 5.0, 6.0],
            [f32::NAN, 0.0, 1.0],
        ] {
            for v in p {
                b.extend_from_slice(&v.to_le_bytes());
            }
        }
        let e = read("org.pcd", &b).unwrap_err();
        assert!(matches!(e, CloudError::NonFinite { point: 1, .. }), "{e}");
        let (c, report) = read_bytes(
            "org.pcd",
            &b,
            &ReadOptions {
                drop_non_finite: true,
            },
        )
        .unwrap();
        assert_eq!(c.positions, vec![[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]]);
        assert_eq!((report.points_in_file, report.dropped_non_finite), (4, 2));
        // The same in ASCII, where PCL writes `nan`.
        let text = b"FIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nWIDTH 1\nHEIGHT 2\nPOINTS 2\nDATA ascii\nnan nan nan\n1 2 3\n";
        let (c, report) = read_bytes(
            "org.pcd",
            text,
            &ReadOptions {
                drop_non_finite: true,
            },
        )
        .unwrap();
        assert_eq!(
            (c.len(), report.points_in_file, report.dropped_non_finite),
            (1, 2, 1)
        );
    }

    #[test]
    fn inflated_counts_and_truncated_bodies_are_errors() {
        // Each must return at once with an error, never allocate for or loop over the count.
        let big = "99999999999";
        let b = header("x y z", "4 4 4", "F F F", "1 1 1", big, "ascii");
        let mut a = b.clone();
        a.extend_from_slice(b"1 2 3\n");
        assert!(is_header_error_at(read("ia.pcd", &a), 10));
        let mut bin = header("x y z", "4 4 4", "F F F", "1 1 1", big, "binary");
        bin.extend_from_slice(&[0; 12 * 3]);
        match read("ib.pcd", &bin) {
            Err(CloudError::Truncated {
                at: Location::Byte(at),
                point: 3,
                expected,
                ..
            }) => {
                assert_eq!(at, bin.len() as u64);
                assert_eq!(expected, 99_999_999_999);
            }
            other => panic!("{other:?}"),
        }
        // POINTS × WIDTH overflowing, and a COUNT whose bytes overflow.
        let b = header(
            "x y z",
            "4 4 4",
            "F F F",
            "1 1 1",
            "18446744073709551615",
            "binary",
        );
        assert!(read("io.pcd", &b).is_err());
        let b = header(
            "x y z d",
            "4 4 4 8",
            "F F F F",
            "1 1 1 18446744073709551615",
            "1",
            "binary",
        );
        assert!(is_header_error_at(read("ic.pcd", &b), 6));
        // binary_compressed: an uncompressed size of 0xFFFFFFFF, a POINTS matching it, and a
        // compressed size of 0xFFFFFFFF.
        let mut c = header("x y z", "4 4 4", "F F F", "1 1 1", "1", "binary_compressed");
        c.extend_from_slice(&16u32.to_le_bytes());
        c.extend_from_slice(&u32::MAX.to_le_bytes());
        c.extend_from_slice(&[0; 16]);
        assert!(matches!(
            read("ic1.pcd", &c),
            Err(CloudError::BadValue { .. })
        ));
        // 357913941 points × 12 bytes = 0xFFFFFFFC bytes from a 16-byte block.
        let mut c = header(
            "x y z",
            "4 4 4",
            "F F F",
            "1 1 1",
            "357913941",
            "binary_compressed",
        );
        c.extend_from_slice(&16u32.to_le_bytes());
        c.extend_from_slice(&0xFFFF_FFFCu32.to_le_bytes());
        c.extend_from_slice(&[0; 16]);
        match read("ic2.pcd", &c) {
            Err(CloudError::BadValue { field, .. }) => assert_eq!(field, "compressed size"),
            other => panic!("{other:?}"),
        }
        let mut c = header("x y z", "4 4 4", "F F F", "1 1 1", "1", "binary_compressed");
        c.extend_from_slice(&u32::MAX.to_le_bytes());
        c.extend_from_slice(&12u32.to_le_bytes());
        c.extend_from_slice(&[0; 16]);
        match read("ic3.pcd", &c) {
            Err(CloudError::BadValue { field, .. }) => assert_eq!(field, "compressed size"),
            other => panic!("{other:?}"),
        }
        // Truncated: a binary point cut, a compressed body without its sizes, an ASCII line
        // missing (named with the line where the data ran out).
        let mut t = header("x y z", "4 4 4", "F F F", "1 1 1", "2", "binary");
        t.extend_from_slice(&[0; 20]);
        assert!(matches!(
            read("t1.pcd", &t),
            Err(CloudError::Truncated { point: 1, .. })
        ));
        let mut t = header("x y z", "4 4 4", "F F F", "1 1 1", "2", "binary_compressed");
        t.extend_from_slice(&[0; 5]);
        assert!(matches!(
            read("t2.pcd", &t),
            Err(CloudError::Truncated { .. })
        ));
        let mut t = header("x y z", "4 4 4", "F F F", "1 1 1", "3", "ascii");
        t.extend_from_slice(b"1.0 2.0 3.0\n4.0 5.0 6.0\n");
        match read("t3.pcd", &t) {
            Err(CloudError::Truncated {
                at: Location::Line(14),
                point: 2,
                expected: 3,
                ..
            }) => {}
            other => panic!("{other:?}"),
        }
        // A header cut before DATA.
        let t = header("x y z", "4 4 4", "F F F", "1 1 1", "3", "ascii");
        assert!(is_header_error_at(read("t4.pcd", &t[..t.len() - 3]), 11));
    }

    #[test]
    fn ascii_lines_with_the_wrong_number_of_values_are_named() {
        let mut b = header("x y z", "4 4 4", "F F F", "1 1 1", "2", "ascii");
        b.extend_from_slice(b"1.0 2.0 3.0\n4.5 5.5\n");
        let e = read("short.pcd", &b).unwrap_err();
        assert!(
            matches!(
                e,
                CloudError::BadValue {
                    at: Location::Line(13),
                    ..
                }
            ),
            "{e}"
        );
        let mut b = header("x y z", "4 4 4", "F F F", "1 1 1", "1", "ascii");
        b.extend_from_slice(b"1 2 3 4\n");
        let e = read("long.pcd", &b).unwrap_err();
        assert!(e.to_string().contains("more than the 3 values"), "{e}");
    }
}
