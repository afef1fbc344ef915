//! PCL's PCD format (v0.7): `DATA ascii` and `DATA binary` (little-endian), streaming.
//!
//! Fields `x y z`, `intensity`, `rgb`/`rgba` (packed 0x00RRGGBB, as U4 or as the bits of
//! an F4, PCL's convention), `label`, `raw_label` and `object` fill the columns; other
//! fields (any type, any COUNT) are skipped. `VIEWPOINT` is read but not applied (it is
//! metadata in PCL too). `DATA binary_compressed` (LZF, column-major) is reported as
//! [`CloudError::Unsupported`]; convert such files with `pcl_convert_pcd_ascii_binary`.

use super::ply::{assign, Role, Scalar};
use super::{io_err, path_buf, read_full, CloudError, Encoding, Location, PointCloud, PointRecord};
use super::{Columns, Precision, ReadOptions, ReadReport, Result, Sink};
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

struct Header {
    fields: Vec<Field>,
    points: usize,
    binary: bool,
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
                let binary = match rest.first().copied() {
                    Some("ascii") => false,
                    Some("binary") => true,
                    Some("binary_compressed") => return Err(CloudError::Unsupported {
                        path: path_buf(path),
                        what:
                            "PCD DATA binary_compressed (LZF); convert it to binary or ascii first"
                                .into(),
                    }),
                    other => {
                        return Err(header_err(path, line_no, format!("unknown DATA {other:?}")))
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
                    binary,
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

/// Reads a PCD file (`DATA ascii` or `DATA binary`).
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
    if h.binary {
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
            line.clear();
            line_no += 1;
            let n = r.read_line(&mut line).map_err(|e| match e.kind() {
                std::io::ErrorKind::InvalidData => CloudError::BadValue {
                    path: path_buf(path),
                    at: Location::Line(line_no),
                    field: "point".into(),
                    value: "non-UTF-8 text".into(),
                },
                _ => io_err(path)(e),
            })?;
            // A point line without its line end is a cut file (the last number may be partial).
            if n == 0 || !line.ends_with('\n') {
                return Err(CloudError::Truncated {
                    path: path_buf(path),
                    at: Location::Line(line_no),
                    point: i,
                    expected: h.points,
                });
            }
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

/// Writes a PCD v0.7 file; `BinaryBigEndian` is written as PCD's (little-endian) binary.
pub fn write_pcd(path: &Path, cloud: &PointCloud, encoding: Encoding) -> Result<()> {
    cloud.check_columns()?;
    let file = File::create(path).map_err(io_err(path))?;
    let mut w = BufWriter::with_capacity(1 << 16, file);
    write_pcd_to(&mut w, cloud, encoding != Encoding::Ascii).map_err(io_err(path))?;
    w.flush().map_err(io_err(path))
}

fn write_pcd_to(w: &mut impl Write, cloud: &PointCloud, binary: bool) -> std::io::Result<()> {
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
    writeln!(w, "DATA {}", if binary { "binary" } else { "ascii" })?;
    let mut rec = Vec::with_capacity(64);
    for i in 0..cloud.len() {
        let Some(p) = cloud.get(i) else { break };
        let rgb = (u32::from(p.rgb[0]) << 16) | (u32::from(p.rgb[1]) << 8) | u32::from(p.rgb[2]);
        if !binary {
            match cloud.precision {
                Precision::F32 => write!(
                    w,
                    "{} {} {}",
                    p.position[0] as f32, p.position[1] as f32, p.position[2] as f32
                )?,
                Precision::F64 => {
                    write!(w, "{} {} {}", p.position[0], p.position[1], p.position[2])?
                }
            }
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
        w.write_all(&rec)?;
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
    fn compressed_is_unsupported() {
        let dir = std::env::temp_dir().join(format!("urbansem-pcd-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let p = dir.join("c.pcd");
        std::fs::write(&p, "VERSION .7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nWIDTH 1\nHEIGHT 1\nPOINTS 1\nDATA binary_compressed\n").unwrap();
        assert!(matches!(
            read_pcd(&p, &ReadOptions::default()),
            Err(CloudError::Unsupported { .. })
        ));
    }
}
