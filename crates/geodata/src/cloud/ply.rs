//! Stanford PLY: ascii, binary_little_endian and binary_big_endian, streaming.
//!
//! The `vertex` element's properties `x y z` (float or double, any numeric type accepted),
//! `intensity` (or `reflectance`/`scalar_intensity`), `red green blue`, `label`,
//! `raw_label` and `object` fill the cloud's columns. Unknown properties (scalar or list)
//! are skipped by their declared type, and other elements (`face`, `edge`, …) before or
//! after `vertex` are read through and discarded, so the byte offsets stay right.
//! Reference: Greg Turk, "The PLY Polygon File Format" (1994). Checked against files written
//! by another library, `plyfile` (`scripts/ply_interop.py`, and the byte-exact headers in this
//! module's tests).
//!
//! Time is linear in the file. Before anything is allocated or looped over for a header count,
//! the counts are checked against the bytes after the header: an instance takes at least the
//! sizes of its scalars and list counts (binary) or two bytes per property (ASCII).

use super::{
    io_err, path_buf, read_full, read_point_line, CloudError, Encoding, Location, PointCloud,
    PointRecord,
};
use super::{write_ascii_position, Columns, Precision, ReadOptions, ReadReport, Result, Sink};
use crate::fsio::AtomicFile;
use std::fs::File;
use std::io::{BufRead, BufReader, Read, Write};
use std::path::Path;

/// Longest header line accepted, bytes (a garbled binary header must not eat memory).
const MAX_HEADER_LINE: usize = 4096;
/// Most header lines accepted.
const MAX_HEADER_LINES: usize = 10_000;

/// A numeric type of PLY (and, shared, of PCD).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Scalar {
    I8,
    U8,
    I16,
    U16,
    I32,
    U32,
    I64,
    U64,
    F32,
    F64,
}

impl Scalar {
    fn from_ply(name: &str) -> Option<Scalar> {
        Some(match name {
            "char" | "int8" => Scalar::I8,
            "uchar" | "uint8" => Scalar::U8,
            "short" | "int16" => Scalar::I16,
            "ushort" | "uint16" => Scalar::U16,
            "int" | "int32" => Scalar::I32,
            "uint" | "uint32" => Scalar::U32,
            "float" | "float32" => Scalar::F32,
            "double" | "float64" => Scalar::F64,
            _ => return None,
        })
    }

    /// Size in bytes.
    pub(crate) fn size(self) -> usize {
        match self {
            Scalar::I8 | Scalar::U8 => 1,
            Scalar::I16 | Scalar::U16 => 2,
            Scalar::I32 | Scalar::U32 | Scalar::F32 => 4,
            Scalar::I64 | Scalar::U64 | Scalar::F64 => 8,
        }
    }

    /// Decodes `bytes` (exactly `size()` long; missing bytes read as 0) to f64; exact for
    /// every type but 64-bit integers beyond 2⁵³.
    #[inline]
    pub(crate) fn decode(self, bytes: &[u8], big_endian: bool) -> f64 {
        #[inline(always)]
        fn arr<const N: usize>(b: &[u8]) -> [u8; N] {
            let mut a = [0u8; N];
            if let Some(s) = b.get(..N) {
                a.copy_from_slice(s);
            }
            a
        }
        macro_rules! num {
            ($t:ty, $n:expr) => {{
                let a = arr::<$n>(bytes);
                if big_endian {
                    <$t>::from_be_bytes(a)
                } else {
                    <$t>::from_le_bytes(a)
                }
            }};
        }
        match self {
            Scalar::I8 => f64::from(num!(i8, 1)),
            Scalar::U8 => f64::from(num!(u8, 1)),
            Scalar::I16 => f64::from(num!(i16, 2)),
            Scalar::U16 => f64::from(num!(u16, 2)),
            Scalar::I32 => f64::from(num!(i32, 4)),
            Scalar::U32 => f64::from(num!(u32, 4)),
            Scalar::F32 => f64::from(num!(f32, 4)),
            Scalar::I64 => num!(i64, 8) as f64,
            Scalar::U64 => num!(u64, 8) as f64,
            Scalar::F64 => num!(f64, 8),
        }
    }

    /// Parses a text token of this type to f64, checking the integer range.
    pub(crate) fn parse(self, token: &str) -> Option<f64> {
        let int = |lo: i64, hi: i64| {
            token
                .parse::<i64>()
                .ok()
                .filter(|v| (lo..=hi).contains(v))
                .map(|v| v as f64)
        };
        match self {
            Scalar::I8 => int(i64::from(i8::MIN), i64::from(i8::MAX)),
            Scalar::U8 => int(0, i64::from(u8::MAX)),
            Scalar::I16 => int(i64::from(i16::MIN), i64::from(i16::MAX)),
            Scalar::U16 => int(0, i64::from(u16::MAX)),
            Scalar::I32 => int(i64::from(i32::MIN), i64::from(i32::MAX)),
            Scalar::U32 => int(0, i64::from(u32::MAX)),
            Scalar::I64 => token.parse::<i64>().ok().map(|v| v as f64),
            Scalar::U64 => token.parse::<u64>().ok().map(|v| v as f64),
            Scalar::F32 => token.parse::<f32>().ok().map(f64::from),
            Scalar::F64 => token.parse::<f64>().ok(),
        }
    }
}

/// Which column a property fills.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Role {
    X,
    Y,
    Z,
    Intensity,
    Red,
    Green,
    Blue,
    Label,
    RawLabel,
    Object,
    Skip,
}

impl Role {
    pub(crate) fn from_name(name: &str) -> Role {
        match name {
            "x" => Role::X,
            "y" => Role::Y,
            "z" => Role::Z,
            "intensity" | "reflectance" | "scalar_intensity" => Role::Intensity,
            "red" | "r" => Role::Red,
            "green" | "g" => Role::Green,
            "blue" | "b" => Role::Blue,
            "label" => Role::Label,
            "raw_label" => Role::RawLabel,
            "object" => Role::Object,
            _ => Role::Skip,
        }
    }
}

/// Stores a decoded value into the record field of `role`, checking its range.
#[inline]
pub(crate) fn assign(
    rec: &mut PointRecord,
    role: Role,
    value: f64,
    path: &Path,
    at: Location,
    field: &str,
) -> Result<()> {
    let bad = || CloudError::BadValue {
        path: path_buf(path),
        at,
        field: field.to_string(),
        value: value.to_string(),
    };
    let int_in = |hi: f64| value.fract() == 0.0 && (0.0..=hi).contains(&value);
    match role {
        Role::X => rec.position[0] = value,
        Role::Y => rec.position[1] = value,
        Role::Z => rec.position[2] = value,
        Role::Intensity => rec.intensity = value as f32,
        Role::Red | Role::Green | Role::Blue => {
            if !int_in(255.0) {
                return Err(bad());
            }
            let k = match role {
                Role::Red => 0,
                Role::Green => 1,
                _ => 2,
            };
            rec.rgb[k] = value as u8;
        }
        Role::Label => {
            if !int_in(255.0) {
                return Err(bad());
            }
            rec.label = value as u8;
        }
        Role::RawLabel | Role::Object => {
            if !int_in(f64::from(u32::MAX)) {
                return Err(bad());
            }
            if role == Role::Object {
                rec.object = value as u32;
            } else {
                rec.raw_label = value as u32;
            }
        }
        Role::Skip => {}
    }
    Ok(())
}

#[derive(Debug, Clone)]
enum Kind {
    Scalar(Scalar),
    List { count: Scalar, item: Scalar },
}

#[derive(Debug, Clone)]
struct Prop {
    name: String,
    kind: Kind,
    role: Role,
}

#[derive(Debug, Clone)]
struct Element {
    name: String,
    count: usize,
    props: Vec<Prop>,
    /// Header line of its `element` keyword.
    line: usize,
}

impl Element {
    /// Fewest bytes one instance takes: binary, the sum of its scalar sizes and list count
    /// sizes (an empty list adds nothing); ASCII, one character and a separator per property,
    /// or the newline of an empty line.
    fn min_bytes(&self, format: PlyFormat) -> u64 {
        match format {
            PlyFormat::Binary { .. } => self
                .props
                .iter()
                .map(|p| match p.kind {
                    Kind::Scalar(s) | Kind::List { count: s, .. } => s.size() as u64,
                })
                .sum(),
            PlyFormat::Ascii => (2 * self.props.len() as u64).max(1),
        }
    }

    /// Whether every instance has the same binary size (no list property).
    fn is_fixed(&self) -> bool {
        self.props.iter().all(|p| matches!(p.kind, Kind::Scalar(_)))
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum PlyFormat {
    Ascii,
    Binary { big_endian: bool },
}

struct Header {
    format: PlyFormat,
    elements: Vec<Element>,
    /// Bytes up to and including `end_header\n`.
    len: u64,
    /// Lines in the header.
    lines: usize,
}

fn header_err(path: &Path, line: usize, message: impl Into<String>) -> CloudError {
    CloudError::Header {
        path: path_buf(path),
        at: Location::Line(line),
        message: message.into(),
    }
}

fn read_header(path: &Path, r: &mut impl BufRead) -> Result<Header> {
    let mut buf = Vec::new();
    let mut len = 0u64;
    let mut format = None;
    let mut elements: Vec<Element> = Vec::new();
    for line_no in 1..=MAX_HEADER_LINES {
        buf.clear();
        let n = r
            .by_ref()
            .take(MAX_HEADER_LINE as u64 + 1)
            .read_until(b'\n', &mut buf)
            .map_err(io_err(path))?;
        if n == 0 {
            return Err(header_err(path, line_no, "file ends before end_header"));
        }
        if buf.last() != Some(&b'\n') {
            return Err(header_err(
                path,
                line_no,
                format!(
                    "header line longer than {MAX_HEADER_LINE} bytes or file ends in the header"
                ),
            ));
        }
        len += n as u64;
        let text = std::str::from_utf8(&buf)
            .map_err(|_| header_err(path, line_no, "header line is not UTF-8"))?
            .trim_end_matches(['\n', '\r']);
        if line_no == 1 {
            if text.trim() != "ply" {
                return Err(header_err(
                    path,
                    1,
                    format!("expected \"ply\", found {text:?}"),
                ));
            }
            continue;
        }
        let mut tok = text.split_whitespace();
        match tok.next() {
            None | Some("comment") | Some("obj_info") => {}
            Some("format") => {
                let f = match tok.next() {
                    Some("ascii") => PlyFormat::Ascii,
                    Some("binary_little_endian") => PlyFormat::Binary { big_endian: false },
                    Some("binary_big_endian") => PlyFormat::Binary { big_endian: true },
                    other => {
                        return Err(header_err(
                            path,
                            line_no,
                            format!("unknown format {other:?}; expected ascii, binary_little_endian or binary_big_endian"),
                        ))
                    }
                };
                if tok.next() != Some("1.0") {
                    return Err(header_err(path, line_no, "expected format version 1.0"));
                }
                format = Some(f);
            }
            Some("element") => {
                let (Some(name), Some(count)) = (tok.next(), tok.next()) else {
                    return Err(header_err(path, line_no, "expected \"element NAME COUNT\""));
                };
                let count = count.parse::<usize>().map_err(|_| {
                    header_err(path, line_no, format!("bad element count {count:?}"))
                })?;
                elements.push(Element {
                    name: name.to_string(),
                    count,
                    props: Vec::new(),
                    line: line_no,
                });
            }
            Some("property") => {
                let words: Vec<&str> = tok.collect();
                let ty = |s: &str| {
                    Scalar::from_ply(s).ok_or_else(|| {
                        header_err(path, line_no, format!("unknown property type {s:?}"))
                    })
                };
                let (kind, name) = match words.as_slice() {
                    ["list", count, item, name] => (
                        Kind::List {
                            count: ty(count)?,
                            item: ty(item)?,
                        },
                        *name,
                    ),
                    [t, name] => (Kind::Scalar(ty(t)?), *name),
                    _ => {
                        return Err(header_err(
                            path,
                            line_no,
                            "expected \"property TYPE NAME\" or \"property list COUNT_TYPE ITEM_TYPE NAME\"",
                        ))
                    }
                };
                let Some(element) = elements.last_mut() else {
                    return Err(header_err(path, line_no, "property before any element"));
                };
                let mut role = if element.name == "vertex" {
                    Role::from_name(name)
                } else {
                    Role::Skip
                };
                if matches!(kind, Kind::List { .. }) {
                    role = Role::Skip;
                }
                if role != Role::Skip && element.props.iter().any(|p| p.role == role) {
                    return Err(header_err(
                        path,
                        line_no,
                        format!("duplicate property {name:?}"),
                    ));
                }
                element.props.push(Prop {
                    name: name.to_string(),
                    kind,
                    role,
                });
            }
            Some("end_header") => {
                let format = format
                    .ok_or_else(|| header_err(path, line_no, "no format line before end_header"))?;
                let Some(vertex) = elements.iter().find(|e| e.name == "vertex") else {
                    return Err(header_err(path, line_no, "no vertex element"));
                };
                for (role, axis) in [(Role::X, "x"), (Role::Y, "y"), (Role::Z, "z")] {
                    if !vertex.props.iter().any(|p| p.role == role) {
                        return Err(header_err(
                            path,
                            line_no,
                            format!("vertex has no {axis} property"),
                        ));
                    }
                }
                if elements.iter().filter(|e| e.name == "vertex").count() > 1 {
                    return Err(header_err(path, line_no, "more than one vertex element"));
                }
                return Ok(Header {
                    format,
                    elements,
                    len,
                    lines: line_no,
                });
            }
            Some(other) => {
                return Err(header_err(
                    path,
                    line_no,
                    format!("unknown header keyword {other:?}"),
                ))
            }
        }
    }
    Err(header_err(
        path,
        MAX_HEADER_LINES,
        format!("no end_header within {MAX_HEADER_LINES} lines"),
    ))
}

fn columns_of(vertex: &Element) -> (Columns, Precision) {
    let has = |r: Role| vertex.props.iter().any(|p| p.role == r);
    let columns = Columns {
        intensity: has(Role::Intensity),
        rgb: has(Role::Red) || has(Role::Green) || has(Role::Blue),
        label: has(Role::Label),
        raw_label: has(Role::RawLabel),
        object: has(Role::Object),
    };
    let double = vertex
        .props
        .iter()
        .filter(|p| matches!(p.role, Role::X | Role::Y | Role::Z))
        .any(|p| !matches!(p.kind, Kind::Scalar(Scalar::F32)));
    let precision = if double {
        Precision::F64
    } else {
        Precision::F32
    };
    (columns, precision)
}

/// Reads a PLY file (any of the three encodings).
pub fn read_ply(path: &Path, options: &ReadOptions) -> Result<(PointCloud, ReadReport)> {
    let file = File::open(path).map_err(io_err(path))?;
    let file_len = file.metadata().map_err(io_err(path))?.len();
    let mut r = BufReader::with_capacity(1 << 16, file);
    let header = read_header(path, &mut r)?;
    let vertex_count = header
        .elements
        .iter()
        .find(|e| e.name == "vertex")
        .map_or(0, |e| e.count);
    let Some(vertex) = header.elements.iter().find(|e| e.name == "vertex") else {
        return Err(header_err(path, header.lines, "no vertex element"));
    };
    let (columns, precision) = columns_of(vertex);
    let body = file_len.saturating_sub(header.len);
    check_counts(path, &header, body)?;
    // The check bounds the count by the file; a point still takes at least 1 byte.
    let capacity = vertex_count.min(usize::try_from(body).unwrap_or(0));
    let mut sink = Sink::new(
        path,
        PointCloud::with_columns(columns, precision, capacity),
        options,
    );
    match header.format {
        PlyFormat::Binary { big_endian } => {
            read_binary_body(path, &mut r, &header, big_endian, &mut sink)?
        }
        PlyFormat::Ascii => read_ascii_body(path, &mut r, &header, &mut sink)?,
    }
    Ok(sink.finish())
}

/// Checks every element count against the bytes after the header, before anything is
/// allocated or looped over for it: each instance takes at least [`Element::min_bytes`].
///
/// While the elements so far, and the one short of bytes, have fixed-size instances, a
/// shortfall is [`CloudError::Truncated`] at the exact byte where the data ends (as reading
/// would say); once a list is involved offsets are only bounds, and it is a header error
/// naming the element's line.
fn check_counts(path: &Path, header: &Header, body: u64) -> Result<()> {
    let mut left = body;
    let mut offset = header.len;
    let mut exact = true;
    for e in &header.elements {
        let min = e.min_bytes(header.format);
        let need = (e.count as u64).checked_mul(min);
        let Some(need) = need.filter(|&need| need <= left) else {
            let binary = matches!(header.format, PlyFormat::Binary { .. });
            if binary && exact && e.is_fixed() && min > 0 {
                let whole = left / min;
                return Err(CloudError::Truncated {
                    path: path_buf(path),
                    at: Location::Byte(offset + whole * min),
                    point: usize::try_from(whole).unwrap_or(usize::MAX),
                    expected: e.count,
                });
            }
            return Err(header_err(
                path,
                e.line,
                format!(
                    "element {} {} takes at least {min} bytes per instance, but only {left} \
                     bytes are left for it; the file is truncated or the count is wrong",
                    e.name, e.count
                ),
            ));
        };
        left -= need;
        offset += need;
        exact &= e.is_fixed();
    }
    Ok(())
}

fn read_binary_body(
    path: &Path,
    r: &mut impl BufRead,
    header: &Header,
    big_endian: bool,
    sink: &mut Sink,
) -> Result<()> {
    let mut offset = header.len;
    let mut buf = vec![0u8; 64];
    for element in &header.elements {
        // An element without properties takes no bytes, whatever its count.
        if element.props.is_empty() {
            continue;
        }
        let is_vertex = element.name == "vertex";
        let fixed: Option<usize> = element
            .props
            .iter()
            .map(|p| match p.kind {
                Kind::Scalar(s) => Some(s.size()),
                Kind::List { .. } => None,
            })
            .sum();
        if let Some(size) = fixed {
            buf.resize(size.max(8), 0);
        }
        for i in 0..element.count {
            let start = offset;
            let truncated = || CloudError::Truncated {
                path: path_buf(path),
                at: Location::Byte(start),
                point: i,
                expected: element.count,
            };
            let mut rec = PointRecord::default();
            if let Some(size) = fixed {
                if !read_full(r, &mut buf[..size]).map_err(io_err(path))? {
                    return Err(truncated());
                }
                offset += size as u64;
                if is_vertex {
                    let mut at = 0usize;
                    for p in &element.props {
                        if let Kind::Scalar(s) = p.kind {
                            let end = at + s.size();
                            if p.role != Role::Skip {
                                let v = s.decode(buf.get(at..end).unwrap_or(&[]), big_endian);
                                assign(
                                    &mut rec,
                                    p.role,
                                    v,
                                    path,
                                    Location::Byte(start + at as u64),
                                    &p.name,
                                )?;
                            }
                            at = end;
                        }
                    }
                }
            } else {
                for p in &element.props {
                    match p.kind {
                        Kind::Scalar(s) => {
                            let b = &mut buf[..s.size()];
                            if !read_full(r, b).map_err(io_err(path))? {
                                return Err(truncated());
                            }
                            let v = s.decode(b, big_endian);
                            if is_vertex {
                                assign(&mut rec, p.role, v, path, Location::Byte(offset), &p.name)?;
                            }
                            offset += s.size() as u64;
                        }
                        Kind::List { count, item } => {
                            let b = &mut buf[..count.size()];
                            if !read_full(r, b).map_err(io_err(path))? {
                                return Err(truncated());
                            }
                            let n = count.decode(b, big_endian);
                            if !(n >= 0.0 && n.fract() == 0.0 && n <= 1e9) {
                                return Err(CloudError::BadValue {
                                    path: path_buf(path),
                                    at: Location::Byte(offset),
                                    field: format!("{} (list length)", p.name),
                                    value: n.to_string(),
                                });
                            }
                            offset += count.size() as u64;
                            let skip = n as u64 * item.size() as u64;
                            let got =
                                std::io::copy(&mut r.by_ref().take(skip), &mut std::io::sink())
                                    .map_err(io_err(path))?;
                            if got < skip {
                                return Err(truncated());
                            }
                            offset += skip;
                        }
                    }
                }
            }
            if is_vertex {
                sink.push(&rec)?;
            }
        }
    }
    let mut rest = [0u8; 1];
    if r.read(&mut rest).map_err(io_err(path))? > 0 {
        let extra = 1 + std::io::copy(r, &mut std::io::sink()).map_err(io_err(path))?;
        return Err(CloudError::TrailingData {
            path: path_buf(path),
            at: Location::Byte(offset),
            extra,
        });
    }
    Ok(())
}

fn read_ascii_body(
    path: &Path,
    r: &mut impl BufRead,
    header: &Header,
    sink: &mut Sink,
) -> Result<()> {
    let mut line = String::new();
    let mut line_no = header.lines;
    for element in &header.elements {
        let is_vertex = element.name == "vertex";
        for i in 0..element.count {
            line_no += 1;
            read_point_line(
                &mut *r,
                &mut line,
                path,
                line_no,
                &element.name,
                i,
                element.count,
            )?;
            let at = Location::Line(line_no);
            let mut tokens = line.split_whitespace();
            let mut next = |field: &str, ty: Scalar| -> Result<f64> {
                let tok = tokens.next().ok_or_else(|| CloudError::BadValue {
                    path: path_buf(path),
                    at,
                    field: field.to_string(),
                    value: "missing (line too short)".into(),
                })?;
                ty.parse(tok).ok_or_else(|| CloudError::BadValue {
                    path: path_buf(path),
                    at,
                    field: field.to_string(),
                    value: tok.to_string(),
                })
            };
            let mut rec = PointRecord::default();
            for p in &element.props {
                match p.kind {
                    Kind::Scalar(s) => {
                        let v = next(&p.name, s)?;
                        if is_vertex {
                            assign(&mut rec, p.role, v, path, at, &p.name)?;
                        }
                    }
                    Kind::List { count, item } => {
                        let n = next(&p.name, count)?;
                        if n < 0.0 {
                            return Err(CloudError::BadValue {
                                path: path_buf(path),
                                at,
                                field: format!("{} (list length)", p.name),
                                value: n.to_string(),
                            });
                        }
                        for _ in 0..(n as u64) {
                            next(&p.name, item)?;
                        }
                    }
                }
            }
            if let Some(extra) = tokens.next() {
                return Err(CloudError::BadValue {
                    path: path_buf(path),
                    at,
                    field: format!("{} (end of line)", element.name),
                    value: extra.to_string(),
                });
            }
            if is_vertex {
                sink.push(&rec)?;
            }
        }
    }
    loop {
        line.clear();
        line_no += 1;
        if r.read_line(&mut line).map_err(io_err(path))? == 0 {
            return Ok(());
        }
        if !line.trim().is_empty() {
            return Err(CloudError::TrailingData {
                path: path_buf(path),
                at: Location::Line(line_no),
                extra: line.len() as u64,
            });
        }
    }
}

/// Writes a PLY file: `vertex` with x y z (float or double by the cloud's precision) and
/// one property per present column.
pub fn write_ply(path: &Path, cloud: &PointCloud, encoding: Encoding) -> Result<()> {
    cloud.check_columns()?;
    let mut w = AtomicFile::create(path).map_err(io_err(path))?;
    write_ply_to(&mut w, cloud, encoding).map_err(io_err(path))?;
    w.commit().map_err(io_err(path))
}

fn write_ply_to(w: &mut impl Write, cloud: &PointCloud, encoding: Encoding) -> std::io::Result<()> {
    let c = cloud.columns();
    let fmt = match encoding {
        Encoding::Ascii => "ascii",
        Encoding::BinaryLittleEndian | Encoding::BinaryCompressed => "binary_little_endian",
        Encoding::BinaryBigEndian => "binary_big_endian",
    };
    let xyz = match cloud.precision {
        Precision::F32 => "float",
        Precision::F64 => "double",
    };
    writeln!(w, "ply\nformat {fmt} 1.0\ncomment urbansem point cloud")?;
    writeln!(w, "element vertex {}", cloud.len())?;
    for a in ["x", "y", "z"] {
        writeln!(w, "property {xyz} {a}")?;
    }
    if c.intensity {
        writeln!(w, "property float intensity")?;
    }
    if c.rgb {
        writeln!(
            w,
            "property uchar red\nproperty uchar green\nproperty uchar blue"
        )?;
    }
    if c.label {
        writeln!(w, "property uchar label")?;
    }
    if c.raw_label {
        writeln!(w, "property uint raw_label")?;
    }
    if c.object {
        writeln!(w, "property uint object")?;
    }
    writeln!(w, "end_header")?;
    let be = encoding == Encoding::BinaryBigEndian;
    let mut rec = Vec::with_capacity(64);
    for i in 0..cloud.len() {
        let Some(p) = cloud.get(i) else { break };
        if encoding == Encoding::Ascii {
            write_ascii_position(w, cloud.precision, p.position)?;
            if c.intensity {
                write!(w, " {}", p.intensity)?;
            }
            if c.rgb {
                write!(w, " {} {} {}", p.rgb[0], p.rgb[1], p.rgb[2])?;
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
        macro_rules! put {
            ($v:expr) => {
                if be {
                    rec.extend_from_slice(&$v.to_be_bytes())
                } else {
                    rec.extend_from_slice(&$v.to_le_bytes())
                }
            };
        }
        for k in 0..3 {
            match cloud.precision {
                Precision::F32 => put!(p.position[k] as f32),
                Precision::F64 => put!(p.position[k]),
            }
        }
        if c.intensity {
            put!(p.intensity);
        }
        if c.rgb {
            rec.extend_from_slice(&p.rgb);
        }
        if c.label {
            rec.push(p.label);
        }
        if c.raw_label {
            put!(p.raw_label);
        }
        if c.object {
            put!(p.object);
        }
        w.write_all(&rec)?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tmp(name: &str) -> std::path::PathBuf {
        let dir = std::env::temp_dir().join(format!("urbansem-ply-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        dir.join(name)
    }

    #[test]
    fn reads_hand_written_ascii_with_faces_and_unknown_properties() {
        let p = tmp("a.ply");
        std::fs::write(
            &p,
            "ply\nformat ascii 1.0\ncomment x\nelement face 1\nproperty list uchar int vertex_indices\n\
             element vertex 2\nproperty float x\nproperty float y\nproperty float z\nproperty short nx\n\
             property uchar red\nproperty uchar green\nproperty uchar blue\nend_header\n\
             3 0 1 2\n1 2 3 -7 10 20 30\n4.5 5 6 8 1 2 3\n",
        )
        .unwrap();
        let (c, rep) = read_ply(&p, &ReadOptions::default()).unwrap();
        assert_eq!(rep.points_in_file, 2);
        assert_eq!(c.positions, vec![[1.0, 2.0, 3.0], [4.5, 5.0, 6.0]]);
        assert_eq!(c.rgb, Some(vec![[10, 20, 30], [1, 2, 3]]));
        assert_eq!(c.precision, Precision::F32);
    }

    #[test]
    fn reads_big_endian_with_list_after_vertex() {
        let p = tmp("be.ply");
        let mut bytes = b"ply\nformat binary_big_endian 1.0\nelement vertex 1\nproperty double x\n\
property double y\nproperty double z\nproperty uint object\nelement face 1\nproperty list uchar int vi\nend_header\n"
            .to_vec();
        for v in [1.25f64, -2.0, 3.0] {
            bytes.extend_from_slice(&v.to_be_bytes());
        }
        bytes.extend_from_slice(&7u32.to_be_bytes());
        bytes.push(2);
        bytes.extend_from_slice(&[0, 0, 0, 0, 0, 0, 0, 1]);
        std::fs::write(&p, &bytes).unwrap();
        let (c, _) = read_ply(&p, &ReadOptions::default()).unwrap();
        assert_eq!(c.positions, vec![[1.25, -2.0, 3.0]]);
        assert_eq!(c.object, Some(vec![7]));
        assert_eq!(c.precision, Precision::F64);
        // One byte short in the face list: truncated, with the face's start offset.
        std::fs::write(&p, &bytes[..bytes.len() - 1]).unwrap();
        let e = read_ply(&p, &ReadOptions::default()).unwrap_err();
        assert!(matches!(e, CloudError::Truncated { point: 0, .. }), "{e}");
    }

    #[test]
    fn nan_is_an_error_or_dropped() {
        let p = tmp("nan.ply");
        std::fs::write(
            &p,
            "ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\nproperty float z\nend_header\n1 2 3\nnan 0 0\n",
        )
        .unwrap();
        let e = read_ply(&p, &ReadOptions::default()).unwrap_err();
        assert!(matches!(e, CloudError::NonFinite { point: 1, .. }), "{e}");
        let (c, rep) = read_ply(
            &p,
            &ReadOptions {
                drop_non_finite: true,
            },
        )
        .unwrap();
        assert_eq!((c.len(), rep.dropped_non_finite), (1, 1));
    }

    #[test]
    fn bad_header_names_the_line() {
        let p = tmp("bad.ply");
        std::fs::write(
            &p,
            "ply\nformat ascii 1.0\nelement vertex 1\nproperty float128 x\nend_header\n",
        )
        .unwrap();
        let e = read_ply(&p, &ReadOptions::default()).unwrap_err();
        assert!(
            matches!(
                e,
                CloudError::Header {
                    at: Location::Line(4),
                    ..
                }
            ),
            "{e}"
        );
        assert!(e.to_string().contains("bad.ply"));
    }

    /// The header `plyfile` 1.1 (Python) writes for a vertex element with float/double
    /// coordinates, an intensity, uchar colours and a face list, byte for byte (from
    /// `PlyData([vertex, face], text=…, byte_order=…, comments=[…], obj_info=[…]).write`).
    fn plyfile_header(format: &str) -> Vec<u8> {
        format!(
            "ply\nformat {format} 1.0\ncomment made by plyfile\nobj_info some info\n\
             element vertex 2\nproperty float x\nproperty double y\nproperty float z\n\
             property double w\nproperty float intensity\nproperty uchar red\n\
             property uchar green\nproperty uchar blue\nelement face 1\n\
             property list uchar int vertex_indices\nend_header\n"
        )
        .into_bytes()
    }

    #[test]
    fn reads_the_headers_plyfile_writes() {
        let want_positions = vec![[1.5, -2.25, 3.0], [4.0, 5.0, 6.0]];
        // ASCII as plyfile prints it (%.18g for doubles, a face line after the vertices).
        let mut ascii = plyfile_header("ascii");
        ascii.extend_from_slice(
            b"1.5 -2.25 3 0.100000000000000006 0.5 255 0 7\n4 5 6 10000000000 0.25 1 2 3\n3 0 1 0\n",
        );
        let p = tmp("plyfile-ascii.ply");
        std::fs::write(&p, &ascii).unwrap();
        let (c, _) = read_ply(&p, &ReadOptions::default()).unwrap();
        assert_eq!(c.positions, want_positions);
        assert_eq!(c.precision, Precision::F64);
        assert_eq!(c.intensity, Some(vec![0.5, 0.25]));
        assert_eq!(c.rgb, Some(vec![[255, 0, 7], [1, 2, 3]]));
        for (format, big) in [("binary_little_endian", false), ("binary_big_endian", true)] {
            let mut bytes = plyfile_header(format);
            macro_rules! put {
                ($v:expr) => {
                    if big {
                        bytes.extend_from_slice(&$v.to_be_bytes())
                    } else {
                        bytes.extend_from_slice(&$v.to_le_bytes())
                    }
                };
            }
            for (p, w, i, rgb) in [
                ([1.5f64, -2.25, 3.0], 0.1f64, 0.5f32, [255u8, 0, 7]),
                ([4.0, 5.0, 6.0], 1e10, 0.25, [1, 2, 3]),
            ] {
                put!(p[0] as f32);
                put!(p[1]);
                put!(p[2] as f32);
                put!(w);
                put!(i);
                bytes.extend_from_slice(&rgb);
            }
            bytes.push(3);
            for k in [0i32, 1, 0] {
                put!(k);
            }
            let p = tmp(&format!("plyfile-{format}.ply"));
            std::fs::write(&p, &bytes).unwrap();
            let (c, report) = read_ply(&p, &ReadOptions::default()).unwrap();
            assert_eq!(c.positions, want_positions, "{format}");
            assert_eq!(c.intensity, Some(vec![0.5, 0.25]), "{format}");
            assert_eq!(c.rgb, Some(vec![[255, 0, 7], [1, 2, 3]]), "{format}");
            assert_eq!(report.points_in_file, 2);
        }
    }

    #[test]
    fn inflated_counts_and_truncated_bodies_are_errors() {
        // Each returns at once with an error, never allocating for or looping over the count.
        let head = |format: &str, vertices: &str, extra: &str| {
            format!(
                "ply\nformat {format} 1.0\nelement vertex {vertices}\nproperty float x\n\
                 property float y\nproperty float z\n{extra}end_header\n"
            )
            .into_bytes()
        };
        let mut b = head("binary_little_endian", "4294967295", "");
        b.extend_from_slice(&[0; 12 * 5 + 7]);
        let p = tmp("inflated.ply");
        std::fs::write(&p, &b).unwrap();
        let e = read_ply(&p, &ReadOptions::default()).unwrap_err();
        let body = (b.len() - 12 * 5 - 7) as u64;
        assert!(
            matches!(e, CloudError::Truncated { at: Location::Byte(at), point: 5, expected: 4_294_967_295, .. } if at == body + 60),
            "{e}"
        );
        let mut b = head("ascii", "4294967295", "");
        b.extend_from_slice(b"1 2 3\n");
        std::fs::write(&p, &b).unwrap();
        let e = read_ply(&p, &ReadOptions::default()).unwrap_err();
        assert!(
            matches!(
                e,
                CloudError::Header {
                    at: Location::Line(3),
                    ..
                }
            ),
            "{e}"
        );
        assert!(e.to_string().contains("element vertex 4294967295"), "{e}");
        // A list element after the vertices, and an element with no property at all.
        let mut b = head(
            "binary_big_endian",
            "1",
            "element face 99999999999\nproperty list uchar int vertex_indices\n",
        );
        b.extend_from_slice(&[0; 12 + 40]);
        std::fs::write(&p, &b).unwrap();
        let e = read_ply(&p, &ReadOptions::default()).unwrap_err();
        assert!(
            matches!(
                e,
                CloudError::Header {
                    at: Location::Line(7),
                    ..
                }
            ),
            "{e}"
        );
        let mut b = head(
            "binary_little_endian",
            "1",
            "element nothing 18446744073709551615\n",
        );
        b.extend_from_slice(&[0; 12]);
        std::fs::write(&p, &b).unwrap();
        let (c, _) = read_ply(&p, &ReadOptions::default()).unwrap();
        assert_eq!(c.len(), 1);
        let mut b = head("ascii", "1", "element nothing 18446744073709551615\n");
        b.extend_from_slice(b"1 2 3\n");
        std::fs::write(&p, &b).unwrap();
        let e = read_ply(&p, &ReadOptions::default()).unwrap_err();
        assert!(
            matches!(
                e,
                CloudError::Header {
                    at: Location::Line(7),
                    ..
                }
            ),
            "{e}"
        );
        // Truncated bodies.
        let mut b = head("binary_little_endian", "2", "");
        b.extend_from_slice(&[0; 20]);
        std::fs::write(&p, &b).unwrap();
        let e = read_ply(&p, &ReadOptions::default()).unwrap_err();
        assert!(
            matches!(
                e,
                CloudError::Truncated {
                    point: 1,
                    expected: 2,
                    ..
                }
            ),
            "{e}"
        );
        let mut b = head("ascii", "2", "");
        b.extend_from_slice(b"1.0 2.0 3.0\n4.0 5.0");
        std::fs::write(&p, &b).unwrap();
        let e = read_ply(&p, &ReadOptions::default()).unwrap_err();
        assert!(matches!(e, CloudError::Truncated { point: 1, .. }), "{e}");
    }
}
