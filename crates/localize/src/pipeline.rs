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
    build_template, filter, search_capped, suppress, suppresses, Cap, Domain, FilterCounts, Masks,
    RawPose, SearchOptions, SearchStats, StreetFilter, Template,
};
use crate::chamfer::{BoundPyramid, ChamferOptions, DtTensor};
use crate::feasible::FeasibleMask;
use crate::heading::{HeadingCache, HeadingMask};
use crate::index::{PrepOptions, PreparedMap};
use crate::level::{level, LevelOptions, Levelling};
use crate::rank::{confidence, costs, rank_order, CostKind, CostOptions, Costs};
use crate::refine::{refine_pose, RefineOptions};
use crate::segments::{extract_segments, SegmentOptions};
use crate::sensor::{options_for_scan, ExtractOverrides, SensorChoice, SensorReport, Vehicle};
use crate::surfaces::{vertical_cells, SurfaceOptions};
use crate::visibility::{visible_segments, EdgeGrid, VisibilityOptions};
use crate::{LocalizeError, Pose2, Result, Segment, WithContext};
use geodata::osm::index::MapIndex;
use geodata::osm::OsmMap;
use rayon::prelude::*;
use serde::Serialize;
use std::time::Instant;

/// Every option of the chain.
#[derive(Debug, Clone, PartialEq)]
pub struct LocalizeOptions {
    /// How each scan's extraction options are chosen (sensor detected, named, or manual).
    pub sensor: SensorChoice,
    /// User values over the sensor's extraction options.
    pub overrides: ExtractOverrides,
    /// What carries the sensor: a car's poses head along a street.
    pub vehicle: Vehicle,
    /// Levelling of a tilted scan by its walls before the extraction (`None`, the default:
    /// the scan is taken as levelled).
    pub level: Option<LevelOptions>,
    /// Surface extraction under [`SensorChoice::Manual`].
    pub surfaces: SurfaceOptions,
    /// Segment extraction under [`SensorChoice::Manual`] (its seed and Hough settings are
    /// used under every choice).
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
    /// The best candidate is not accepted when its symmetric cost exceeds this and its
    /// d_DCM exceeds `max_accept_dcm_m`, metres (no pose explains the scan well: it may be
    /// outside the map); the candidates and their confidence are kept, with a message.
    pub max_accept_cost_m: f64,
    /// See `max_accept_cost_m`: a candidate whose segments lie on map edges (low d_DCM) is
    /// kept even when the visibility-aware costs are high (a building of the map missing in
    /// the world hides, in the map, the walls the scan sees behind it), metres.
    pub max_accept_dcm_m: f64,
}

impl Default for LocalizeOptions {
    fn default() -> Self {
        LocalizeOptions {
            sensor: SensorChoice::Auto,
            overrides: ExtractOverrides::default(),
            vehicle: Vehicle::Auto,
            level: None,
            surfaces: SurfaceOptions::default(),
            segments: SegmentOptions::default(),
            chamfer: ChamferOptions::default(),
            search: SearchOptions::default(),
            visibility: VisibilityOptions::default(),
            cost: CostOptions::default(),
            refine: RefineOptions::default(),
            rank_by: CostKind::Symmetric,
            refine_top: 5,
            distinct_m: 4.0,
            distinct_rad: 0.2,
            max_accept_cost_m: 1.8,
            max_accept_dcm_m: 1.0,
        }
    }
}

pub use crate::index::MapSeconds;

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
    /// The feasible poses of the domain (when the search is restricted to them).
    pub feasible: Option<FeasibleMask>,
    /// Map preparation times.
    pub seconds: MapSeconds,
    index: MapIndex<'m>,
    heading: HeadingCache,
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

/// The wall segments of one scan and how they were extracted.
#[derive(Debug, Clone, Serialize)]
pub struct ScanSegments {
    /// Segments in the sensor frame.
    pub segments: Vec<Segment>,
    /// The sensor the scan was processed as (`None` under manual options).
    pub sensor: Option<SensorReport>,
    /// Wall clearance used, metres.
    pub clearance_m: f64,
    /// What the levelling found and did (`None`: off).
    pub levelling: Option<Levelling>,
    /// Vertical-surface cells found.
    pub vertical_cells: usize,
    /// Shortest segment kept, metres.
    pub min_length_m: f64,
    /// Seconds of the surface extraction.
    pub surfaces_s: f64,
    /// Seconds of the segment extraction.
    pub segments_s: f64,
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
    /// The sensor the scan was processed as (`None` for segments given directly or manual
    /// options).
    pub sensor: Option<SensorReport>,
    /// Wall clearance the surface extraction used, metres (0 for segments given directly).
    pub clearance_m: f64,
    /// What the levelling of the scan found and did (`None`: off, or segments given).
    pub levelling: Option<Levelling>,
    /// Vertical-surface cells found.
    pub vertical_cells: usize,
    /// Poses within the factor of the minimum before suppression.
    pub raw_poses: usize,
    /// Candidates after suppression.
    pub after_suppression: usize,
    /// Candidates dropped after refinement, for having converged on a better-ranked one.
    pub refined_duplicates: usize,
    /// Candidates dropped by the filters.
    pub filtered: FilterCounts,
    /// Branch-and-bound statistics.
    pub search: SearchStats,
    /// Why the result is empty or not accepted, when it is.
    pub message: Option<String>,
    /// Whether the best candidate of the scan's own search passes the acceptance gate
    /// ([`LocalizeOptions::max_accept_cost_m`]); false without candidates. Track mode
    /// re-ranks the candidates and leaves it as the search set it.
    pub accepted: bool,
    /// Seconds per stage.
    pub seconds: StageSeconds,
    /// In a track: the run of scans whose answers were refined with this one, and the
    /// odometry drift estimated over it (`None` outside a run).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub odometry_run: Option<crate::graph::OdometryRun>,
}

impl Localization {
    /// A localization with nothing found yet.
    pub fn empty(rank_by: CostKind) -> Localization {
        Localization {
            segments: Vec::new(),
            candidates: Vec::new(),
            rank_by,
            confidence: 0.0,
            sensor: None,
            clearance_m: 0.0,
            levelling: None,
            vertical_cells: 0,
            raw_poses: 0,
            after_suppression: 0,
            refined_duplicates: 0,
            filtered: FilterCounts::default(),
            search: SearchStats::default(),
            message: None,
            accepted: false,
            seconds: StageSeconds::default(),
            odometry_run: None,
        }
    }

    /// Records how the scan's walls were extracted (sensor, clearance, cells, stage times);
    /// the extraction seconds are added to the total.
    pub fn record_extraction(&mut self, extracted: &ScanSegments) {
        self.sensor = extracted.sensor;
        self.clearance_m = extracted.clearance_m;
        self.levelling = extracted.levelling;
        self.vertical_cells = extracted.vertical_cells;
        self.seconds.surfaces = extracted.surfaces_s;
        self.seconds.segments = extracted.segments_s;
        self.seconds.total += extracted.surfaces_s + extracted.segments_s;
    }

    /// [`Localization::record_extraction`] of a scan of `points` points, and why nothing was
    /// matched when it yielded no segment.
    pub fn record_scan(&mut self, extracted: &ScanSegments, points: usize) {
        self.record_extraction(extracted);
        if extracted.segments.is_empty() {
            self.message = Some(format!(
                "no vertical structure found in the scan ({points} points, {} vertical-surface cells, no segment ≥ {} m); nothing to match",
                extracted.vertical_cells, extracted.min_length_m
            ));
        }
    }
}

impl<'m> Localizer<'m> {
    /// Prepares a map: edges, tensor, pyramid, spatial index.
    pub fn new(map: &'m OsmMap, options: LocalizeOptions) -> Result<Localizer<'m>> {
        let prepared = PreparedMap::build(map, &options.chamfer, &options.search)?;
        Localizer::with_prepared(map, options, prepared)
    }

    /// A localizer on the map of `path` ([`crate::index::load_map_or_index`]): taken from its
    /// index when one was read, prepared now otherwise.
    pub fn prepared_or_new(
        map: &'m OsmMap,
        prepared: Option<PreparedMap>,
        options: LocalizeOptions,
        path: &std::path::Path,
    ) -> Result<Localizer<'m>> {
        match prepared {
            Some(p) => Localizer::with_prepared(map, options, p)
                .context_with(|| format!("using the map index {}", path.display())),
            None => Localizer::new(map, options)
                .context_with(|| format!("preparing the map {}", path.display())),
        }
    }

    /// A localizer on a map prepared before (e.g. read from an index, [`PreparedMap::read`]);
    /// an error when the preparation options differ from `options`'.
    pub fn with_prepared(
        map: &'m OsmMap,
        options: LocalizeOptions,
        prepared: PreparedMap,
    ) -> Result<Localizer<'m>> {
        let wanted = PrepOptions::of(&options.chamfer, &options.search);
        let differ = prepared.options.differences(&wanted);
        if !differ.is_empty() {
            return Err(LocalizeError::PrepMismatch {
                differences: differ.join("; "),
            });
        }
        let t = Instant::now();
        let edge_grid = EdgeGrid::new(&prepared.edges, 25.0);
        let index = MapIndex::new(map);
        let mut seconds = prepared.seconds;
        seconds.edges += t.elapsed().as_secs_f64();
        Ok(Localizer {
            map,
            options,
            edges: prepared.edges,
            edge_grid,
            dt: prepared.dt,
            pyramid: prepared.pyramid,
            domain: prepared.domain,
            feasible: prepared.feasible,
            seconds,
            index,
            heading: HeadingCache::default(),
        })
    }

    /// The wall segments of a gravity-levelled scan (sensor frame), with the sensor it was
    /// processed as.
    pub fn scan_segments(&self, points: &[[f64; 3]]) -> Result<ScanSegments> {
        scan_segments(&self.options, points)
    }

    /// Localizes a gravity-levelled scan given as points in the sensor frame.
    pub fn localize_points(&self, points: &[[f64; 3]]) -> Result<Localization> {
        let t0 = Instant::now();
        let extracted = self.scan_segments(points)?;
        let mut out = self.localize_scan(&extracted);
        out.record_scan(&extracted, points.len());
        out.seconds.total = t0.elapsed().as_secs_f64();
        Ok(out)
    }

    /// Localizes scan segments given in the sensor frame (no sensor known: the pose prior
    /// of [`Vehicle::Auto`] is off).
    pub fn localize_segments(&self, segments: &[Segment]) -> Localization {
        self.localize_segments_seen_from(segments, &[[0.0, 0.0]])
    }

    /// Localizes scan segments at any heading, whatever the vehicle (track mode's own search
    /// of each scan).
    pub(crate) fn localize_free(&self, segments: &[Segment]) -> Localization {
        self.localize_inner(segments, &[[0.0, 0.0]], false)
    }

    /// Localizes the segments of an extracted scan, with the pose prior of the sensor it was
    /// processed as (the extraction itself is not recorded in the result).
    pub fn localize_scan(&self, scan: &ScanSegments) -> Localization {
        let along = self.options.vehicle.along_streets(scan.sensor.as_ref());
        self.localize_inner(&scan.segments, &[[0.0, 0.0]], along)
    }

    /// Localizes segments gathered from several sensor positions (`views`, in the segments'
    /// frame): the visibility-aware costs use the map edges visible from any of them.
    pub fn localize_segments_seen_from(
        &self,
        segments: &[Segment],
        views: &[[f64; 2]],
    ) -> Localization {
        let along = self.options.vehicle.along_streets(None);
        self.localize_inner(segments, views, along)
    }

    /// The search and finishing stages; `along_streets`: poses must head along a street (the
    /// search visits only those a car can have, [`HeadingMask`]).
    fn localize_inner(
        &self,
        segments: &[Segment],
        views: &[[f64; 2]],
        along_streets: bool,
    ) -> Localization {
        let t0 = Instant::now();
        let mut out = Localization::empty(self.options.rank_by);
        out.segments = segments.to_vec();
        if self.edges.is_empty() {
            out.message = Some("the map has no building outlines; nothing to match against".into());
            return out;
        }
        if segments.is_empty() {
            out.message = Some("the scan has no segments; nothing to match".into());
            return out;
        }
        let t = Instant::now();
        let templates = templates_on(segments, &self.dt, self.pyramid.top(), &self.options);
        out.seconds.templates = t.elapsed().as_secs_f64();
        let t = Instant::now();
        let heading = along_streets
            .then(|| self.car_headings(&templates))
            .flatten();
        let (raw, stats) = self.search_masked(&templates, heading.as_deref());
        out.search = stats;
        out.seconds.search = t.elapsed().as_secs_f64();
        let place = |_: [f64; 2]| -> &dyn Place { self };
        finish(
            &mut out,
            &self.options,
            Scan {
                segments,
                views,
                templates: &templates,
                along_streets,
            },
            raw,
            &self.dt,
            &place,
        );
        out.seconds.total = t0.elapsed().as_secs_f64();
        out
    }

    /// The heading mask of a car's search with `templates` ([`HeadingMask`], built on first
    /// use and kept); `None` on a map without streets.
    pub fn car_headings(&self, templates: &[Template]) -> Option<std::sync::Arc<HeadingMask>> {
        heading_mask(
            &self.heading,
            &self.map.streets.segments,
            &self.dt,
            self.domain,
            templates,
            &self.options.search,
            self.pyramid.top(),
        )
    }

    /// Every pose of this map's domain (feasible ones only when the search is restricted,
    /// and only those `heading` allows when given: a car's scan) whose cost is within the
    /// factor of the minimum over them, sorted, in this tensor's cells, the first
    /// `max_raw_poses` of them ([`search_capped`]; within `max_boxes`, the cheapest found).
    pub fn search_masked(
        &self,
        templates: &[Template],
        heading: Option<&HeadingMask>,
    ) -> (Vec<RawPose>, SearchStats) {
        let cap = Cap {
            count: self.options.search.max_raw_poses,
            max_boxes: self.options.search.max_boxes,
            ..Cap::NONE
        };
        let (raw, stats, _) = search_capped(
            &self.dt,
            &self.pyramid,
            templates,
            self.domain,
            Masks {
                feasible: self.feasible.as_ref(),
                heading,
            },
            self.options.search.keep_factor,
            cap,
        );
        (raw, stats)
    }

    /// Forward, reverse and symmetric costs of the scan segments at a pose.
    pub fn costs_at(&self, segments: &[Segment], pose: Pose2, dcm: f64) -> Costs {
        self.costs_seen_from(segments, pose, dcm, &[[0.0, 0.0]])
    }

    /// Costs of segments gathered from several sensor positions (`views`, segment frame).
    pub fn costs_seen_from(
        &self,
        segments: &[Segment],
        pose: Pose2,
        dcm: f64,
        views: &[[f64; 2]],
    ) -> Costs {
        costs_from(self, &self.options, segments, pose, dcm, views)
    }

    /// The map edges visible from any of `views` (segment frame) placed at `pose`.
    pub(crate) fn visible_from_views(&self, pose: &Pose2, views: &[[f64; 2]]) -> Vec<Segment> {
        visible_from_views(self, &self.options.visibility, pose, views)
    }

    /// Whether a pose passes the search's filter: outside every building and, on a map with
    /// streets, within the street distance of one.
    pub(crate) fn pose_allowed(&self, pose: &Pose2) -> bool {
        let p = [pose.x, pose.y];
        self.index.building_at(p).is_none()
            && (self.map.streets.segments.is_empty()
                || self
                    .index
                    .nearest_segment(p)
                    .is_some_and(|(_, d)| d <= self.options.search.street_distance_m))
    }

    /// The map edges visible from a position.
    pub fn visible_from(&self, p: [f64; 2]) -> Vec<Segment> {
        visible_segments(&self.edges, &self.edge_grid, p, &self.options.visibility)
    }

    pub(crate) fn sort(&self, cands: &mut Vec<Candidate>) {
        sort_candidates(cands, self.options.rank_by);
    }
}

/// The wall segments of a gravity-levelled scan (sensor frame), with the sensor it was
/// processed as (the map plays no part).
pub fn scan_segments(options: &LocalizeOptions, points: &[[f64; 3]]) -> Result<ScanSegments> {
    let t0 = Instant::now();
    crate::surfaces::check_points(points)?;
    let levelled;
    let (points, levelling) = match &options.level {
        Some(lo) => {
            let mut copy = points.to_vec();
            let l = level(&mut copy, lo);
            levelled = copy;
            (levelled.as_slice(), Some(l))
        }
        None => (points, None),
    };
    let (sensor, surfaces, mut segment_options) = options_for_scan(
        options.sensor,
        &options.overrides,
        (&options.surfaces, &options.segments),
        points,
    );
    segment_options.seed = options.segments.seed;
    let cells = vertical_cells(points, &surfaces)?;
    let surfaces_s = t0.elapsed().as_secs_f64();
    let t = Instant::now();
    let segments = extract_segments(&cells, &segment_options);
    Ok(ScanSegments {
        segments,
        sensor,
        clearance_m: surfaces.clearance_m,
        levelling,
        vertical_cells: cells.len(),
        min_length_m: segment_options.final_min_length_m,
        surfaces_s,
        segments_s: t.elapsed().as_secs_f64(),
    })
}

/// What the finishing stages need of the map around a pose: its buildings and streets (the
/// filters) and its outline edges (visibility). A whole map's [`Localizer`] is one; a tiled
/// map's tiles are others ([`crate::tiles`]).
pub trait Place: Sync {
    /// The spatial index of the buildings and streets.
    fn map_index(&self) -> &MapIndex<'_>;
    /// Whether the map has street segments (else the street filter is off).
    fn has_streets(&self) -> bool;
    /// The outline edges and their buckets.
    fn edges(&self) -> (&[Segment], &EdgeGrid);
}

impl Place for Localizer<'_> {
    fn map_index(&self) -> &MapIndex<'_> {
        &self.index
    }
    fn has_streets(&self) -> bool {
        !self.map.streets.segments.is_empty()
    }
    fn edges(&self) -> (&[Segment], &EdgeGrid) {
        (&self.edges, &self.edge_grid)
    }
}

/// The map edges of `place` visible from any of `views` (segment frame) placed at `pose`.
pub(crate) fn visible_from_views(
    place: &dyn Place,
    options: &VisibilityOptions,
    pose: &Pose2,
    views: &[[f64; 2]],
) -> Vec<Segment> {
    let (edges, grid) = place.edges();
    let mut out = Vec::new();
    for v in views {
        out.extend(visible_segments(edges, grid, pose.apply(*v), options));
    }
    out
}

/// Costs of segments gathered from `views` at `pose` against the edges of `place`.
fn costs_from(
    place: &dyn Place,
    o: &LocalizeOptions,
    segments: &[Segment],
    pose: Pose2,
    dcm: f64,
    views: &[[f64; 2]],
) -> Costs {
    let visible = visible_from_views(place, &o.visibility, &pose, views);
    let moved: Vec<Segment> = segments.iter().map(|s| s.transformed(&pose)).collect();
    costs(&moved, &visible, dcm, &o.cost)
}

/// Sorts candidates by the ranking cost (ties by pose).
pub(crate) fn sort_candidates(cands: &mut Vec<Candidate>, rank_by: CostKind) {
    let costs: Vec<Costs> = cands.iter().map(|c| c.costs).collect();
    let poses: Vec<Pose2> = cands.iter().map(|c| c.pose).collect();
    let order = rank_order(&costs, &poses, rank_by);
    let sorted: Vec<Candidate> = order.iter().map(|&i| cands[i]).collect();
    *cands = sorted;
}

/// The yaw templates of scan segments on the lattice of `dt` (every `yaw_step_deg`).
pub fn templates_on(
    segments: &[Segment],
    dt: &DtTensor,
    levels: u32,
    o: &LocalizeOptions,
) -> Vec<Template> {
    let n_yaw = ((360.0 / o.search.yaw_step_deg).round() as usize).max(1);
    (0..n_yaw)
        .into_par_iter()
        .map(|k| {
            let yaw = k as f64 * std::f64::consts::TAU / n_yaw as f64;
            build_template(segments, yaw, dt, levels)
        })
        .collect()
}

/// The heading mask of a car's search on the tensor window `dt` ([`HeadingMask`]): the
/// street filter's distance and angle over `streets`, kept in `cache` for the next scan;
/// `None` without streets (the street filters are then off too).
pub fn heading_mask(
    cache: &HeadingCache,
    streets: &[geodata::osm::model::StreetSegment],
    dt: &DtTensor,
    domain: Domain,
    templates: &[Template],
    search: &SearchOptions,
    top: u32,
) -> Option<std::sync::Arc<HeadingMask>> {
    if streets.is_empty() {
        return None;
    }
    let max_rad = search.along_street_deg.to_radians();
    let key = (
        templates.len(),
        search.street_distance_m.to_bits(),
        max_rad.to_bits(),
        top,
    );
    cache.get_or_build(key, || {
        let yaws: Vec<f64> = templates.iter().map(|t| t.yaw_rad).collect();
        Some(HeadingMask::build(
            streets,
            dt,
            domain,
            &yaws,
            search.street_distance_m,
            max_rad,
            top,
        ))
    })
}

/// The scan as the finishing stages see it.
#[derive(Clone, Copy)]
pub(crate) struct Scan<'a> {
    /// Its segments (sensor frame).
    pub segments: &'a [Segment],
    /// The sensor positions they were gathered from.
    pub views: &'a [[f64; 2]],
    /// Its templates, one per yaw.
    pub templates: &'a [Template],
    /// Whether its poses must head along a street (a car's scan).
    pub along_streets: bool,
}

/// Ranked candidates without those that refinement brought within the suppression radius and
/// yaw of a better-ranked one (two starting poses that converge are one candidate).
fn without_refined_duplicates(
    ranked: Vec<Candidate>,
    radius_m: f64,
    yaw_rad: f64,
) -> Vec<Candidate> {
    let mut kept: Vec<Candidate> = Vec::with_capacity(ranked.len());
    for c in ranked {
        // Unrefined candidates were suppressed against each other already.
        let duplicate = kept
            .iter()
            .any(|k| (k.refined || c.refined) && suppresses(&k.pose, &c.pose, radius_m, yaw_rad));
        if !duplicate {
            kept.push(c);
        }
    }
    kept
}

/// The stages after the search: raw poses (sorted, in the cells of `lattice`, within the
/// factor of the minimum) → truncation → suppression → filters → costs → ranking →
/// refinement → confidence, into `out`; `place` gives the map around a pose.
pub(crate) fn finish<'p>(
    out: &mut Localization,
    o: &LocalizeOptions,
    scan: Scan<'_>,
    mut raw: Vec<RawPose>,
    lattice: &DtTensor,
    place: &(dyn Sync + Fn([f64; 2]) -> &'p dyn Place),
) {
    let Scan {
        segments,
        views,
        templates,
        along_streets,
    } = scan;
    if o.search.max_raw_poses > 0 {
        raw.truncate(o.search.max_raw_poses);
    }
    out.raw_poses = raw.len();
    let t = Instant::now();
    let suppressed = suppress(
        &raw,
        templates,
        lattice,
        o.search.nms_radius_m,
        o.search.nms_yaw_rad,
    );
    out.after_suppression = suppressed.len();
    let (kept, counts) = filter(
        suppressed,
        |p| {
            let pl = place(p);
            (pl.map_index(), pl.has_streets())
        },
        StreetFilter {
            distance_m: o.search.street_distance_m,
            along_rad: along_streets.then(|| o.search.along_street_deg.to_radians()),
        },
    );
    out.filtered = counts;
    out.seconds.filter = t.elapsed().as_secs_f64();
    let t = Instant::now();
    let at = |pose: &Pose2| place([pose.x, pose.y]);
    let mut cands: Vec<Candidate> = kept
        .par_iter()
        .map(|c| Candidate {
            pose: c.pose,
            costs: costs_from(at(&c.pose), o, segments, c.pose, c.dcm, views),
            refined: false,
            confidence: 0.0,
        })
        .collect();
    out.seconds.visibility_costs = t.elapsed().as_secs_f64();
    let t = Instant::now();
    sort_candidates(&mut cands, o.rank_by);
    let top = o.refine_top.min(cands.len());
    cands[..top].par_iter_mut().for_each(|c| {
        let here = at(&c.pose);
        let visible = visible_from_views(here, &o.visibility, &c.pose, views);
        let pose = refine_pose(segments, &visible, c.pose, &o.refine);
        c.pose = pose;
        c.costs = costs_from(here, o, segments, pose, c.costs.dcm, views);
        c.refined = true;
    });
    sort_candidates(&mut cands, o.rank_by);
    let before = cands.len();
    cands = without_refined_duplicates(cands, o.search.nms_radius_m, o.search.nms_yaw_rad);
    out.refined_duplicates = before - cands.len();
    out.seconds.refine = t.elapsed().as_secs_f64();
    let ranked_costs: Vec<f64> = cands.iter().map(|c| c.costs.get(o.rank_by)).collect();
    let ranked_poses: Vec<Pose2> = cands.iter().map(|c| c.pose).collect();
    out.confidence = confidence(&ranked_costs, &ranked_poses, o.distinct_m, o.distinct_rad);
    if let Some(first) = cands.first_mut() {
        first.confidence = out.confidence;
    }
    if let Some(best) = cands.first() {
        out.accepted =
            !(best.costs.symmetric > o.max_accept_cost_m && best.costs.dcm > o.max_accept_dcm_m);
        if !out.accepted {
            // Kept, not dropped: a car's scan of a real street sees mostly things no map
            // holds (parked cars, hedges, trees), so its true pose can cost this much too.
            out.message = Some(format!(
                "no pose explains the scan well: the best candidate's symmetric cost is {:.2} m > {:.2} m and its d_DCM {:.2} m > {:.2} m; the scan may be outside the map, or see mostly things the map does not hold; its {} candidates are kept",
                best.costs.symmetric,
                o.max_accept_cost_m,
                best.costs.dcm,
                o.max_accept_dcm_m,
                cands.len()
            ));
        }
    } else {
        out.message = Some(format!(
            "no candidate pose survived ({} raw poses, {} after suppression, {} inside buildings, {} farther than {} m from streets, {} heading across the streets near them); the scan is probably outside the map",
            out.raw_poses,
            out.after_suppression,
            counts.inside_building,
            counts.far_from_street,
            o.search.street_distance_m,
            counts.across_streets
        ));
    }
    out.candidates = cands;
}

#[cfg(test)]
mod tests {
    use super::*;
    use geodata::osm::model::{Building, OsmStats, StreetNetwork, StreetSegment};
    use geodata::projection::LocalFrame;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    fn rect(c: [f64; 2], hw: f64, hh: f64, ang: f64) -> Vec<[f64; 2]> {
        let (s, co) = ang.sin_cos();
        [(-hw, -hh), (hw, -hh), (hw, hh), (-hw, hh)]
            .iter()
            .map(|&(x, y)| [c[0] + co * x - s * y, c[1] + s * x + co * y])
            .collect()
    }

    fn map_of(rings: Vec<Vec<[f64; 2]>>) -> OsmMap {
        OsmMap {
            frame: LocalFrame::new(48.15, 11.57).unwrap(),
            bbox_lonlat: [11.5, 48.1, 11.6, 48.2],
            buildings: rings
                .into_iter()
                .enumerate()
                .map(|(i, outer)| Building::outline(i as i64, outer, Vec::new()))
                .collect(),
            highways: Vec::new(),
            streets: StreetNetwork::default(),
            stats: OsmStats::default(),
        }
    }

    /// A random block of rectangular buildings, 200 m × 200 m.
    fn random_city(seed: u64) -> OsmMap {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let mut rings = Vec::new();
        for gx in 0..5 {
            for gy in 0..5 {
                let c = [
                    gx as f64 * 40.0 + rng.gen_range(-4.0..4.0),
                    gy as f64 * 40.0 + rng.gen_range(-4.0..4.0),
                ];
                let (hw, hh) = (rng.gen_range(5.0..13.0), rng.gen_range(5.0..13.0));
                rings.push(rect(c, hw, hh, rng.gen_range(-0.3..0.3)));
            }
        }
        map_of(rings)
    }

    /// Points on vertical walls over segments given in the sensor frame.
    fn wall_points(segments: &[Segment]) -> Vec<[f64; 3]> {
        let mut pts = Vec::new();
        for s in segments {
            let n = (s.length() / 0.1) as usize;
            for i in 0..=n {
                let t = i as f64 / n.max(1) as f64;
                let p = [
                    s.a[0] + t * (s.b[0] - s.a[0]),
                    s.a[1] + t * (s.b[1] - s.a[1]),
                ];
                for k in 0..40 {
                    pts.push([p[0], p[1], -0.4 + k as f64 * 0.2]);
                }
            }
        }
        pts
    }

    fn scan_from(localizer: &Localizer<'_>, truth: Pose2) -> Vec<[f64; 3]> {
        let visible = localizer.visible_from([truth.x, truth.y]);
        let (s, c) = truth.yaw_rad.sin_cos();
        let to_scan = |p: [f64; 2]| {
            let (dx, dy) = (p[0] - truth.x, p[1] - truth.y);
            [c * dx + s * dy, -s * dx + c * dy]
        };
        let in_sensor: Vec<Segment> = visible
            .iter()
            .map(|v| Segment::new(to_scan(v.a), to_scan(v.b)))
            .collect();
        wall_points(&in_sensor)
    }

    #[test]
    fn candidates_that_refinement_brought_together_are_one() {
        let cand = |x: f64, yaw_rad: f64, refined: bool| Candidate {
            pose: Pose2 { x, y: 0.0, yaw_rad },
            costs: Costs {
                dcm: 0.0,
                forward: 0.0,
                reverse: 0.0,
                symmetric: x,
            },
            refined,
            confidence: 0.0,
        };
        let cases: [(Vec<Candidate>, &[f64]); 3] = [
            // A refined candidate 0.5 m from a better refined one goes; one 3 m away stays.
            (
                vec![
                    cand(0.0, 0.0, true),
                    cand(0.5, 0.0, true),
                    cand(3.0, 0.0, true),
                ],
                &[0.0, 3.0],
            ),
            // An unrefined candidate next to a refined one that moved onto it goes too...
            (
                vec![
                    cand(10.0, 0.0, true),
                    cand(10.4, 0.01, false),
                    cand(12.5, 0.0, false),
                ],
                &[10.0, 12.5],
            ),
            // ...but two unrefined ones are never compared (suppression kept them apart), and
            // a candidate at the same place heading another way is another candidate.
            (
                vec![
                    cand(20.0, 0.0, false),
                    cand(20.5, 0.0, false),
                    cand(20.2, 0.5, true),
                ],
                &[20.0, 20.5, 20.2],
            ),
        ];
        for (ranked, expected) in cases {
            let kept = without_refined_duplicates(ranked, 2.0, 10f64.to_radians());
            let xs: Vec<f64> = kept.iter().map(|c| c.pose.x).collect();
            assert_eq!(xs, expected);
        }
    }

    #[test]
    fn localizes_a_synthetic_scan_without_prior() {
        let map = random_city(4);
        let localizer = Localizer::new(&map, LocalizeOptions::default()).unwrap();
        let truth = Pose2 {
            x: 61.0,
            y: 79.0,
            yaw_rad: 2.0,
        };
        assert!(localizer.index.building_at([truth.x, truth.y]).is_none());
        let r = localizer
            .localize_points(&scan_from(&localizer, truth))
            .unwrap();
        let best = r.candidates.first().expect("a candidate");
        assert!(best.pose.distance_to(&truth) < 0.3, "{best:?}");
        assert!(best.pose.yaw_error_to(&truth) < 0.01, "{best:?}");
        assert!(r.message.is_none());
        assert!(r.accepted && r.confidence > 0.0, "{}", r.confidence);
    }

    /// Streets along x through the gaps between the rows of [`random_city`].
    fn with_streets_along_x(mut map: OsmMap) -> OsmMap {
        map.streets.segments = (0..5)
            .map(|k| {
                let y = 20.0 + 40.0 * k as f64;
                StreetSegment {
                    way_index: k,
                    index_in_way: 0,
                    from_node: 2 * k as i64,
                    to_node: 2 * k as i64 + 1,
                    a: [-40.0, y],
                    b: [200.0, y],
                    length_m: 240.0,
                    highway: "residential".into(),
                }
            })
            .collect();
        map
    }

    #[test]
    fn a_car_heads_along_the_street_it_is_on() {
        let map = with_streets_along_x(random_city(4));
        let truth = Pose2 {
            x: 61.0,
            y: 21.0,
            yaw_rad: 0.05,
        };
        let run = |vehicle: Vehicle, one_wall: bool| {
            let o = LocalizeOptions {
                vehicle,
                max_accept_cost_m: f64::INFINITY,
                ..LocalizeOptions::default()
            };
            let localizer = Localizer::new(&map, o).unwrap();
            assert!(localizer.index.building_at([truth.x, truth.y]).is_none());
            let scan = if one_wall {
                // An 8 m wall and a fence no map edge explains: the wall fits many places
                // and headings about as well.
                wall_points(&[
                    Segment::new([4.0, 6.0], [-4.0, 6.0]),
                    Segment::new([2.0, -3.0], [2.0, -7.0]),
                ])
            } else {
                scan_from(&localizer, truth)
            };
            localizer.localize_points(&scan).unwrap()
        };
        // The synthetic walls are detected as a terrestrial scanner: `auto` is free.
        assert_eq!(
            run(Vehicle::Auto, true).candidates,
            run(Vehicle::Free, true).candidates
        );
        let free = run(Vehicle::Free, true);
        let car = run(Vehicle::Car, true);
        assert_eq!(free.filtered.across_streets, 0);
        assert!(car.filtered.across_streets > 0, "{:?}", car.filtered);
        let along = |yaw: f64| {
            let t = yaw.rem_euclid(std::f64::consts::PI);
            t.min(std::f64::consts::PI - t) <= 20f64.to_radians() + 1e-9
        };
        // Before refinement every candidate of the car heads along a street (all run along
        // x); the free search keeps others.
        assert!(car
            .candidates
            .iter()
            .filter(|c| !c.refined)
            .all(|c| along(c.pose.yaw_rad)));
        assert!(free.candidates.iter().any(|c| !along(c.pose.yaw_rad)));
        // With the whole scene the car finds its pose.
        let car = run(Vehicle::Car, false);
        let best = car.candidates.first().expect("a candidate");
        assert!(best.pose.distance_to(&truth) < 0.3, "{best:?}");
        assert!(best.pose.yaw_error_to(&truth) < 0.01, "{best:?}");
    }

    #[test]
    fn map_without_buildings_gives_an_empty_result_with_a_message() {
        let map = map_of(Vec::new());
        let localizer = Localizer::new(&map, LocalizeOptions::default()).unwrap();
        let pts = wall_points(&[Segment::new([5.0, -5.0], [5.0, 5.0])]);
        let r = localizer.localize_points(&pts).unwrap();
        assert!(r.candidates.is_empty());
        assert!(
            r.message
                .as_deref()
                .unwrap_or("")
                .contains("no building outlines"),
            "{:?}",
            r.message
        );
        assert!(serde_json::to_string(&r).is_ok());
    }

    #[test]
    fn scan_without_vertical_structure_gives_an_empty_result_with_a_message() {
        let map = random_city(1);
        let localizer = Localizer::new(&map, LocalizeOptions::default()).unwrap();
        let ground: Vec<[f64; 3]> = (0..200)
            .flat_map(|i| {
                (0..200).map(move |j| [i as f64 * 0.2 - 20.0, j as f64 * 0.2 - 20.0, -1.8])
            })
            .collect();
        let r = localizer.localize_points(&ground).unwrap();
        assert!(r.candidates.is_empty());
        assert!(
            r.message
                .as_deref()
                .unwrap_or("")
                .contains("no vertical structure"),
            "{:?}",
            r.message
        );
        let r = localizer.localize_points(&[]).unwrap();
        assert!(r.candidates.is_empty() && r.message.is_some());
    }

    #[test]
    fn scan_of_a_place_outside_the_map_is_not_accepted_and_says_so() {
        let map = random_city(2);
        let mut options = LocalizeOptions::default();
        options.search.yaw_step_deg = 5.0;
        let localizer = Localizer::new(&map, options).unwrap();
        // A round courtyard of 12 walls: nothing like it is in the map.
        let ring: Vec<[f64; 2]> = (0..12)
            .map(|k| {
                let a = k as f64 * std::f64::consts::TAU / 12.0;
                [12.0 * a.cos(), 12.0 * a.sin()]
            })
            .collect();
        let walls: Vec<Segment> = (0..12)
            .map(|k| Segment::new(ring[k], ring[(k + 1) % 12]))
            .collect();
        let r = localizer.localize_points(&wall_points(&walls)).unwrap();
        // The candidates are kept for the user to judge, flagged: not accepted. Their
        // confidence (the margin to the next distinct pose) is the search's, not the gate's.
        assert!(!r.accepted);
        assert!(!r.candidates.is_empty());
        assert_eq!(r.candidates[0].confidence, r.confidence);
        assert!(
            r.message
                .as_deref()
                .unwrap_or("")
                .contains("outside the map"),
            "{:?}",
            r.message
        );
    }

    #[test]
    fn nan_point_is_an_error() {
        let map = random_city(3);
        let localizer = Localizer::new(&map, LocalizeOptions::default()).unwrap();
        let mut pts = wall_points(&[Segment::new([5.0, -5.0], [5.0, 5.0])]);
        pts[3][2] = f64::NAN;
        assert!(localizer.localize_points(&pts).is_err());
    }
}
