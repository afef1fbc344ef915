//! The whole localization chain on one scan: surfaces → segments → search → suppression and
//! filtering → visibility and costs for every candidate → ranking → refinement → confidence.
//!
//! ```no_run
//! use geodata::osm::OsmMap;
//! use localize::pipeline::{Localizer, LocalizeOptions};
//! let map = OsmMap::load("map.osm").unwrap();
//! let localizer = Localizer::new(&map, LocalizeOptions::default()).unwrap();
//! let cloud = geodata::cloud::read_cloud("scan.ply").unwrap();
//! let result = localizer.localize_points(&cloud.positions).unwrap();
//! println!("{:?}", result.candidates.first());
//! ```

use crate::candidates::{
    build_template, filter, search, suppress, Domain, FilterCounts, SearchOptions, SearchStats,
    Template,
};
use crate::chamfer::{bounding_box, map_edges, BoundPyramid, ChamferOptions, DtTensor};
use crate::rank::{confidence, costs, rank_order, CostKind, CostOptions, Costs};
use crate::refine::{refine_pose, RefineOptions};
use crate::segments::{extract_segments, SegmentOptions};
use crate::surfaces::{vertical_cells, SurfaceOptions};
use crate::visibility::{visible_segments, EdgeGrid, VisibilityOptions};
use crate::{Pose2, Result, Segment};
use geodata::osm::index::MapIndex;
use geodata::osm::OsmMap;
use rayon::prelude::*;
use serde::Serialize;
use std::time::Instant;

/// Every option of the chain.
#[derive(Debug, Clone, PartialEq)]
pub struct LocalizeOptions {
    /// Surface extraction.
    pub surfaces: SurfaceOptions,
    /// Segment extraction.
    pub segments: SegmentOptions,
    /// Distance-transform tensor.
    pub chamfer: ChamferOptions,
    /// Candidate search.
    pub search: SearchOptions,
    /// Visibility.
    pub visibility: VisibilityOptions,
    /// Per-candidate costs.
    pub cost: CostOptions,
    /// Refinement.
    pub refine: RefineOptions,
    /// The cost that ranks the candidates.
    pub rank_by: CostKind,
    /// How many of the best candidates are refined.
    pub refine_top: usize,
    /// Poses farther apart than this are distinct (confidence), metres.
    pub distinct_m: f64,
    /// Poses turned more than this are distinct (confidence), radians.
    pub distinct_rad: f64,
}

impl Default for LocalizeOptions {
    fn default() -> Self {
        LocalizeOptions {
            surfaces: SurfaceOptions::default(),
            segments: SegmentOptions::default(),
            chamfer: ChamferOptions::default(),
            search: SearchOptions::default(),
            visibility: VisibilityOptions::default(),
            cost: CostOptions::default(),
            refine: RefineOptions::default(),
            rank_by: CostKind::Reverse,
            refine_top: 5,
            distinct_m: 4.0,
            distinct_rad: 0.2,
        }
    }
}

/// Seconds spent in the map preparation.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize)]
pub struct MapSeconds {
    /// Outline edges and the visibility grid.
    pub edges: f64,
    /// Distance-transform tensor.
    pub distance_transform: f64,
    /// Lower-bound pyramid.
    pub pyramid: f64,
}

/// A map prepared for localization.
pub struct Localizer<'m> {
    /// The map.
    pub map: &'m OsmMap,
    /// The options.
    pub options: LocalizeOptions,
    /// Building outline edges.
    pub edges: Vec<Segment>,
    /// Buckets of edges for range queries.
    pub edge_grid: EdgeGrid,
    /// The directional distance-transform tensor.
    pub dt: DtTensor,
    /// Its lower-bound pyramid.
    pub pyramid: BoundPyramid,
    /// The searched poses (cells).
    pub domain: Domain,
    /// Map preparation times.
    pub seconds: MapSeconds,
    index: MapIndex<'m>,
}

/// A ranked pose candidate.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Candidate {
    /// Pose in the map's local frame.
    pub pose: Pose2,
    /// Every cost, metres.
    pub costs: Costs,
    /// Whether the pose was refined.
    pub refined: bool,
    /// Margin to the best distinct other candidate (0 unless this one is ahead), [0, 1].
    pub confidence: f64,
}

/// Seconds per stage of one scan.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize)]
pub struct StageSeconds {
    /// Voxels, normals, vertical cells.
    pub surfaces: f64,
    /// Histograms, Hough, merging.
    pub segments: f64,
    /// Templates per yaw.
    pub templates: f64,
    /// Branch-and-bound search.
    pub search: f64,
    /// Suppression and filtering.
    pub filter: f64,
    /// Visibility and costs of every candidate.
    pub visibility_costs: f64,
    /// Refinement of the best candidates.
    pub refine: f64,
    /// The whole chain.
    pub total: f64,
}

/// The result of one scan.
#[derive(Debug, Clone, Serialize)]
pub struct Localization {
    /// Extracted segments in the sensor frame.
    pub segments: Vec<Segment>,
    /// Candidates, best first by `rank_by`.
    pub candidates: Vec<Candidate>,
    /// The ranking cost.
    pub rank_by: CostKind,
    /// Confidence of the best candidate.
    pub confidence: f64,
    /// Vertical-surface cells found.
    pub vertical_cells: usize,
    /// Poses within the factor of the minimum before suppression.
    pub raw_poses: usize,
    /// Candidates after suppression.
    pub after_suppression: usize,
    /// Candidates dropped by the filters.
    pub filtered: FilterCounts,
    /// Branch-and-bound statistics.
    pub search: SearchStats,
    /// Why the result is empty, when it is.
    pub message: Option<String>,
    /// Seconds per stage.
    pub seconds: StageSeconds,
}

impl<'m> Localizer<'m> {
    /// Prepares a map: edges, tensor, pyramid, spatial index.
    pub fn new(map: &'m OsmMap, options: LocalizeOptions) -> Result<Localizer<'m>> {
        let t = Instant::now();
        let edges = map_edges(map);
        let edge_grid = EdgeGrid::new(&edges, 25.0);
        let index = MapIndex::new(map);
        let edges_s = t.elapsed().as_secs_f64();
        let t = Instant::now();
        let dt = DtTensor::build(&edges, &options.chamfer)?;
        let dt_s = t.elapsed().as_secs_f64();
        let t = Instant::now();
        let pyramid = BoundPyramid::build(&dt, options.search.levels);
        let pyr_s = t.elapsed().as_secs_f64();
        let domain = match bounding_box(&edges) {
            Some((min, max)) => {
                let m = options.search.pose_margin_m;
                Domain::from_box(&dt, [min[0] - m, min[1] - m], [max[0] + m, max[1] + m])
            }
            None => Domain {
                i0: 0,
                j0: 0,
                i1: 0,
                j1: 0,
            },
        };
        Ok(Localizer {
            map,
            options,
            edges,
            edge_grid,
            dt,
            pyramid,
            domain,
            seconds: MapSeconds {
                edges: edges_s,
                distance_transform: dt_s,
                pyramid: pyr_s,
            },
            index,
        })
    }

    /// Localizes a gravity-levelled scan given as points in the sensor frame.
    pub fn localize_points(&self, points: &[[f64; 3]]) -> Result<Localization> {
        let t0 = Instant::now();
        let cells = vertical_cells(points, &self.options.surfaces)?;
        let surfaces_s = t0.elapsed().as_secs_f64();
        let t = Instant::now();
        let segments = extract_segments(&cells, &self.options.segments);
        let segments_s = t.elapsed().as_secs_f64();
        let mut out = self.localize_segments(&segments);
        out.vertical_cells = cells.len();
        out.seconds.surfaces = surfaces_s;
        out.seconds.segments = segments_s;
        out.seconds.total = t0.elapsed().as_secs_f64();
        if segments.is_empty() {
            out.message = Some(format!(
                "no vertical structure found in the scan ({} points, {} vertical-surface cells, no segment ≥ {} m); nothing to match",
                points.len(),
                cells.len(),
                self.options.segments.final_min_length_m
            ));
        }
        Ok(out)
    }

    /// Localizes scan segments given in the sensor frame.
    pub fn localize_segments(&self, segments: &[Segment]) -> Localization {
        let t0 = Instant::now();
        let mut out = Localization {
            segments: segments.to_vec(),
            candidates: Vec::new(),
            rank_by: self.options.rank_by,
            confidence: 0.0,
            vertical_cells: 0,
            raw_poses: 0,
            after_suppression: 0,
            filtered: FilterCounts::default(),
            search: SearchStats::default(),
            message: None,
            seconds: StageSeconds::default(),
        };
        if self.edges.is_empty() {
            out.message = Some("the map has no building outlines; nothing to match against".into());
            return out;
        }
        if segments.is_empty() {
            out.message = Some("the scan has no segments; nothing to match".into());
            return out;
        }
        let o = &self.options;
        let t = Instant::now();
        let n_yaw = ((360.0 / o.search.yaw_step_deg).round() as usize).max(1);
        let templates: Vec<Template> = (0..n_yaw)
            .into_par_iter()
            .map(|k| {
                let yaw = k as f64 * std::f64::consts::TAU / n_yaw as f64;
                build_template(segments, yaw, &self.dt, self.pyramid.top())
            })
            .collect();
        out.seconds.templates = t.elapsed().as_secs_f64();
        let t = Instant::now();
        let (mut raw, stats) = search(
            &self.dt,
            &self.pyramid,
            &templates,
            self.domain,
            o.search.keep_factor,
        );
        if o.search.max_raw_poses > 0 {
            raw.truncate(o.search.max_raw_poses);
        }
        out.search = stats;
        out.raw_poses = raw.len();
        out.seconds.search = t.elapsed().as_secs_f64();
        let t = Instant::now();
        let suppressed = suppress(
            &raw,
            &templates,
            &self.dt,
            o.search.nms_radius_m,
            o.search.nms_yaw_rad,
        );
        out.after_suppression = suppressed.len();
        let has_streets = !self.map.streets.segments.is_empty();
        let (kept, counts) = filter(
            suppressed,
            &self.index,
            has_streets,
            o.search.street_distance_m,
        );
        out.filtered = counts;
        out.seconds.filter = t.elapsed().as_secs_f64();
        let t = Instant::now();
        let mut cands: Vec<Candidate> = kept
            .par_iter()
            .map(|c| Candidate {
                pose: c.pose,
                costs: self.costs_at(segments, c.pose, c.dcm),
                refined: false,
                confidence: 0.0,
            })
            .collect();
        out.seconds.visibility_costs = t.elapsed().as_secs_f64();
        let t = Instant::now();
        self.sort(&mut cands);
        let top = o.refine_top.min(cands.len());
        cands[..top].par_iter_mut().for_each(|c| {
            let visible = visible_segments(
                &self.edges,
                &self.edge_grid,
                [c.pose.x, c.pose.y],
                &o.visibility,
            );
            let pose = refine_pose(segments, &visible, c.pose, &o.refine);
            c.pose = pose;
            c.costs = self.costs_at(segments, pose, c.costs.dcm);
            c.refined = true;
        });
        self.sort(&mut cands);
        out.seconds.refine = t.elapsed().as_secs_f64();
        let ranked_costs: Vec<f64> = cands.iter().map(|c| c.costs.get(o.rank_by)).collect();
        let ranked_poses: Vec<Pose2> = cands.iter().map(|c| c.pose).collect();
        out.confidence = confidence(&ranked_costs, &ranked_poses, o.distinct_m, o.distinct_rad);
        if let Some(first) = cands.first_mut() {
            first.confidence = out.confidence;
        }
        if cands.is_empty() {
            out.message = Some(format!(
                "no candidate pose survived ({} raw poses, {} after suppression, {} inside buildings, {} farther than {} m from streets); is the scan inside the map?",
                out.raw_poses,
                out.after_suppression,
                counts.inside_building,
                counts.far_from_street,
                o.search.street_distance_m
            ));
        }
        out.candidates = cands;
        out.seconds.total = t0.elapsed().as_secs_f64();
        out
    }

    /// Forward, reverse and symmetric costs of the scan segments at a pose.
    pub fn costs_at(&self, segments: &[Segment], pose: Pose2, dcm: f64) -> Costs {
        let visible = visible_segments(
            &self.edges,
            &self.edge_grid,
            [pose.x, pose.y],
            &self.options.visibility,
        );
        let moved: Vec<Segment> = segments.iter().map(|s| s.transformed(&pose)).collect();
        costs(&moved, &visible, dcm, &self.options.cost)
    }

    /// The map edges visible from a position.
    pub fn visible_from(&self, p: [f64; 2]) -> Vec<Segment> {
        visible_segments(&self.edges, &self.edge_grid, p, &self.options.visibility)
    }

    fn sort(&self, cands: &mut Vec<Candidate>) {
        let costs: Vec<Costs> = cands.iter().map(|c| c.costs).collect();
        let poses: Vec<Pose2> = cands.iter().map(|c| c.pose).collect();
        let order = rank_order(&costs, &poses, self.options.rank_by);
        let sorted: Vec<Candidate> = order.iter().map(|&i| cands[i]).collect();
        *cands = sorted;
    }
}
