//! What `urbansem map build` and `urbansem map query` print, as typed values.

use crate::map::{InsertStats, MemoryReport, SrMap};
use crate::semantic::SemanticMap;
use serde::Serialize;
use std::fmt::Write as _;
use std::path::Path;

/// A cloud inserted into a new map and saved (`map build --json`).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct BuildReport {
    /// Points inserted.
    pub points: usize,
    /// Cells of the map.
    pub cells: usize,
    /// Objects extracted from the cells.
    pub objects: usize,
    /// Rays cast.
    pub rays: usize,
    /// Free-space updates applied to existing cells.
    pub misses: usize,
    /// Height of the R-tree.
    pub tree_height: usize,
    /// Bytes held by the map, by part.
    pub memory: MemoryReport,
    /// Seconds spent reading the cloud.
    pub seconds_read: f64,
    /// Seconds spent inserting it.
    pub seconds_insert: f64,
    /// Points inserted per second.
    pub points_per_second: f64,
    /// The map file written.
    pub out: String,
    /// For a map built from a ROS 2 bag: its scans and poses.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub bag: Option<crate::jobs::BagBuild>,
}

impl BuildReport {
    /// The report of `map`, built by one insertion (`stats`) and written to `out`.
    pub fn new(
        map: &SemanticMap,
        stats: &InsertStats,
        seconds_read: f64,
        seconds_insert: f64,
        out: &Path,
    ) -> Self {
        let cells = &map.cells;
        Self {
            points: stats.points,
            cells: cells.len(),
            objects: map.relations.objects.len(),
            rays: stats.rays,
            misses: stats.misses,
            tree_height: cells.tree_height(),
            memory: cells.memory(),
            seconds_read,
            seconds_insert,
            points_per_second: stats.points as f64 / seconds_insert.max(1e-9),
            out: out.display().to_string(),
            bag: None,
        }
    }

    /// One line: points, cells, objects, speed, bytes per cell, tree height (and for a bag,
    /// a line on its scans).
    pub fn text(&self) -> String {
        let bag = self.bag.as_ref().map_or_else(String::new, |b| {
            format!(
                "{} of {} scans inserted ({} without a pose within the allowed gap), placed by {} poses\n",
                b.inserted, b.scans, b.skipped_without_pose, b.poses
            )
        });
        bag + &format!(
            "{}: {} points → {} cells ({} objects) in {:.2} s ({:.1} M points/s); {:.0} bytes per cell; R-tree height {}\n",
            self.out,
            self.points,
            self.cells,
            self.objects,
            self.seconds_insert,
            self.points_per_second / 1e6,
            self.memory.bytes_per_cell,
            self.tree_height
        )
    }
}

/// One cell of a [`QueryReport`].
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct CellRow {
    /// Centre, metres.
    pub centre: [f64; 3],
    /// Class name.
    pub class: String,
    /// Object id (0: none).
    pub object: u32,
    /// Points that fell in the cell.
    pub hits: u32,
    /// Occupancy probability.
    pub occupancy: f64,
    /// Mean colour.
    pub rgb: [u8; 3],
}

/// The cells a query found (`map query --json`).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct QueryReport {
    /// Cells found.
    pub count: usize,
    /// Seconds the query took.
    pub seconds: f64,
    /// The cells, in the query's order.
    pub cells: Vec<CellRow>,
}

/// Cells a text listing shows before it refers to `--json`.
const TEXT_ROWS: usize = 50;

impl QueryReport {
    /// The report of the cells `ids` of `map`, found in `seconds`.
    pub fn new(map: &SrMap, ids: &[u32], seconds: f64) -> Self {
        let cells: Vec<CellRow> = ids
            .iter()
            .filter_map(|&i| {
                let c = map.cells().get(i as usize)?;
                Some(CellRow {
                    centre: map.centre(c.key),
                    class: c.class().name().to_owned(),
                    object: c.object,
                    hits: c.hits,
                    occupancy: c.occupancy(),
                    rgb: map.mean_rgb(i),
                })
            })
            .collect();
        Self {
            count: cells.len(),
            seconds,
            cells,
        }
    }

    /// A count line and the first 50 cells, one per line.
    pub fn text(&self) -> String {
        let mut s = format!("{} cells ({:.3} ms)\n", self.count, self.seconds * 1e3);
        for r in self.cells.iter().take(TEXT_ROWS) {
            let _ = writeln!(
                s,
                "  {:>9.2} {:>9.2} {:>7.2}  {:<10} object {} hits {}",
                r.centre[0], r.centre[1], r.centre[2], r.class, r.object, r.hits
            );
        }
        if self.cells.len() > TEXT_ROWS {
            let _ = writeln!(
                s,
                "  … {} more (use --json for all)",
                self.cells.len() - TEXT_ROWS
            );
        }
        s
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;
    use crate::map::MapOptions;
    use crate::objects::ObjectOptions;
    use geodata::classes::Class;
    use geodata::cloud::PointCloud;

    /// `n` car points 1 m apart along x, one per 0.1 m cell.
    fn car_row(n: usize) -> SrMap {
        let cloud = PointCloud {
            positions: (0..n).map(|i| [i as f64 + 0.05, 0.05, 0.05]).collect(),
            label: Some(vec![Class::Car.id(); n]),
            ..PointCloud::default()
        };
        let mut map = SrMap::new(MapOptions::default()).unwrap();
        map.insert_cloud(&cloud, None).unwrap();
        map
    }

    #[test]
    fn a_query_lists_fifty_cells_then_counts_the_rest() {
        let map = car_row(53);
        let mut ids: Vec<u32> = (0..map.len() as u32).collect();
        ids.sort_unstable();
        let report = QueryReport::new(&map, &ids, 0.002);
        assert_eq!(report.count, 53);
        assert!(report.cells.iter().all(|c| c.class == "car" && c.hits == 1));
        let text = report.text();
        assert!(text.starts_with("53 cells (2.000 ms)\n"), "{text}");
        assert_eq!(text.lines().count(), 1 + 50 + 1);
        assert!(
            text.ends_with("  … 3 more (use --json for all)\n"),
            "{text}"
        );
    }

    #[test]
    fn a_build_report_counts_points_cells_and_objects() {
        let cloud = PointCloud {
            positions: vec![[0.05, 0.05, 0.05], [0.15, 0.05, 0.05]],
            label: Some(vec![Class::Car.id(); 2]),
            ..PointCloud::default()
        };
        let mut cells = SrMap::new(MapOptions::default()).unwrap();
        let stats = cells.insert_cloud(&cloud, None).unwrap();
        let map = SemanticMap::with_objects(cells, &ObjectOptions::default());
        let report = BuildReport::new(&map, &stats, 0.1, 2.0, Path::new("m.srt"));
        assert_eq!((report.points, report.cells, report.rays), (2, 2, 0));
        assert_eq!(report.points_per_second, 1.0);
        assert!(report.text().starts_with("m.srt: 2 points → 2 cells ("));
    }
}
