//! Decoding `sensor_msgs/msg/PointCloud2` from its CDR bytes: the layout (size, point fields)
//! checked against the data, then the points into a [`PointCloud`].

use super::cdr::{Cdr, CdrResult};
use crate::cloud::error::MessageProblem;
use crate::cloud::ply::{assign, Role, Scalar};
use crate::cloud::{Columns, Location, PointCloud, PointRecord};
use crate::cloud::{Precision, ReadOptions, ReadReport, Result, Sink};
use serde::Serialize;
use std::path::Path;

/// One `sensor_msgs/msg/PointField` of a PointCloud2 message.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct PointFieldInfo {
    /// Field name (`x`, `intensity`, `ring`, …).
    pub name: String,
    /// Byte offset inside a point.
    pub offset: u32,
    /// PointField datatype: 1 INT8, 2 UINT8, 3 INT16, 4 UINT16, 5 INT32, 6 UINT32, 7 FLOAT32, 8 FLOAT64.
    pub datatype: u8,
    /// Number of values of this datatype.
    pub count: u32,
}

impl PointFieldInfo {
    /// The datatype's name in PointField's words (`FLOAT32`, …), `?` for an unknown one.
    pub fn datatype_name(&self) -> &'static str {
        match self.datatype {
            1 => "INT8",
            2 => "UINT8",
            3 => "INT16",
            4 => "UINT16",
            5 => "INT32",
            6 => "UINT32",
            7 => "FLOAT32",
            8 => "FLOAT64",
            _ => "?",
        }
    }
}

/// The layout of a PointCloud2 message: its size and point fields.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct CloudLayout {
    /// Points per row.
    pub width: u32,
    /// Rows (1 for an unorganized cloud).
    pub height: u32,
    /// Bytes per point.
    pub point_step: u32,
    /// True when the point data is big-endian.
    pub is_bigendian: bool,
    /// The frame of the points (`header.frame_id`).
    pub frame_id: String,
    /// The point fields.
    pub fields: Vec<PointFieldInfo>,
}

/// A decoded PointCloud2 message, its point data borrowed from the message bytes.
#[derive(Debug, Clone, PartialEq)]
pub(super) struct PointCloud2<'a> {
    /// Size, fields and frame.
    pub(super) layout: CloudLayout,
    /// `header.stamp`, nanoseconds since the epoch.
    pub(super) stamp_ns: i64,
    /// Bytes per row.
    row_step: u32,
    /// The point data, `height × row_step` bytes.
    data: &'a [u8],
    /// Byte offset of `data` within the message.
    data_offset: u64,
}

/// Decodes the CDR bytes of a `sensor_msgs/msg/PointCloud2` message and checks that its
/// fields fit its points and its data holds `width × height` points.
pub(super) fn decode_point_cloud2(message: &[u8]) -> CdrResult<PointCloud2<'_>> {
    let mut c = Cdr::new(message)?;
    let stamp_ns = c.time_ns("header.stamp")?;
    let frame_id = c.string("header.frame_id")?;
    let height = c.u32("height")?;
    let width = c.u32("width")?;
    let n_fields = c.u32("the field count")?;
    let mut fields = Vec::new();
    // Each field takes at least 13 bytes, so this loop ends within the message's length.
    for _ in 0..n_fields {
        let name = c.string("a field name")?;
        let offset = c.u32("a field offset")?;
        let datatype = c.u8("a field datatype")?;
        let count = c.u32("a field count")?;
        fields.push(PointFieldInfo {
            name,
            offset,
            datatype,
            count,
        });
    }
    let is_bigendian = c.u8("is_bigendian")? != 0;
    let point_step = c.u32("point_step")?;
    let row_step = c.u32("row_step")?;
    let data_len = c.u32("the data length")?;
    let data_offset = c.offset();
    let data = c.take(data_len as usize, 1, "data")?;
    c.u8("is_dense")?;
    for f in &fields {
        let size = match scalar_of(f.datatype) {
            Some(s) => s.size() as u64,
            // An unknown datatype is an error only for a field the reader uses.
            None if role_of(f) == Role::Skip => continue,
            None => {
                return Err((
                    data_offset,
                    MessageProblem::BadDatatype {
                        name: f.name.clone(),
                        datatype: f.datatype,
                    },
                ))
            }
        };
        let end = u64::from(f.offset) + size * u64::from(f.count);
        if end > u64::from(point_step) {
            return Err((
                data_offset,
                MessageProblem::FieldOutsidePoint {
                    name: f.name.clone(),
                    offset: f.offset,
                    end,
                    point_step,
                },
            ));
        }
    }
    let packed_row = u128::from(width) * u128::from(point_step);
    let need = u128::from(height) * packed_row.max(u128::from(row_step));
    if u128::from(row_step) < packed_row || need != data.len() as u128 {
        return Err((
            data_offset,
            MessageProblem::DataLength {
                width,
                height,
                point_step,
                row_step,
                need,
                data: data.len() as u64,
            },
        ));
    }
    Ok(PointCloud2 {
        stamp_ns,
        layout: CloudLayout {
            width,
            height,
            point_step,
            is_bigendian,
            frame_id,
            fields,
        },
        row_step,
        data,
        data_offset,
    })
}

/// The scalar type of a PointField datatype.
fn scalar_of(datatype: u8) -> Option<Scalar> {
    Some(match datatype {
        1 => Scalar::I8,
        2 => Scalar::U8,
        3 => Scalar::I16,
        4 => Scalar::U16,
        5 => Scalar::I32,
        6 => Scalar::U32,
        7 => Scalar::F32,
        8 => Scalar::F64,
        _ => return None,
    })
}

/// Which column a field fills: the PCD reader's rule (a UINT8 `label` is urbansem's class
/// id, a wider one a dataset's id); arrays other than coordinates are skipped.
fn role_of(f: &PointFieldInfo) -> Role {
    match (f.name.as_str(), f.count) {
        ("label", 1) if f.datatype != 2 => Role::RawLabel,
        ("x" | "y" | "z", _) => Role::from_name(&f.name),
        (name, 1) => Role::from_name(name),
        _ => Role::Skip,
    }
}

/// A field the reader fills, resolved for fast decoding.
struct Used {
    role: Role,
    scalar: Scalar,
    offset: usize,
    name: String,
}

/// Decodes the points of a checked message into a cloud; errors are `(byte, problem)` for
/// the layout and [`CloudError`](crate::cloud::CloudError)s naming the point for the values.
pub(super) fn points_of(
    path: &Path,
    msg: &PointCloud2<'_>,
    options: &ReadOptions,
) -> CdrResult<Result<(PointCloud, ReadReport)>> {
    let layout = &msg.layout;
    let mut used = Vec::new();
    for f in &layout.fields {
        let role = role_of(f);
        if role == Role::Skip || f.count == 0 {
            continue;
        }
        if matches!(role, Role::X | Role::Y | Role::Z) && f.count != 1 {
            return Err((
                msg.data_offset,
                MessageProblem::CoordinateCount {
                    name: f.name.clone(),
                    count: f.count,
                },
            ));
        }
        // Checked by decode_point_cloud2: a used field has a known datatype.
        if let Some(scalar) = scalar_of(f.datatype) {
            used.push(Used {
                role,
                scalar,
                offset: f.offset as usize,
                name: f.name.clone(),
            });
        }
    }
    for (role, name) in [(Role::X, "x"), (Role::Y, "y"), (Role::Z, "z")] {
        if !used.iter().any(|u| u.role == role) {
            let names: Vec<&str> = layout.fields.iter().map(|f| f.name.as_str()).collect();
            return Err((
                msg.data_offset,
                MessageProblem::MissingField {
                    name,
                    fields: names.join(" "),
                },
            ));
        }
    }
    let has = |role: Role| used.iter().any(|u| u.role == role);
    let columns = Columns {
        intensity: has(Role::Intensity),
        rgb: has(Role::Red) && has(Role::Green) && has(Role::Blue),
        label: has(Role::Label),
        raw_label: has(Role::RawLabel),
        object: has(Role::Object),
    };
    let double = used
        .iter()
        .any(|u| matches!(u.role, Role::X | Role::Y | Role::Z) && u.scalar != Scalar::F32);
    let precision = if double {
        Precision::F64
    } else {
        Precision::F32
    };
    // Checked by decode_point_cloud2: data holds height × width points.
    let points = layout.width as usize * layout.height as usize;
    let mut sink = Sink::new(
        path,
        PointCloud::with_columns(columns, precision, points),
        options,
    );
    let point_step = layout.point_step as usize;
    let rows = msg
        .data
        .chunks(msg.row_step.max(1) as usize)
        .take(layout.height as usize);
    let mut i = 0usize;
    for row in rows {
        for point in row.chunks(point_step.max(1)).take(layout.width as usize) {
            let mut rec = PointRecord::default();
            for u in &used {
                let bytes = point.get(u.offset..).unwrap_or(&[]);
                let v = u.scalar.decode(bytes, layout.is_bigendian);
                if let Err(e) = assign(&mut rec, u.role, v, path, Location::Point(i), &u.name) {
                    return Ok(Err(e));
                }
            }
            if let Err(e) = sink.push(&rec) {
                return Ok(Err(e));
            }
            i += 1;
        }
    }
    Ok(Ok(sink.finish()))
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    /// A one-point little-endian message with x y z FLOAT32 and an empty frame id, written
    /// out by hand: the offsets in the comments count from after the 4-byte header.
    fn one_point() -> Vec<u8> {
        let mut m = vec![0, 1, 0, 0];
        let u32s = |m: &mut Vec<u8>, values: &[u32]| {
            for v in values {
                m.extend_from_slice(&v.to_le_bytes());
            }
        };
        u32s(&mut m, &[7, 8, 1]); // 0: stamp, 8: frame_id length (NUL only)
        m.extend_from_slice(&[0, 0, 0, 0]); // 12: NUL, 13..16: padding to 4
        u32s(&mut m, &[1, 1, 3]); // 16: height, 20: width, 24: field count
        for (name, offset) in [(b'x', 0u32), (b'y', 4), (b'z', 8)] {
            u32s(&mut m, &[2]); // name length
            m.extend_from_slice(&[name, 0, 0, 0]); // name, NUL, padding to 4
            u32s(&mut m, &[offset]);
            m.extend_from_slice(&[7, 0, 0, 0]); // FLOAT32, padding to 4
            u32s(&mut m, &[1]); // count
        }
        m.extend_from_slice(&[0, 0, 0, 0]); // 88: is_bigendian, padding to 4
        u32s(&mut m, &[12, 12, 12]); // 92: point_step, 96: row_step, 100: data length
        for v in [1.5f32, -2.0, 0.25] {
            m.extend_from_slice(&v.to_le_bytes()); // 104: data
        }
        m.push(1); // 116: is_dense
        m
    }

    #[test]
    fn a_hand_written_message_decodes_and_its_offsets_are_exact() {
        let m = one_point();
        let msg = decode_point_cloud2(&m).unwrap();
        assert_eq!((msg.layout.width, msg.layout.height), (1, 1));
        assert_eq!(msg.data_offset, 4 + 104);
        assert_eq!(msg.layout.fields[2].name, "z");
        let (cloud, report) = points_of(Path::new("a.mcap"), &msg, &ReadOptions::default())
            .unwrap()
            .unwrap();
        assert_eq!(cloud.positions, vec![[1.5, -2.0, 0.25]]);
        assert_eq!(
            (cloud.precision, report.points_in_file),
            (Precision::F32, 1)
        );
        // Cut before is_dense: the error is at the byte where is_dense starts.
        let (offset, problem) = decode_point_cloud2(&m[..m.len() - 1]).unwrap_err();
        assert_eq!(offset, 4 + 116);
        assert_eq!(
            problem,
            MessageProblem::Truncated {
                field: "is_dense",
                need: 1,
                left: 0
            }
        );
    }
}
