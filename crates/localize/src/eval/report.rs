//! The evaluation report of one dataset (`localize eval`): per scan the candidates ranked by
//! every cost and by the hashing baseline, and over the scans N_accurate of thesis §5.4.3
//! (k best candidates within radius w), the car-mounted 2 m / 3° counts of issue 15, the
//! track-mode counts, sensor profiles and per-stage timings. [`EvalReport::curves_svg`]
//! draws Figs. 5.5/5.6.

use super::{accurate_within, Accuracy};
use crate::candidates::{FilterCounts, SearchStats};
use crate::distractors::{DistractorOptions, DistractorSummary};
use crate::index::MapSeconds;
use crate::pipeline::{Localization, LocalizeOptions, Localizer, StageSeconds};
use crate::rank::{rank_order, CostKind, Costs};
use crate::sensor::SensorReport;
use crate::tiles::Manifest;
use crate::Pose2;
use serde::Serialize;
use std::collections::BTreeMap;
use std::fmt::Write as _;

/// How candidates are ranked for the evaluation: by one of the chamfer costs or by the
/// geometric-hashing baseline.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum RankMethod {
    /// d_DCM of the search (eq. 5.3).
    Dcm,
    /// Forward d_f (eq. 5.4).
    Forward,
    /// Reverse d_r (eq. 5.5).
    Reverse,
    /// Symmetric d_s.
    Symmetric,
    /// Geometric hashing of building corners.
    Hashing,
}

impl RankMethod {
    /// Every method, in table order.
    pub const ALL: [RankMethod; 5] = [
        RankMethod::Dcm,
        RankMethod::Forward,
        RankMethod::Reverse,
        RankMethod::Symmetric,
        RankMethod::Hashing,
    ];

    /// Name in tables and JSON keys.
    pub fn name(self) -> &'static str {
        match self {
            RankMethod::Dcm => "dcm",
            RankMethod::Forward => "forward",
            RankMethod::Reverse => "reverse",
            RankMethod::Symmetric => "symmetric",
            RankMethod::Hashing => "hashing",
        }
    }

    /// The thresholds an accurate pose must meet (thesis §5.4.3).
    pub fn accuracy(self) -> Accuracy {
        if self == RankMethod::Hashing {
            Accuracy::HASHING
        } else {
            Accuracy::THESIS
        }
    }
}

/// Search radii w of N_accurate, metres (the last: the whole map).
pub const RADII_M: [f64; 6] = [50.0, 100.0, 200.0, 500.0, 1000.0, f64::INFINITY];
/// Numbers k of best candidates of N_accurate.
pub const KS: [usize; 3] = [1, 5, 10];

/// A radius' name in tables and JSON keys (`"50"`, …, `"map"`).
pub fn radius_name(w: f64) -> String {
    if w.is_finite() {
        format!("{w:.0}")
    } else {
        "map".into()
    }
}

/// One scan localized: its truth, the candidates in every order and the hashing baseline's.
#[derive(Debug, Clone)]
pub struct ScanOutcome {
    /// Scan name.
    pub name: String,
    /// True pose.
    pub truth: Pose2,
    /// Candidate poses ranked by each chamfer cost (dcm, forward, reverse, symmetric).
    pub ranked: [Vec<Pose2>; 4],
    /// Costs of the localizer's top candidate.
    pub top_costs: Option<Costs>,
    /// Poses of the hashing baseline, best first (empty when it did not run).
    pub hashing: Vec<Pose2>,
    /// What the localizer returned.
    pub result: Localization,
    /// Seconds of the hashing baseline.
    pub hashing_seconds: f64,
}

impl ScanOutcome {
    /// Ranks `result`'s candidates by every cost.
    pub fn new(
        name: String,
        truth: Pose2,
        result: Localization,
        hashing: Vec<Pose2>,
        hashing_seconds: f64,
    ) -> Self {
        let costs: Vec<Costs> = result.candidates.iter().map(|c| c.costs).collect();
        let poses: Vec<Pose2> = result.candidates.iter().map(|c| c.pose).collect();
        let ranked = CostKind::ALL.map(|k| {
            rank_order(&costs, &poses, k)
                .into_iter()
                .map(|j| poses[j])
                .collect()
        });
        ScanOutcome {
            name,
            truth,
            ranked,
            top_costs: result.candidates.first().map(|c| c.costs),
            hashing,
            result,
            hashing_seconds,
        }
    }

    /// The poses in `method`'s order.
    pub fn ranked_by(&self, method: RankMethod) -> &[Pose2] {
        match method {
            RankMethod::Dcm => &self.ranked[0],
            RankMethod::Forward => &self.ranked[1],
            RankMethod::Reverse => &self.ranked[2],
            RankMethod::Symmetric => &self.ranked[3],
            RankMethod::Hashing => &self.hashing,
        }
    }

    /// Position (m) and heading (°) error of `method`'s top pose (NaN without one).
    pub fn top1_error(&self, method: RankMethod) -> Top1Error {
        self.error_of(self.ranked_by(method).first())
    }

    /// Position (m) and heading (°) error of a pose (NaN without one).
    fn error_of(&self, pose: Option<&Pose2>) -> Top1Error {
        pose.map_or(
            Top1Error {
                error_m: f64::NAN,
                error_deg: f64::NAN,
            },
            |p| Top1Error {
                error_m: p.distance_to(&self.truth),
                error_deg: p.yaw_error_to(&self.truth).to_degrees(),
            },
        )
    }

    /// Rank (1 = top) of the first of `poses` within 2 m / 3° of the truth.
    fn first_accurate_rank<'p>(&self, poses: impl IntoIterator<Item = &'p Pose2>) -> Option<usize> {
        poses
            .into_iter()
            .position(|p| Accuracy::STRICT.accepts(p, &self.truth))
            .map(|k| k + 1)
    }

    /// The result in the localizer's own order of its candidates.
    pub fn own_ranking(&self) -> OwnRanking {
        let own = &self.result.candidates;
        OwnRanking {
            top1: self.error_of(own.first().map(|c| &c.pose)),
            first_accurate_rank: self.first_accurate_rank(own.iter().map(|c| &c.pose)),
        }
    }
}

/// A scan's result in the localizer's own order of its candidates.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct OwnRanking {
    /// Error of the first candidate (NaN without one).
    pub top1: Top1Error,
    /// Rank (1 = top) of the first candidate within 2 m / 3° of the truth.
    pub first_accurate_rank: Option<usize>,
}

/// Error of a top-1 pose.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Top1Error {
    /// Position error, metres.
    pub error_m: f64,
    /// Heading error, degrees.
    pub error_deg: f64,
}

/// Position and heading thresholds.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Threshold {
    /// Metres.
    pub m: f64,
    /// Radians.
    pub rad: f64,
}

impl From<Accuracy> for Threshold {
    fn from(a: Accuracy) -> Self {
        Threshold {
            m: a.max_m,
            rad: a.max_rad,
        }
    }
}

/// The thresholds of N_accurate.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Thresholds {
    /// For the chamfer costs.
    pub chamfer: Threshold,
    /// For the hashing baseline.
    pub hashing: Threshold,
}

/// The distractor map a target was embedded in.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct DistractorsReport {
    /// The other map.
    pub map: String,
    /// Seed of the tiles.
    pub seed: u64,
    /// Ring width, metres.
    pub ring_m: f64,
    /// Gap to the target, metres.
    pub gap_m: f64,
    /// Tile side, metres.
    pub tile_m: f64,
    /// What was built.
    pub summary: DistractorSummary,
}

impl DistractorsReport {
    /// The report of a composition with `options` from the map at `map`.
    pub fn new(map: &str, options: &DistractorOptions, summary: DistractorSummary) -> Self {
        DistractorsReport {
            map: map.to_owned(),
            seed: options.seed,
            ring_m: options.ring_m,
            gap_m: options.gap_m,
            tile_m: options.tile_m,
            summary,
        }
    }
}

/// How a track was run (`--track K`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TrackSetup {
    /// Scans per window.
    pub window: usize,
    /// Odometry distance before the window through which chains still count, metres.
    pub history_m: f64,
    /// Relative odometry drift (0.02: 2 % of the distance).
    pub odometry_drift: f64,
    /// Heading drift, degrees per 50 m.
    pub odometry_yaw_drift_deg: f64,
    /// `None`: the drift is the same at every step (the worst case); `Some(seed)`: drawn per
    /// step within those bounds ([`crate::track::randomly_drifted_odometry`]).
    pub odometry_random_seed: Option<u64>,
    /// Whether the scans after each scan count too ([`crate::track::TrackOptions::smooth`]).
    pub smooth: bool,
    /// Whether a smoothed track's answers are refined together
    /// ([`crate::track::TrackOptions::refine_poses`]).
    pub pose_graph: bool,
}

/// Track-mode counts: the scans after the first window, judged in the localizer's order.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct TrackCounts {
    /// Scans per window.
    pub window: usize,
    /// Odometry distance before the window through which chains still count, metres.
    pub history_m: f64,
    /// Relative odometry drift.
    pub odometry_drift: f64,
    /// Heading drift, degrees per 50 m.
    pub odometry_yaw_drift_deg_per_50m: f64,
    /// `systematic` (the same drift at every step) or `random` (drawn per step).
    pub odometry_drift_kind: &'static str,
    /// The seed of a random drift (`null` for a systematic one).
    pub odometry_seed: Option<u64>,
    /// Scans after the first window.
    pub scans_after_first_window: usize,
    /// Of them, with the top candidate within 2 m and 3°.
    pub top1_within_2m_3deg: usize,
    /// Of them, with one of the top 10 within 2 m and 3°.
    pub top10_within_2m_3deg: usize,
    /// Every scan of the track, the first window's included.
    pub scans: usize,
    /// Of them, with the top candidate within 2 m and 3°.
    pub top1_within_2m_3deg_every_scan: usize,
    /// Whether the scans after each scan counted too (the default; `--causal`: only those
    /// before it, as a robot driving would).
    pub smoothed: bool,
    /// Whether the smoothed answers were moved to fit their walls and the odometry together
    /// (the default; `--no-pose-graph`: the chains' states as they are).
    pub pose_graph: bool,
    /// The cost whose chains rank the candidates (`reverse`, `symmetric`, …).
    pub cost: &'static str,
}

/// A count per chamfer cost.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct PerCost {
    /// d_DCM.
    pub dcm: usize,
    /// Forward.
    pub forward: usize,
    /// Reverse.
    pub reverse: usize,
    /// Symmetric.
    pub symmetric: usize,
}

/// Seconds preparing the map.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct MapPrepSeconds {
    /// Loading the map (or index).
    pub load_map: f64,
    /// Map edges.
    pub map_edges: f64,
    /// Distance-transform tensor.
    pub distance_transform: f64,
    /// Lower-bound pyramid.
    pub pyramid: f64,
    /// Feasible-pose mask.
    pub feasible_mask: f64,
    /// The hashing baseline's index.
    pub hashing_index: f64,
}

/// The distance-transform tensor's shape.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct TensorInfo {
    /// Cells along x.
    pub width: usize,
    /// Cells along y.
    pub height: usize,
    /// Orientation channels.
    pub channels: usize,
    /// Cell side, metres.
    pub grid_m: f64,
    /// Bytes held.
    pub bytes: usize,
}

/// Mean, median and maximum of a stage's seconds per scan.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct StageStats {
    /// Mean.
    pub mean: f64,
    /// Median (finite values).
    pub median: f64,
    /// Maximum.
    pub max: f64,
}

/// The true pose of a scan row.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct TruthRow {
    /// Metres east in the map frame.
    pub x: f64,
    /// Metres north.
    pub y: f64,
    /// Heading from grid east, radians.
    pub yaw_grid: f64,
}

/// One scan's row of the report.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ScanRow {
    /// Scan name.
    pub scan: String,
    /// True pose.
    pub truth: TruthRow,
    /// Wall segments extracted.
    pub segments: usize,
    /// Sensor profile the scan was processed as.
    pub sensor: Option<SensorReport>,
    /// Wall clearance above ground used, metres.
    pub clearance_m: f64,
    /// The scan's tilt estimated from its walls and whether it was levelled (`null`: off).
    pub level: Option<crate::level::Levelling>,
    /// Poses the search returned.
    pub raw_poses: usize,
    /// Search statistics.
    pub search: SearchStats,
    /// Candidates dropped by the filters, by reason.
    pub filtered: FilterCounts,
    /// Candidates after filtering.
    pub candidates: usize,
    /// Confidence of the top candidate.
    pub confidence: f64,
    /// Top-1 error per method.
    pub top1: BTreeMap<String, Top1Error>,
    /// Costs of the top candidate.
    pub top_costs: Option<Costs>,
    /// Per method, the rank (1 = top) of the first candidate within 2 m / 3° of the truth.
    pub first_accurate_rank: BTreeMap<String, Option<usize>>,
    /// The localizer's own order of the candidates (in track mode the chains' ranking, which
    /// the per-cost fields above re-sort; otherwise the default cost's).
    pub own_ranking: OwnRanking,
    /// Why the scan could not be localized, or why its best candidate is not accepted.
    pub message: Option<String>,
    /// Whether the best candidate of the scan's own search passes the acceptance gate (in
    /// track mode too, where the chains re-rank the candidates).
    pub accepted: bool,
    /// Seconds per stage.
    pub seconds: StageSeconds,
    /// Seconds of the hashing baseline.
    pub hashing_seconds: f64,
    /// Track mode: the run of scans the pose graph refined with this one and the odometry
    /// drift estimated over it (absent outside track mode, `null` outside a run).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub odometry_run: Option<Option<crate::graph::OdometryRun>>,
}

impl ScanRow {
    /// The row of one outcome.
    pub fn new(r: &ScanOutcome) -> Self {
        let top1 = RankMethod::ALL
            .iter()
            .map(|&m| (m.name().to_owned(), r.top1_error(m)))
            .collect();
        let first_accurate_rank = RankMethod::ALL
            .iter()
            .map(|&m| (m.name().to_owned(), r.first_accurate_rank(r.ranked_by(m))))
            .collect();
        ScanRow {
            scan: r.name.clone(),
            truth: TruthRow {
                x: r.truth.x,
                y: r.truth.y,
                yaw_grid: r.truth.yaw_rad,
            },
            segments: r.result.segments.len(),
            sensor: r.result.sensor,
            clearance_m: r.result.clearance_m,
            level: r.result.levelling,
            raw_poses: r.result.raw_poses,
            search: r.result.search,
            filtered: r.result.filtered,
            candidates: r.result.candidates.len(),
            confidence: r.result.confidence,
            top1,
            top_costs: r.top_costs,
            first_accurate_rank,
            own_ranking: r.own_ranking(),
            message: r.result.message.clone(),
            accepted: r.result.accepted,
            seconds: r.result.seconds,
            hashing_seconds: r.hashing_seconds,
            odometry_run: None,
        }
    }
}

/// N_accurate: method → k → radius name → scans.
pub type AccuracyTable = BTreeMap<String, BTreeMap<String, BTreeMap<String, usize>>>;

/// What the evaluation of one dataset measured (`localize eval --json`).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct EvalReport {
    /// The dataset folder.
    pub dataset: String,
    /// The map (or index) file.
    pub map: String,
    /// Scans evaluated.
    pub scans: usize,
    /// The thresholds of N_accurate.
    pub thresholds: Thresholds,
    /// The distractor map, when the target was embedded in one.
    pub distractors: Option<DistractorsReport>,
    /// Area searched, km².
    pub search_area_km2: f64,
    /// N_accurate per method, k and radius.
    pub n_accurate: AccuracyTable,
    /// Scans with an accurate candidate anywhere in the candidate set.
    pub accurate_in_candidate_set: usize,
    /// Scans whose top candidate is within 2 m and 3°, per cost.
    pub top1_within_2m_3deg: PerCost,
    /// Scans with one of the top 10 by d_r within 2 m and 3°.
    pub top10_within_2m_3deg_reverse: usize,
    /// Scans with one of the top 10 by d_s (the default ranking) within 2 m and 3°.
    pub top10_within_2m_3deg_symmetric: usize,
    /// Track-mode counts.
    pub track: Option<TrackCounts>,
    /// On a tiled map: scans for which the tiled search equals the whole map's
    /// ([`crate::tiles::is_exact`]); absent on one map.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub tiled_exact_scans: Option<usize>,
    /// Scans per sensor profile, in the order first seen (a JSON object).
    #[serde(serialize_with = "as_map")]
    pub sensors: Vec<(String, usize)>,
    /// Median position error of accurate top-1 poses (reverse), metres.
    pub median_error_accurate_top1_reverse_m: f64,
    /// Median position error of accurate top-1 poses (symmetric), metres.
    pub median_error_accurate_top1_symmetric_m: f64,
    /// Seconds preparing the map.
    pub map_seconds: MapPrepSeconds,
    /// The distance-transform tensor.
    pub tensor: TensorInfo,
    /// Seconds per scan and stage, in pipeline order (a JSON object).
    #[serde(serialize_with = "as_map")]
    pub stage_seconds: Vec<(String, StageStats)>,
    /// Worker threads.
    pub threads: usize,
    /// One row per scan.
    pub per_scan: Vec<ScanRow>,
    /// The methods evaluated, in table order.
    #[serde(skip)]
    pub methods: Vec<RankMethod>,
    /// Position cells of the search domain.
    #[serde(skip)]
    pub domain_cells: u64,
    /// Headings searched per cell.
    #[serde(skip)]
    pub yaws_per_cell: u64,
    /// Position cells the feasible-pose mask keeps.
    #[serde(skip)]
    pub feasible_cells: u64,
}

/// Serializes (key, value) pairs as a map.
fn as_map<S: serde::Serializer, V: Serialize>(
    pairs: &[(String, V)],
    serializer: S,
) -> Result<S::Ok, S::Error> {
    serializer.collect_map(pairs.iter().map(|(k, v)| (k, v)))
}

/// The median of the finite values (NaN if none).
fn median(mut v: Vec<f64>) -> f64 {
    v.retain(|x| x.is_finite());
    if v.is_empty() {
        return f64::NAN;
    }
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// The searched map as the report describes it: one prepared map or a tiled map.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MapFacts {
    /// Tensor cell, metres.
    pub grid_m: f64,
    /// Position cells of the search domain.
    pub domain_cells: u64,
    /// Position cells the feasible-pose mask keeps.
    pub feasible_cells: u64,
    /// Seconds preparing the map (zero for a tiled map: prepared by `localize index`).
    pub seconds: MapSeconds,
    /// Tensor width, height and channels (a tiled map: its lattice over the whole domain).
    pub tensor_dims: [usize; 3],
    /// Bytes of the tensor (a tiled map: the sum of its tiles' memory).
    pub tensor_bytes: usize,
}

impl MapFacts {
    /// The facts of a localizer's prepared map.
    pub fn of_localizer(localizer: &Localizer<'_>) -> MapFacts {
        let domain_cells = localizer.domain.cells();
        MapFacts {
            grid_m: localizer.dt.grid_m,
            domain_cells,
            feasible_cells: localizer
                .feasible
                .as_ref()
                .map_or(domain_cells, |m| m.feasible_cells),
            seconds: localizer.seconds,
            tensor_dims: [
                localizer.dt.width,
                localizer.dt.height,
                localizer.dt.channels,
            ],
            tensor_bytes: localizer.dt.bytes(),
        }
    }

    /// The facts of a tiled map: its tiles' cores make its domain.
    pub fn of_manifest(manifest: &Manifest) -> MapFacts {
        let [i0, j0, i1, j1] = manifest.domain;
        let cells = |c: &[i64; 4]| ((c[2] - c[0]).max(0) * (c[3] - c[1]).max(0)) as u64;
        MapFacts {
            grid_m: manifest.grid_m,
            domain_cells: manifest.tiles.iter().map(|t| cells(&t.core)).sum(),
            feasible_cells: manifest.tiles.iter().map(|t| t.feasible_cells).sum(),
            seconds: MapSeconds::default(),
            tensor_dims: [
                (i1 - i0).max(0) as usize,
                (j1 - j0).max(0) as usize,
                manifest.channels,
            ],
            tensor_bytes: manifest.tiles.iter().map(|t| t.memory_bytes as usize).sum(),
        }
    }
}

/// What [`EvalReport::new`] needs besides the outcomes.
#[derive(Clone)]
pub struct EvalSetup {
    /// The dataset folder.
    pub dataset: String,
    /// The map (or index) file.
    pub map: String,
    /// Methods to tabulate.
    pub methods: Vec<RankMethod>,
    /// What was searched (map preparation timings, tensor, domain).
    pub facts: MapFacts,
    /// Seconds loading the map.
    pub load_map_seconds: f64,
    /// Seconds building the hashing index.
    pub hashing_index_seconds: f64,
    /// The distractor map, if any.
    pub distractors: Option<DistractorsReport>,
    /// Track mode, if run.
    pub track: Option<TrackSetup>,
}

impl EvalReport {
    /// Tabulates the outcomes of every scan.
    pub fn new(setup: EvalSetup, records: &[ScanOutcome]) -> Self {
        let facts = setup.facts;
        let n_accurate: AccuracyTable = setup
            .methods
            .iter()
            .map(|&m| {
                let per_k = KS
                    .iter()
                    .map(|&k| {
                        let per_w = RADII_M
                            .iter()
                            .map(|&w| {
                                let c = records
                                    .iter()
                                    .filter(|r| {
                                        accurate_within(
                                            r.ranked_by(m),
                                            &r.truth,
                                            k,
                                            w,
                                            m.accuracy(),
                                        )
                                    })
                                    .count();
                                (radius_name(w), c)
                            })
                            .collect();
                        (k.to_string(), per_w)
                    })
                    .collect();
                (m.name().to_owned(), per_k)
            })
            .collect();
        let accurate_in_candidate_set = records
            .iter()
            .filter(|r| {
                accurate_within(
                    r.ranked_by(RankMethod::Reverse),
                    &r.truth,
                    usize::MAX,
                    f64::INFINITY,
                    Accuracy::THESIS,
                )
            })
            .count();
        let strict = Accuracy::STRICT;
        let strict_top1 = |m: RankMethod| {
            records
                .iter()
                .filter(|r| {
                    r.ranked_by(m)
                        .first()
                        .is_some_and(|p| strict.accepts(p, &r.truth))
                })
                .count()
        };
        let top10_within = |m: RankMethod| {
            records
                .iter()
                .filter(|r| {
                    r.ranked_by(m)
                        .iter()
                        .take(10)
                        .any(|p| strict.accepts(p, &r.truth))
                })
                .count()
        };
        // Track mode ranks by the chains of its window: judged in the localizer's own order.
        let track = setup.track.map(|t| {
            let after: Vec<&ScanOutcome> =
                records.iter().skip(t.window.saturating_sub(1)).collect();
            let within = |r: &ScanOutcome, n: usize| {
                r.own_ranking().first_accurate_rank.is_some_and(|k| k <= n)
            };
            TrackCounts {
                window: t.window,
                history_m: t.history_m,
                odometry_drift: t.odometry_drift,
                odometry_yaw_drift_deg_per_50m: t.odometry_yaw_drift_deg,
                odometry_drift_kind: if t.odometry_random_seed.is_some() {
                    "random"
                } else {
                    "systematic"
                },
                odometry_seed: t.odometry_random_seed,
                scans_after_first_window: after.len(),
                top1_within_2m_3deg: after.iter().filter(|r| within(r, 1)).count(),
                top10_within_2m_3deg: after.iter().filter(|r| within(r, 10)).count(),
                scans: records.len(),
                top1_within_2m_3deg_every_scan: records.iter().filter(|r| within(r, 1)).count(),
                smoothed: t.smooth,
                pose_graph: t.smooth && t.pose_graph,
                cost: records
                    .first()
                    .map_or(LocalizeOptions::default().rank_by, |r| r.result.rank_by)
                    .name(),
            }
        });
        let mut sensors: Vec<(String, usize)> = Vec::new();
        for r in records {
            let name = r.result.sensor.map_or("manual", |s| s.profile);
            match sensors.iter_mut().find(|(p, _)| p == name) {
                Some(e) => e.1 += 1,
                None => sensors.push((name.to_owned(), 1)),
            }
        }
        let accurate_top1_err = |m: RankMethod| -> Vec<f64> {
            records
                .iter()
                .filter_map(|r| {
                    r.ranked_by(m)
                        .first()
                        .filter(|p| Accuracy::THESIS.accepts(p, &r.truth))
                        .map(|p| p.distance_to(&r.truth))
                })
                .collect()
        };
        type StageFn = fn(&ScanOutcome) -> f64;
        let stages: [(&str, StageFn); 9] = [
            ("surfaces", |r| r.result.seconds.surfaces),
            ("segments", |r| r.result.seconds.segments),
            ("templates", |r| r.result.seconds.templates),
            ("search", |r| r.result.seconds.search),
            ("filter", |r| r.result.seconds.filter),
            ("visibility_costs", |r| r.result.seconds.visibility_costs),
            ("refine", |r| r.result.seconds.refine),
            ("total", |r| r.result.seconds.total),
            ("hashing", |r| r.hashing_seconds),
        ];
        let stage_seconds: Vec<(String, StageStats)> = stages
            .iter()
            .map(|(name, f)| {
                let v: Vec<f64> = records.iter().map(f).collect();
                let mean = if v.is_empty() {
                    0.0
                } else {
                    v.iter().sum::<f64>() / v.len() as f64
                };
                let max = v.iter().copied().fold(0.0, f64::max);
                let stats = StageStats {
                    mean,
                    median: median(v),
                    max,
                };
                ((*name).to_owned(), stats)
            })
            .collect();
        let grid_m = facts.grid_m;
        let domain_cells = facts.domain_cells;
        EvalReport {
            dataset: setup.dataset,
            map: setup.map,
            scans: records.len(),
            thresholds: Thresholds {
                chamfer: Accuracy::THESIS.into(),
                hashing: Accuracy::HASHING.into(),
            },
            distractors: setup.distractors,
            search_area_km2: domain_cells as f64 * grid_m * grid_m / 1e6,
            n_accurate,
            accurate_in_candidate_set,
            top1_within_2m_3deg: PerCost {
                dcm: strict_top1(RankMethod::Dcm),
                forward: strict_top1(RankMethod::Forward),
                reverse: strict_top1(RankMethod::Reverse),
                symmetric: strict_top1(RankMethod::Symmetric),
            },
            top10_within_2m_3deg_reverse: top10_within(RankMethod::Reverse),
            top10_within_2m_3deg_symmetric: top10_within(RankMethod::Symmetric),
            track,
            tiled_exact_scans: None,
            sensors,
            median_error_accurate_top1_reverse_m: median(accurate_top1_err(RankMethod::Reverse)),
            median_error_accurate_top1_symmetric_m: median(accurate_top1_err(
                RankMethod::Symmetric,
            )),
            map_seconds: MapPrepSeconds {
                load_map: setup.load_map_seconds,
                map_edges: facts.seconds.edges,
                distance_transform: facts.seconds.distance_transform,
                pyramid: facts.seconds.pyramid,
                feasible_mask: facts.seconds.feasible,
                hashing_index: setup.hashing_index_seconds,
            },
            tensor: TensorInfo {
                width: facts.tensor_dims[0],
                height: facts.tensor_dims[1],
                channels: facts.tensor_dims[2],
                grid_m,
                bytes: facts.tensor_bytes,
            },
            stage_seconds,
            threads: rayon::current_num_threads(),
            per_scan: records
                .iter()
                .map(|r| ScanRow {
                    odometry_run: setup.track.map(|_| r.result.odometry_run),
                    ..ScanRow::new(r)
                })
                .collect(),
            methods: setup.methods,
            domain_cells,
            yaws_per_cell: records
                .first()
                .map_or(0, |r| r.result.search.space / domain_cells.max(1)),
            feasible_cells: facts.feasible_cells,
        }
    }

    /// N_accurate of `method` for `k` and radius `w` (0 when not tabulated).
    pub fn n_accurate_at(&self, method: RankMethod, k: usize, w: f64) -> usize {
        self.n_accurate
            .get(method.name())
            .and_then(|v| v.get(&k.to_string()))
            .and_then(|v| v.get(&radius_name(w)))
            .copied()
            .unwrap_or(0)
    }

    /// The curves of thesis Figs. 5.5/5.6 as SVG: N_accurate against the search radius w,
    /// one panel per k, one line per method.
    pub fn curves_svg(&self) -> String {
        let scans = self.scans;
        let (pw, ph, left, top, gap) = (260.0, 220.0, 48.0, 30.0, 30.0);
        let width = left + KS.len() as f64 * (pw + gap) + 110.0;
        let height = top + ph + 50.0;
        let colour = |m: RankMethod| match m {
            RankMethod::Dcm => "#7f7f7f",
            RankMethod::Forward => "#1f77b4",
            RankMethod::Reverse => "#d62728",
            RankMethod::Symmetric => "#2ca02c",
            RankMethod::Hashing => "#9467bd",
        };
        let mut out = format!(
            r#"<svg xmlns="http://www.w3.org/2000/svg" width="{width:.0}" height="{height:.0}" viewBox="0 0 {width:.0} {height:.0}" font-family="sans-serif" font-size="11"><rect width="100%" height="100%" fill="white"/>"#
        );
        let ymax = scans.max(1) as f64;
        for (p, k) in KS.iter().enumerate() {
            let x0 = left + p as f64 * (pw + gap);
            let px = |i: usize| x0 + pw * i as f64 / (RADII_M.len() - 1) as f64;
            let py = |v: f64| top + ph * (1.0 - v / ymax);
            let _ = write!(
                out,
                r#"<rect x="{x0:.1}" y="{top:.1}" width="{pw:.1}" height="{ph:.1}" fill="none" stroke="dimgray"/><text x="{:.1}" y="{:.1}" text-anchor="middle">k = {k}</text>"#,
                x0 + pw / 2.0,
                top - 8.0
            );
            for (i, w) in RADII_M.iter().enumerate() {
                let _ = write!(
                    out,
                    r#"<line x1="{x:.1}" y1="{y0:.1}" x2="{x:.1}" y2="{y1:.1}" stroke="gainsboro"/><text x="{x:.1}" y="{ty:.1}" text-anchor="middle">{}</text>"#,
                    radius_name(*w),
                    x = px(i),
                    y0 = top,
                    y1 = top + ph,
                    ty = top + ph + 14.0
                );
            }
            for q in 0..=4 {
                let v = ymax * q as f64 / 4.0;
                let _ = write!(
                    out,
                    r#"<text x="{:.1}" y="{:.1}" text-anchor="end">{v:.0}</text>"#,
                    x0 - 4.0,
                    py(v) + 4.0
                );
            }
            let _ = write!(
                out,
                r#"<text x="{:.1}" y="{:.1}" text-anchor="middle">search radius w (m)</text>"#,
                x0 + pw / 2.0,
                top + ph + 32.0
            );
            for &m in &self.methods {
                let pts: Vec<String> = RADII_M
                    .iter()
                    .enumerate()
                    .map(|(i, &w)| {
                        let c = self.n_accurate_at(m, *k, w);
                        format!("{:.1},{:.1}", px(i), py(c as f64))
                    })
                    .collect();
                let _ = write!(
                    out,
                    r#"<polyline points="{}" fill="none" stroke="{}" stroke-width="2"/>"#,
                    pts.join(" "),
                    colour(m)
                );
            }
        }
        let _ = write!(
            out,
            r#"<text x="12" y="{:.1}" transform="rotate(-90 12 {:.1})" text-anchor="middle">N_accurate of {scans}</text>"#,
            top + ph / 2.0,
            top + ph / 2.0
        );
        let lx = left + KS.len() as f64 * (pw + gap);
        for (i, &m) in self.methods.iter().enumerate() {
            let y = top + 14.0 + 18.0 * i as f64;
            let _ = write!(
                out,
                r#"<line x1="{lx:.1}" y1="{y:.1}" x2="{:.1}" y2="{y:.1}" stroke="{}" stroke-width="2"/><text x="{:.1}" y="{:.1}">{}</text>"#,
                lx + 22.0,
                colour(m),
                lx + 28.0,
                y + 4.0,
                m.name()
            );
        }
        out.push_str("</svg>");
        out
    }
}

impl ScanOutcome {
    /// The one-line summary of a scan printed while an evaluation runs.
    pub fn line_text(&self) -> String {
        let r = self;
        let mut line = format!(
            "{:<14} segs {:>3} cands {:>5}",
            r.name,
            r.result.segments.len(),
            r.result.candidates.len()
        );
        for (m, name) in RankMethod::ALL
            .iter()
            .zip(["dcm", "fwd", "rev", "sym", "hash"])
        {
            let e = r.top1_error(*m);
            line += &format!(" | {name} {:>7.2} m {:>6.2}°", e.error_m, e.error_deg);
        }
        line += &format!(
            " | conf {:.2} | {:.2} s",
            r.result.confidence, r.result.seconds.total
        );
        if let Some(msg) = &r.result.message {
            line += &format!(" | {msg}");
        }
        line
    }
}

impl EvalReport {
    /// The evaluation as the command line prints it (`real`: the layout of the real
    /// sequence the scans come from, `None`: simulated scans).
    pub fn table_text(&self, real: Option<&str>) -> String {
        let r = self;
        let mut out = String::new();
        let n = r.scans;
        let _ = writeln!(out);
        let _ = writeln!(
            out,
            "{} scans of {} on {} ({})",
            n,
            r.dataset,
            r.map,
            real.map_or_else(|| "simulated".to_owned(), |k| format!("real {k} scans"))
        );
        if let Some(d) = &r.distractors {
            let s = &d.summary;
            let _ = writeln!(
                out,
            "embedded among distractors from {} (seed {}, ring {} m, gap {} m, tiles {} m): {} target buildings, {} distractor buildings ({} dropped at tile seams), {} distractor street segments in {} tiles; building box {:.2} km² → {:.2} km²",
            d.map,
            d.seed,
            d.ring_m,
            d.gap_m,
            d.tile_m,
            s.target_buildings,
            s.distractor_buildings,
            s.dropped_overlapping,
            s.distractor_street_segments,
            s.tiles.len(),
            s.target_area_km2,
            s.outer_area_km2
        );
        }
        let _ = writeln!(
            out,
            "search area {:.2} km² ({} cells × {} yaws)",
            r.search_area_km2, r.domain_cells, r.yaws_per_cell
        );
        let _ = writeln!(out, "N_accurate (thresholds 4 m / 0.2 rad; hashing 5 m / π/6), k best candidates within radius w (m) of the truth:");
        let mut header = format!("{:<10} {:>3}", "method", "k");
        for w in RADII_M {
            header += &format!(" {:>6}", radius_name(w));
        }
        let _ = writeln!(out, "{header}");
        for &m in &r.methods {
            for k in KS {
                let mut line = format!("{:<10} {k:>3}", m.name());
                for w in RADII_M {
                    line += &format!(" {:>6}", r.n_accurate_at(m, k, w));
                }
                let _ = writeln!(out, "{line}");
            }
        }
        let t1 = &r.top1_within_2m_3deg;
        let _ = writeln!(
                out,
        "accurate candidate in the candidate set: {}/{n}; top-1 within 2 m and 3°: dcm {}, forward {}, reverse {}, symmetric {} of {n}; top 10 (reverse) within 2 m and 3°: {}/{n}; median error of accurate top-1 (reverse, refined) {:.2} m; by symmetric (the default ranking) top 10 {}/{n}, median error {:.2} m",
        r.accurate_in_candidate_set,
        t1.dcm,
        t1.forward,
        t1.reverse,
        t1.symmetric,
        r.top10_within_2m_3deg_reverse,
        r.median_error_accurate_top1_reverse_m,
        r.top10_within_2m_3deg_symmetric,
        r.median_error_accurate_top1_symmetric_m
    );
        let sensor_counts: Vec<String> =
            r.sensors.iter().map(|(p, c)| format!("{p} ×{c}")).collect();
        let _ = writeln!(out, "sensor profiles: {}", sensor_counts.join(", "));
        if let Some(n) = r.tiled_exact_scans {
            let _ = writeln!(
                out,
                "tiled map: {n} of {} scans searched exactly as on the whole map",
                r.scans
            );
        }
        if let Some(t) = &r.track {
            let _ = writeln!(
                out,
            "track mode (window {}, {} odometry drift {:.1} % and {:.1}°/50 m): after the first window, top-1 ({}) within 2 m and 3° for {}/{} scans, top 10 for {}/{}",
            t.window,
            t.odometry_drift_kind,
            100.0 * t.odometry_drift,
            t.odometry_yaw_drift_deg_per_50m,
            t.cost,
            t.top1_within_2m_3deg,
            t.scans_after_first_window,
            t.top10_within_2m_3deg,
            t.scans_after_first_window
        );
        }
        let (s, dt) = (&r.map_seconds, &r.tensor);
        let _ = writeln!(
                out,
        "map: load {:.2} s, edges {:.3} s, DT tensor {}×{}×{} at {} m {:.3} s, pyramid {:.3} s, feasible-pose mask {:.3} s ({} of {} cells), hashing index {:.3} s ({} threads)",
        s.load_map,
        s.map_edges,
        dt.width,
        dt.height,
        dt.channels,
        dt.grid_m,
        s.distance_transform,
        s.pyramid,
        s.feasible_mask,
        r.feasible_cells,
        r.domain_cells,
        s.hashing_index,
        r.threads
    );
        let _ = writeln!(
            out,
            "{:<18} {:>9} {:>9} {:>9}",
            "stage (s/scan)", "mean", "median", "max"
        );
        for (name, t) in &r.stage_seconds {
            let _ = writeln!(
                out,
                "{name:<18} {:>9.4} {:>9.4} {:>9.4}",
                t.mean, t.median, t.max
            );
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn thresholds_come_from_the_accuracy_constants() {
        let t = Thresholds {
            chamfer: Accuracy::THESIS.into(),
            hashing: Accuracy::HASHING.into(),
        };
        assert_eq!(t.chamfer, Threshold { m: 4.0, rad: 0.2 });
        assert_eq!(t.hashing.m, 5.0);
        assert!((t.hashing.rad - std::f64::consts::FRAC_PI_6).abs() < 1e-15);
    }

    #[test]
    fn the_first_accurate_rank_counts_from_one_per_method() {
        let truth = Pose2 {
            x: 10.0,
            y: 20.0,
            yaw_rad: 0.5,
        };
        let off = |dx: f64, dyaw: f64| Pose2 {
            x: truth.x + dx,
            y: truth.y,
            yaw_rad: truth.yaw_rad + dyaw,
        };
        let mut outcome = ScanOutcome::new(
            "s".into(),
            truth,
            Localization::empty(CostKind::Reverse),
            vec![off(50.0, 0.0), off(0.5, 0.01)],
            0.0,
        );
        // 2.5 m off is outside 2 m; 3° + 1° is outside 3°.
        outcome.ranked[2] = vec![off(2.5, 0.0), off(0.0, 4f64.to_radians()), off(1.0, 0.0)];
        let row = ScanRow::new(&outcome);
        assert_eq!(row.first_accurate_rank["reverse"], Some(3));
        assert_eq!(row.first_accurate_rank["hashing"], Some(2));
        assert_eq!(row.first_accurate_rank["dcm"], None);
    }

    #[test]
    fn the_own_ranking_keeps_the_localizer_order_the_cost_fields_resort() {
        let truth = Pose2 {
            x: 10.0,
            y: 20.0,
            yaw_rad: 0.5,
        };
        let candidate = |dx: f64, symmetric: f64| crate::pipeline::Candidate {
            pose: Pose2 {
                x: truth.x + dx,
                ..truth
            },
            costs: Costs {
                dcm: symmetric,
                forward: symmetric,
                reverse: symmetric,
                symmetric,
            },
            refined: true,
            confidence: 0.0,
        };
        // A track ranks the accurate candidate second although it is the cheapest.
        let mut result = Localization::empty(CostKind::Symmetric);
        result.candidates = vec![candidate(6.0, 1.5), candidate(0.5, 1.0)];
        let row = ScanRow::new(&ScanOutcome::new(
            "s".into(),
            truth,
            result,
            Vec::new(),
            0.0,
        ));
        assert_eq!(row.first_accurate_rank["symmetric"], Some(1));
        assert_eq!(row.own_ranking.first_accurate_rank, Some(2));
        assert!((row.own_ranking.top1.error_m - 6.0).abs() < 1e-12);
        assert_eq!(row.own_ranking.top1.error_deg, 0.0);
        let empty = ScanOutcome::new(
            "e".into(),
            truth,
            Localization::empty(CostKind::Symmetric),
            Vec::new(),
            0.0,
        );
        let row = ScanRow::new(&empty);
        assert_eq!(row.own_ranking.first_accurate_rank, None);
        assert!(row.own_ranking.top1.error_m.is_nan());
    }

    #[test]
    fn median_skips_non_finite_values() {
        assert!(median(vec![]).is_nan());
        assert_eq!(median(vec![3.0, f64::NAN, 1.0, 2.0]), 2.0);
        assert_eq!(radius_name(f64::INFINITY), "map");
        assert_eq!(radius_name(50.0), "50");
    }
}
