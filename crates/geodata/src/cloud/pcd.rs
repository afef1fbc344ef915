//! PCL's PCD format (v0.7): `DATA ascii` and `DATA binary` (little-endian), streaming.
//!
//! Fields `x y z`, `intensity`, `rgb`/`rgba` (packed 0x00RRGGBB, as U4 or as the bits of
//! an F4, PCL's convention), `label`, `raw_label` and `object` fill the columns; other
//! fields (any type, any COUNT) are skipped. `VIEWPOINT` is read but not applied (it is
//! metadata in PCL too). `DATA binary_compressed` is read and written too: after the header,
//! u32 compressed size, u32 uncompressed size, then one LZF block ([`super::lzf`]) holding the
//! fields column by column (all x, then all y, …). That block is decompressed in memory;
//! ascii and binary bodies are streamed.

use super::ply::{assign, Role, Scalar};
use super::{
    io_err, path_buf, read_full, read_point_line, CloudError, Encoding, Location, PointCloud,
    PointRecord,
};
use super::{write_ascii_position, Columns, Precision, ReadOptions, ReadReport, Result, Sink};
use std::fs::File;
use std::io::{BufRead, BufReader, BufWriter, Read, Write};
use std::path::Path;

const MAX_HEADER_LINE: u64 = 65_536;

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum PcdRole {
    Column(Role),
    Rgb,
}

#[derive(Debug, Clone)]
struct Field {
    name: String,
    ty: Scalar,
    count: usize,
    role: PcdRole,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Data {
    Ascii,
    Binary,
    Compressed,
}

struct Header {
    fields: Vec<Field>,
    points: usize,
    data: Data,
    len: u64,
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
    let mut names: Vec<String> = Vec::new();
    let mut sizes: Vec<usize> = Vec::new();
    let mut types: Vec<char> = Vec::new();
    let mut counts: Option<Vec<usize>> = None;
    let (mut width, mut height, mut points) = (None, None, None);
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
                "file ends (or a line is too long) before the DATA line",
            ));
        }
        len += n as u64;
        let text = std::str::from_utf8(&buf)
            .map_err(|_| header_err(path, line_no, "header is not UTF-8"))?;
        let mut tok = text.split_whitespace();
        let Some(key) = tok.next() else { continue };
        if key.starts_with('#') {
            continue;
        }
        let rest: Vec<&str> = tok.collect();
        let parse_usizes = |what: &str| -> Result<Vec<usize>> {
            rest.iter()
                .map(|s| {
                    s.parse::<usize>()
                        .map_err(|_| header_err(path, line_no, format!("bad {what} value {s:?}")))
                })
                .collect()
        };
        let one = |what: &str| -> Result<usize> {
            match parse_usizes(what)?.as_slice() {
                [v] => Ok(*v),
                _ => Err(header_err(
                    path,
                    line_no,
                    format!("{what} takes one number"),
                )),
            }
        };
        match key {
            "VERSION" | "VIEWPOINT" => {}
            "FIELDS" | "COLUMNS" => names = rest.iter().map(|s| s.to_string()).collect(),
            "SIZE" => sizes = parse_usizes("SIZE")?,
            "TYPE" => {
                types = rest
                    .iter()
                    .map(|s| match *s {
                        "I" | "U" | "F" => Ok(s.chars().next().unwrap_or('F')),
                        _ => Err(header_err(
                            path,
                            line_no,
                            format!("unknown TYPE {s:?}; expected I, U or F"),
                        )),
                    })
                    .collect::<Result<_>>()?
            }
            "COUNT" => counts = Some(parse_usizes("COUNT")?),
            "WIDTH" => width = Some(one("WIDTH")?),
            "HEIGHT" => height = Some(one("HEIGHT")?),
            "POINTS" => points = Some(one("POINTS")?),
            "DATA" => {
                let data = match rest.first().copied() {
                    Some("ascii") => Data::Ascii,
                    Some("binary") => Data::Binary,
                    Some("binary_compressed") => Data::Compressed,
                    other => {
                        return Err(header_err(
                            path,
                            line_no,
                            format!(
                            "unknown DATA {other:?}; expected ascii, binary or binary_compressed"
                        ),
                        ))
                    }
                };
                let counts = counts.unwrap_or_else(|| vec![1; names.len()]);
                if names.is_empty()
                    || sizes.len() != names.len()
                    || types.len() != names.len()
                    || counts.len() != names.len()
                {
                    return Err(header_err(
                        path,
                        line_no,
                        format!(
                            "FIELDS ({}), SIZE ({}), TYPE ({}) and COUNT ({}) must have the same length",
                            names.len(),
                            sizes.len(),
                            types.len(),
                            counts.len()
                        ),
                    ));
                }
                let (Some(width), Some(height)) = (width, height) else {
                    return Err(header_err(path, line_no, "WIDTH and HEIGHT are required"));
                };
                let wh = width
                    .checked_mul(height)
                    .ok_or_else(|| header_err(path, line_no, "WIDTH × HEIGHT overflows"))?;
                let points = points.unwrap_or(wh);
                if points != wh {
                    return Err(header_err(
                        path,
                        line_no,
                        format!("POINTS {points} ≠ WIDTH × HEIGHT = {wh}"),
                    ));
                }
                let mut fields = Vec::with_capacity(names.len());
                for (((name, &size), &t), &count) in
                    names.iter().zip(&sizes).zip(&types).zip(&counts)
                {
                    let ty = match (t, size) {
                        ('I', 1) => Scalar::I8,
                        ('I', 2) => Scalar::I16,
                        ('I', 4) => Scalar::I32,
                        ('I', 8) => Scalar::I64,
                        ('U', 1) => Scalar::U8,
                        ('U', 2) => Scalar::U16,
                        ('U', 4) => Scalar::U32,
                        ('U', 8) => Scalar::U64,
                        ('F', 4) => Scalar::F32,
                        ('F', 8) => Scalar::F64,
                        _ => {
                            return Err(header_err(
                                path,
                                line_no,
                                format!("field {name}: TYPE {t} with SIZE {size} is not valid"),
                            ))
                        }
                    };
                    let role = match (name.as_str(), count) {
                        ("rgb" | "rgba", 1) => PcdRole::Rgb,
                        (n, 1) => PcdRole::Column(Role::from_name(n)),
                        _ => PcdRole::Column(Role::Skip),
                    };
                    if role != PcdRole::Column(Role::Skip)
                        && fields.iter().any(|f: &Field| f.role == role)
                    {
                        return Err(header_err(
                            path,
                            line_no,
                            format!("duplicate field {name:?}"),
                        ));
                    }
                    fields.push(Field {
                        name: name.clone(),
                        ty,
                        count,
                        role,
                    });
                }
                for axis in [Role::X, Role::Y, Role::Z] {
                    if !fields.iter().any(|f| f.role == PcdRole::Column(axis)) {
                        return Err(header_err(path, line_no, "FIELDS must include x, y and z"));
                    }
                }
                return Ok(Header {
                    fields,
                    points,
                    data,
                    len,
                    lines: line_no,
                });
            }
            other => {
                return Err(header_err(
                    path,
                    line_no,
                    format!("unknown header keyword {other:?}"),
                ))
            }
        }
    }
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
            let bits = if f.ty == Scalar::F32 {
                let b: [u8; 4] = raw
                    .get(..4)
                    .and_then(|s| s.try_into().ok())
                    .unwrap_or((v as f32).to_le_bytes());
                u32::from_le_bytes(b)
            } else {
                v as u32
            };
            rec.rgb = [(bits >> 16) as u8, (bits >> 8) as u8, bits as u8];
            Ok(())
        }
        PcdRole::Column(role) => assign(rec, role, v, path, at, &f.name),
    }
}

/// Reads a PCD file (`DATA ascii`, `binary` or `binary_compressed`).
pub fn read_pcd(path: &Path, options: &ReadOptions) -> Result<(PointCloud, ReadReport)> {
    let file = File::open(path).map_err(io_err(path))?;
    let file_len = file.metadata().map_err(io_err(path))?.len();
    let mut r = BufReader::with_capacity(1 << 16, file);
    let h = read_header(path, &mut r)?;
    let has = |role: PcdRole| h.fields.iter().any(|f| f.role == role);
    let columns = Columns {
        intensity: has(PcdRole::Column(Role::Intensity)),
        rgb: has(PcdRole::Rgb),
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
    let capacity = h
        .points
        .min(usize::try_from(file_len.saturating_sub(h.len)).unwrap_or(0));
    let mut sink = Sink::new(
        path,
        PointCloud::with_columns(columns, precision, capacity),
        options,
    );
    if h.data == Data::Compressed {
        read_compressed_body(path, &mut r, &h, file_len, &mut sink)?;
    } else if h.data == Data::Binary {
        let record: usize = h.fields.iter().map(|f| f.ty.size() * f.count).sum();
        let mut buf = vec![0u8; record];
        for i in 0..h.points {
            let start = h.len + (i as u64) * record as u64;
            if !read_full(&mut r, &mut buf).map_err(io_err(path))? {
                return Err(CloudError::Truncated {
                    path: path_buf(path),
                    at: Location::Byte(start),
                    point: i,
                    expected: h.points,
                });
            }
            let mut rec = PointRecord::default();
            let mut at = 0usize;
            for f in &h.fields {
                let end = at + f.ty.size() * f.count;
                if f.role != PcdRole::Column(Role::Skip) {
                    let raw = buf.get(at..at + f.ty.size()).unwrap_or(&[]);
                    let v = f.ty.decode(raw, false);
                    set(&mut rec, f, v, raw, path, Location::Byte(start + at as u64))?;
                }
                at = end;
            }
            sink.push(&rec)?;
        }
        let end = h.len + (h.points as u64) * record as u64;
        let extra = std::io::copy(&mut r, &mut std::io::sink()).map_err(io_err(path))?;
        if extra > 0 {
            return Err(CloudError::TrailingData {
                path: path_buf(path),
                at: Location::Byte(end),
                extra,
            });
        }
    } else {
        let mut line = String::new();
        let mut line_no = h.lines;
        let mut i = 0usize;
        while i < h.points {
            line_no += 1;
            read_point_line(&mut r, &mut line, path, line_no, "point", i, h.points)?;
            let at = Location::Line(line_no);
            let mut tokens = line.split_whitespace();
            let mut rec = PointRecord::default();
            for f in &h.fields {
                for _ in 0..f.count {
                    let tok = tokens.next().ok_or_else(|| CloudError::BadValue {
                        path: path_buf(path),
                        at,
                        field: f.name.clone(),
                        value: "missing (line too short)".into(),
                    })?;
                    // PCL writes NaN as "nan"; f32 rgb is parsed by its bits below.
                    let v = f.ty.parse(tok).ok_or_else(|| CloudError::BadValue {
                        path: path_buf(path),
                        at,
                        field: f.name.clone(),
                        value: tok.to_string(),
                    })?;
                    if f.role != PcdRole::Column(Role::Skip) {
                        let raw = (v as f32).to_le_bytes();
                        set(&mut rec, f, v, &raw, path, at)?;
                    }
                }
            }
            if let Some(extra) = tokens.next() {
                return Err(CloudError::BadValue {
                    path: path_buf(path),
                    at,
                    field: "end of line".into(),
                    value: extra.to_string(),
                });
            }
            sink.push(&rec)?;
            i += 1;
        }
        loop {
            line.clear();
            line_no += 1;
            if r.read_line(&mut line).map_err(io_err(path))? == 0 {
                break;
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
    Ok(sink.finish())
}

fn read_compressed_body(
    path: &Path,
    r: &mut impl Read,
    h: &Header,
    file_len: u64,
    sink: &mut Sink,
) -> Result<()> {
    let truncated = |at: u64| CloudError::Truncated {
        path: path_buf(path),
        at: Location::Byte(at),
        point: 0,
        expected: h.points,
    };
    let mut sizes = [0u8; 8];
    if !read_full(r, &mut sizes).map_err(io_err(path))? {
        return Err(truncated(h.len));
    }
    let compressed = u64::from(u32::from_le_bytes([sizes[0], sizes[1], sizes[2], sizes[3]]));
    let raw_len = u64::from(u32::from_le_bytes([sizes[4], sizes[5], sizes[6], sizes[7]]));
    let record: usize = h.fields.iter().map(|f| f.ty.size() * f.count).sum();
    let expected_raw = (h.points as u64).saturating_mul(record as u64);
    if raw_len != expected_raw {
        return Err(CloudError::BadValue {
            path: path_buf(path),
            at: Location::Byte(h.len + 4),
            field: "uncompressed size".into(),
            value: format!("{raw_len} (POINTS × record size = {expected_raw})"),
        });
    }
    // One 3-byte LZF chunk expands to at most 264 bytes: a larger claim is a corrupt header
    // (and must not become a huge allocation).
    if raw_len > compressed.saturating_mul(88) + 32 {
        return Err(CloudError::BadValue {
            path: path_buf(path),
            at: Location::Byte(h.len),
            field: "compressed size".into(),
            value: format!("{compressed} bytes cannot hold {raw_len} uncompressed bytes"),
        });
    }
    let data_start = h.len + 8;
    if data_start + compressed > file_len {
        return Err(truncated(file_len));
    }
    if data_start + compressed < file_len {
        return Err(CloudError::TrailingData {
            path: path_buf(path),
            at: Location::Byte(data_start + compressed),
            extra: file_len - data_start - compressed,
        });
    }
    let mut packed = vec![0u8; compressed as usize];
    if !read_full(r, &mut packed).map_err(io_err(path))? {
        return Err(truncated(data_start));
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
            value: format!("{e:?}"),
        }
    })?;
    // Column-major: field k's values start at POINTS × (record bytes of the fields before k).
    let mut starts = Vec::with_capacity(h.fields.len());
    let mut acc = 0usize;
    for f in &h.fields {
        starts.push(acc);
        acc += h.points * f.ty.size() * f.count;
    }
    for i in 0..h.points {
        let mut rec = PointRecord::default();
        for (f, &start) in h.fields.iter().zip(&starts) {
            if f.role == PcdRole::Column(Role::Skip) {
                continue;
            }
            let at = start + i * f.ty.size() * f.count;
            let raw = soa.get(at..at + f.ty.size()).unwrap_or(&[]);
            let v = f.ty.decode(raw, false);
            set(&mut rec, f, v, raw, path, Location::Point(i))?;
        }
        sink.push(&rec)?;
    }
    Ok(())
}

/// Writes a PCD v0.7 file: `Ascii`, `BinaryCompressed` (LZF) or binary (little-endian; PCD
/// has no big-endian variant, so `BinaryBigEndian` writes binary too).
pub fn write_pcd(path: &Path, cloud: &PointCloud, encoding: Encoding) -> Result<()> {
    cloud.check_columns()?;
    let file = File::create(path).map_err(io_err(path))?;
    let mut w = BufWriter::with_capacity(1 << 16, file);
    let data = match encoding {
        Encoding::Ascii => Data::Ascii,
        Encoding::BinaryCompressed => Data::Compressed,
        Encoding::BinaryLittleEndian | Encoding::BinaryBigEndian => Data::Binary,
    };
    write_pcd_to(&mut w, cloud, data).map_err(io_err(path))?;
    w.flush().map_err(io_err(path))
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
}
