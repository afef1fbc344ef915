//! The semantic map as files other tools open: one point per occupied cell (its centre) with
//! the class colour, class id and object id, written as PLY (CloudCompare, Rerun, MeshLab
//! show the `red`/`green`/`blue` colours and keep `label` and `object` as scalar fields).

use crate::error::Result;
use crate::semantic::SemanticMap;
use geodata::cloud::{Columns, PointCloud, PointRecord, Precision};
use std::path::Path;

/// One point per occupied cell, in the map's cell order: the cell centre (f64), the class
/// colour ([`geodata::classes::Class::color_rgb`]), the class id (`label`) and the object id
/// (`object`, 0: none).
pub fn cells_cloud(map: &SemanticMap) -> PointCloud {
    let cells = &map.cells;
    let columns = Columns {
        rgb: true,
        label: true,
        object: true,
        ..Columns::default()
    };
    let occupied = cells.cells().iter().filter(|c| c.occupied());
    let mut cloud = PointCloud::with_columns(columns, Precision::F64, cells.len());
    for c in occupied {
        let class = c.class();
        cloud.push(&PointRecord {
            position: cells.centre(c.key),
            rgb: class.color_rgb(),
            label: class.id(),
            object: c.object,
            ..PointRecord::default()
        });
    }
    cloud
}

/// Writes [`cells_cloud`] as a binary little-endian PLY file (atomically); returns the
/// number of points.
pub fn write_ply(path: &Path, map: &SemanticMap) -> Result<usize> {
    let cloud = cells_cloud(map);
    geodata::cloud::write_cloud_with(
        path,
        &cloud,
        &geodata::cloud::WriteOptions {
            encoding: geodata::cloud::Encoding::BinaryLittleEndian,
        },
    )?;
    Ok(cloud.len())
}
