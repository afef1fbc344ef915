//! The trained street model: bin classifier (standardised features + RBF SVM), its confusion
//! matrix on held-out bins, and the geometry prior; plus the per-segment estimate from a cloud.

use crate::corridor::{Corridor, CorridorOptions, CorridorSource};
use crate::features::{bin_features, BinFeatures, FeatureOptions, FEATURE_DIMS};
use crate::inference::{Edge, McmcOptions, Network};
use crate::potentials::{
    segment_potential, tempered_with_prior, ColumnCounts, Confusion, GeometryPrior,
    SegmentPotential, Tempering, ThetaGrid,
};
use crate::prior::{MarginSample, PriorTables, SegmentTags, SidewalkPrior, TagPrior};
use crate::svm::{Svm, SvmOptions};
use crate::{Result, StreetsError};
use geodata::classes::Class;
use geodata::cloud::PointCloud;
use geodata::osm::OsmMap;
use rand::seq::SliceRandom;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::path::Path;

/// What counts as street.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Target {
    /// The driving area (road and parking).
    DrivingArea,
    /// Driving area and sidewalk.
    WithSidewalk,
}

impl Target {
    /// Whether a class is street for this target.
    pub fn positive(self, class: Class) -> bool {
        match self {
            Target::DrivingArea => class == Class::Street,
            Target::WithSidewalk => class == Class::Street || class == Class::Sidewalk,
        }
    }

    /// The JSON key.
    pub fn key(self) -> &'static str {
        match self {
            Target::DrivingArea => "driving_area",
            Target::WithSidewalk => "with_sidewalk",
        }
    }
}

/// Per-feature standardisation (z-scores).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Scaler {
    /// Means.
    pub mean: Vec<f32>,
    /// Standard deviations (1 where constant).
    pub std: Vec<f32>,
}

impl Scaler {
    /// Fitted on a row-major matrix with `dims` columns.
    pub fn fit(x: &[f32], dims: usize) -> Scaler {
        let n = (x.len() / dims.max(1)).max(1) as f64;
        let mut mean = vec![0f64; dims];
        let mut sq = vec![0f64; dims];
        for row in x.chunks_exact(dims) {
            for (k, &v) in row.iter().enumerate() {
                mean[k] += f64::from(v);
                sq[k] += f64::from(v) * f64::from(v);
            }
        }
        let mean: Vec<f64> = mean.iter().map(|m| m / n).collect();
        let std = sq
            .iter()
            .zip(&mean)
            .map(|(s, m)| {
                let v = (s / n - m * m).max(0.0).sqrt();
                if v > 1e-6 {
                    v as f32
                } else {
                    1.0
                }
            })
            .collect();
        Scaler {
            mean: mean.iter().map(|&m| m as f32).collect(),
            std,
        }
    }

    /// Standardises a row-major matrix in place.
    pub fn apply(&self, x: &mut [f32]) {
        let d = self.mean.len();
        for row in x.chunks_exact_mut(d) {
            for ((v, m), sd) in row.iter_mut().zip(&self.mean).zip(&self.std) {
                *v = (*v - m) / sd;
            }
        }
    }
}

/// Options of the bin classifier.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ClassifierOptions {
    /// SVM options.
    pub svm: SvmOptions,
    /// Largest number of training bins (a seeded random subset).
    pub max_train_bins: usize,
    /// Held-out bins for the confusion matrix.
    pub calibration_bins: usize,
    /// Seed of the subsets.
    pub seed: u64,
}

impl Default for ClassifierOptions {
    fn default() -> Self {
        ClassifierOptions {
            svm: SvmOptions {
                c: 4.0,
                ..SvmOptions::default()
            },
            max_train_bins: 3000,
            calibration_bins: 3000,
            seed: 1,
        }
    }
}

/// A trained bin classifier with its held-out confusion matrix.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct BinClassifier {
    /// Feature standardisation.
    pub scaler: Scaler,
    /// The SVM.
    pub svm: Svm,
    /// Confusion matrix on held-out bins.
    pub confusion: Confusion,
}

impl BinClassifier {
    /// Trains on rows of `x` (row-major, [`FEATURE_DIMS`] wide) with labels `y`: a seeded
    /// subset of at most `max_train_bins` for the SVM and disjoint held-out bins for C.
    pub fn train(x: &[f32], y: &[bool], options: &ClassifierOptions) -> Result<BinClassifier> {
        let n = y.len();
        if x.len() != n * FEATURE_DIMS {
            return Err(StreetsError::FeatureLength {
                got: x.len(),
                expected: n * FEATURE_DIMS,
            });
        }
        let mut order: Vec<usize> = (0..n).collect();
        order.shuffle(&mut ChaCha8Rng::seed_from_u64(options.seed));
        let n_train = options.max_train_bins.min(n);
        let (train, rest) = order.split_at(n_train);
        let calib = &rest[..options.calibration_bins.min(rest.len())];
        let gather = |ids: &[usize]| -> (Vec<f32>, Vec<bool>) {
            let mut xs = Vec::with_capacity(ids.len() * FEATURE_DIMS);
            for &i in ids {
                xs.extend_from_slice(&x[i * FEATURE_DIMS..(i + 1) * FEATURE_DIMS]);
            }
            (xs, ids.iter().map(|&i| y[i]).collect())
        };
        let (mut xt, yt) = gather(train);
        let scaler = Scaler::fit(&xt, FEATURE_DIMS);
        scaler.apply(&mut xt);
        let svm = Svm::train_flat(&xt, FEATURE_DIMS, &yt, &options.svm)?;
        let mut clf = BinClassifier {
            scaler,
            svm,
            confusion: Confusion {
                counts: [[0; 2]; 2],
            },
        };
        // Held-out bins when there are any, else (tiny data) the training bins.
        let (xc, yc) = if calib.is_empty() {
            gather(train)
        } else {
            gather(calib)
        };
        let pred = clf.predict(&xc)?;
        clf.confusion = Confusion::from_pairs(&yc, &pred);
        Ok(clf)
    }

    /// Predicted labels of raw (unscaled) feature rows.
    pub fn predict(&self, x: &[f32]) -> Result<Vec<bool>> {
        let mut xs = x.to_vec();
        self.scaler.apply(&mut xs);
        self.svm.predict_flat(&xs)
    }
}

/// Options of the geometry model.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct GeometryOptions {
    /// Corridors.
    pub corridor: CorridorOptions,
    /// Features.
    pub features: FeatureOptions,
    /// Widest street considered, metres.
    pub max_width_m: f64,
    /// σ of the intersegment potential, metres (thesis: 0.5).
    pub sigma_m: f64,
    /// Couple neighbours only when their directions differ by less than this, degrees
    /// (180: every pair of N, as the thesis).
    pub max_turn_deg: f64,
    /// Couple neighbours also where the tags that set a street's width prior change
    /// ([`SegmentTags`]: `highway` class, `width`, `lanes`, `sidewalk`), as the thesis does;
    /// false: a tag change ends the coupling (a mapper splits a way where its width changes).
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub couple_across_tag_changes: bool,
    /// Tempering of the segment likelihood, prior weight and coupling cap used by
    /// [`StreetModel::estimate`] (`urbansem streets eval` selects them per fold instead).
    #[serde(default)]
    pub tempering: Tempering,
}

impl Default for GeometryOptions {
    fn default() -> Self {
        GeometryOptions {
            corridor: CorridorOptions::default(),
            features: FeatureOptions::default(),
            max_width_m: 30.0,
            sigma_m: 0.5,
            max_turn_deg: 45.0,
            couple_across_tag_changes: false,
            tempering: Tempering {
                tau: 128.0,
                floor_nats: 8.0,
                prior_weight: 1.0,
                coupling_cap_nats: f64::INFINITY,
            },
        }
    }
}

impl GeometryOptions {
    /// The θ grid.
    pub fn theta_grid(&self) -> ThetaGrid {
        ThetaGrid {
            cols: self.corridor.cols(),
            bin_m: self.corridor.bin_m,
            max_width_cols: (self.max_width_m / self.corridor.bin_m).round().max(1.0) as usize,
        }
    }
}

/// Height above the local ground below which a bin's lowest point counts as ground, metres.
pub const GROUND_SEEN_M: f32 = 0.5;

/// A segment's corridor with its bin features.
pub struct SegmentBins {
    /// The corridor.
    pub corridor: Corridor,
    /// Its features.
    pub features: BinFeatures,
}

impl SegmentBins {
    /// A corridor with the features of its bins.
    pub fn of(corridor: Corridor, cloud: &PointCloud, options: &FeatureOptions) -> SegmentBins {
        let o = corridor.frame.origin;
        let features = bin_features(&corridor.grid, cloud, [o[0], o[1], 0.0], options);
        SegmentBins { corridor, features }
    }

    /// Bins used for estimation: unmasked, observed, and with ground seen (the lowest point
    /// less than [`GROUND_SEEN_M`] above the local ground; a bin holding only a car roof or
    /// a canopy says nothing about the surface under it).
    pub fn usable(&self) -> impl Iterator<Item = usize> + '_ {
        (0..self.corridor.grid.len()).filter(move |&k| {
            !self.corridor.masked[k]
                && self.features.observed[k]
                && self.features.z_min_above_ground_m[k] < GROUND_SEEN_M
        })
    }

    /// Raw feature rows of the usable bins.
    pub fn usable_rows(&self) -> Vec<f32> {
        let mut out = Vec::new();
        for k in self.usable() {
            out.extend_from_slice(self.features.row(k));
        }
        out
    }

    /// Column counts of a labelling of the usable bins (in [`SegmentBins::usable`] order).
    pub fn counts(&self, labels: &[bool]) -> ColumnCounts {
        let cols = self.corridor.grid.cols;
        let mut c = ColumnCounts {
            ones: vec![0; cols],
            zeros: vec![0; cols],
        };
        for (k, &l) in self.usable().zip(labels) {
            if l {
                c.ones[k % cols] += 1;
            } else {
                c.zeros[k % cols] += 1;
            }
        }
        c
    }
}

/// Corridors and features of the segments `which` (parallel over segments); `None` where
/// a segment is shorter than a bin.
pub fn segment_bins(
    map: &OsmMap,
    cloud: &PointCloud,
    which: &[usize],
    options: &GeometryOptions,
) -> Vec<Option<SegmentBins>> {
    CorridorSource::new(
        &map.streets.segments,
        &map.streets.intersections,
        &cloud.positions,
        &options.corridor,
    )
    .map(which, |corridor| {
        SegmentBins::of(corridor, cloud, &options.features)
    })
}

/// Whether neighbours `s1` and `s2` of the map are coupled when both are observed: `None`
/// when their directions differ by more than [`GeometryOptions::max_turn_deg`] or (unless
/// [`GeometryOptions::couple_across_tag_changes`]) their width-prior tags differ, else
/// `Some(flipped)` (they run in opposite directions, left of one is right of the other).
pub fn coupling(map: &OsmMap, s1: usize, s2: usize, geometry: &GeometryOptions) -> Option<bool> {
    let segs = &map.streets.segments;
    let (a, b) = (segs.get(s1)?, segs.get(s2)?);
    let max_turn_deg = geometry.max_turn_deg;
    // Same direction when one ends where the other starts.
    let flipped = !(a.to_node == b.from_node || a.from_node == b.to_node);
    let da = [a.b[0] - a.a[0], a.b[1] - a.a[1]];
    let db = [b.b[0] - b.a[0], b.b[1] - b.a[1]];
    let cos = (da[0] * db[0] + da[1] * db[1]) / (a.length_m * b.length_m).max(1e-12);
    let cos = if flipped { -cos } else { cos };
    if max_turn_deg < 180.0 && cos < max_turn_deg.to_radians().cos() {
        return None;
    }
    if !geometry.couple_across_tag_changes
        && SegmentTags::of(map, s1).without_geometry()
            != SegmentTags::of(map, s2).without_geometry()
    {
        return None;
    }
    Some(flipped)
}

/// Coupled pairs among `which` (indices into `which` in the result), with orientation, in
/// the order of the map's neighbour pairs.
pub fn network_edges(map: &OsmMap, which: &[usize], geometry: &GeometryOptions) -> Vec<Edge> {
    let pos: std::collections::HashMap<usize, usize> =
        which.iter().enumerate().map(|(k, &s)| (s, k)).collect();
    let mut edges = Vec::new();
    for &[s1, s2] in &map.streets.neighbour_pairs {
        let (Some(&k1), Some(&k2)) = (pos.get(&s1), pos.get(&s2)) else {
            continue;
        };
        if let Some(flipped) = coupling(map, s1, s2, geometry) {
            edges.push(Edge {
                s1: k1,
                s2: k2,
                flipped,
            });
        }
    }
    edges
}

/// The labelled bins of a dataset for training: features, labels and the true geometry of
/// each segment they come from.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct TrainingBins {
    /// Feature rows, [`FEATURE_DIMS`] per bin.
    pub features: Vec<f32>,
    /// Whether each bin is street for the target.
    pub labels: Vec<bool>,
    /// (offset, width) of every segment with usable bins, metres.
    pub geometries: Vec<(f64, f64)>,
    /// The OSM tags of the same segments, in the same order.
    pub tags: Vec<SegmentTags>,
    /// With sidewalk: the segments with both truths (tags, driving area, with sidewalk),
    /// for the [`SidewalkPrior`]; empty for the driving area.
    pub margins: Vec<MarginSample>,
}

impl TrainingBins {
    /// The width priors per tag group fitted on these segments.
    pub fn tag_prior(&self, target: Target) -> TagPrior {
        let samples: Vec<(SegmentTags, (f64, f64))> = self
            .tags
            .iter()
            .cloned()
            .zip(self.geometries.iter().copied())
            .collect();
        TagPrior::fit(&samples, target == Target::WithSidewalk)
    }

    /// The sidewalk margins fitted on these segments (with sidewalk only; `None` for the
    /// driving area or without a segment that has both truths).
    pub fn sidewalk_prior(&self, target: Target) -> Option<SidewalkPrior> {
        (target == Target::WithSidewalk)
            .then(|| SidewalkPrior::fit(&self.margins))
            .flatten()
    }
}

/// Segment `s`'s sample for [`SidewalkPrior::fit`] (its tags, true driving area and true
/// geometry with sidewalk) when it has both truths.
pub fn margin_sample(
    ds: &crate::dataset::StreetsDataset,
    s: usize,
    tags: &SegmentTags,
) -> Option<MarginSample> {
    (has_truth(ds, s, Target::DrivingArea) && has_truth(ds, s, Target::WithSidewalk)).then(|| {
        (
            tags.clone(),
            true_geometry(ds, s, Target::DrivingArea),
            true_geometry(ds, s, Target::WithSidewalk),
        )
    })
}

/// True geometry (offset, width) of a segment for a target.
pub fn true_geometry(ds: &crate::dataset::StreetsDataset, s: usize, target: Target) -> (f64, f64) {
    let t = &ds.segments[s];
    match target {
        Target::DrivingArea => (t.offset_m, t.width_m),
        Target::WithSidewalk => (
            t.outer_offset_m.unwrap_or(t.offset_m),
            t.width_m + 2.0 * t.sidewalk_m,
        ),
    }
}

/// Whether a segment has a true geometry for a target (real data may see the driving area's
/// edges but not the sidewalk's).
pub fn has_truth(ds: &crate::dataset::StreetsDataset, s: usize, target: Target) -> bool {
    match target {
        Target::DrivingArea => true,
        Target::WithSidewalk => ds.segments[s].outer_observed,
    }
}

/// Features and labels (for `target`) of all usable labelled bins of a dataset's observed
/// drivable segments.
pub fn dataset_bins(
    ds: &crate::dataset::StreetsDataset,
    geometry: &GeometryOptions,
    target: Target,
) -> TrainingBins {
    let which: Vec<usize> = (0..ds.segments.len())
        .filter(|&s| ds.segments[s].drivable && ds.segments[s].observed)
        .collect();
    let bins = segment_bins(&ds.map, &ds.cloud, &which, geometry);
    let mut out = TrainingBins::default();
    for (&s, b) in which.iter().zip(&bins) {
        let Some(b) = b else { continue };
        // The prior learns from segments with a truth for the target (a real sequence may
        // see the driving area's edges and not the sidewalk's).
        if has_truth(ds, s, target) {
            let tags = SegmentTags::of(&ds.map, s);
            if target == Target::WithSidewalk {
                out.margins.extend(margin_sample(ds, s, &tags));
            }
            out.geometries.push(true_geometry(ds, s, target));
            out.tags.push(tags);
        }
        for k in b.usable() {
            if let Some(c) = b.features.truth[k] {
                out.features.extend_from_slice(b.features.row(k));
                out.labels.push(target.positive(c));
            }
        }
    }
    out
}

/// Weight of the calibration confusion matrix in [`StreetModel::estimate_self_calibrated`],
/// as bins per true class (the cloud's own corridors count hundreds of thousands).
pub const SELF_CALIBRATION_PSEUDO_BINS: f64 = 200.0;

/// The shipped default model's JSON ([`StreetModel::shipped_default`]).
pub const DEFAULT_MODEL_JSON: &[u8] = include_bytes!("../models/default.json");

/// How errors and reports name the shipped default model.
pub const DEFAULT_MODEL_NAME: &str = "<urbansem default street model>";

/// The shipped with-sidewalk model's JSON ([`StreetModel::shipped`]).
pub const WITH_SIDEWALK_MODEL_JSON: &[u8] = include_bytes!("../models/with_sidewalk.json");

/// How errors and reports name the shipped with-sidewalk model.
pub const WITH_SIDEWALK_MODEL_NAME: &str = "<urbansem default with-sidewalk street model>";

/// A trained model for `urbansem streets estimate`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct StreetModel {
    /// What the model calls street.
    pub target: Target,
    /// Geometry options.
    pub geometry: GeometryOptions,
    /// The bin classifier.
    pub classifier: BinClassifier,
    /// The geometry prior.
    pub prior: GeometryPrior,
    /// Width priors per OSM tag group; absent (models written before them): `prior` for
    /// every segment.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub tag_prior: Option<TagPrior>,
    /// With sidewalk: the sidewalk margins per class, for a prior centred on each segment's
    /// estimated driving area ([`StreetModel::estimate_given_driving_area`]); absent for the
    /// driving area and in models written before it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sidewalk_prior: Option<SidewalkPrior>,
}

/// One segment's estimate.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SegmentEstimate {
    /// Segment index in the map.
    pub segment: usize,
    /// Offset of the street centre, left of a→b positive, metres.
    pub offset_m: f64,
    /// Width, metres.
    pub width_m: f64,
    /// Usable bins in the corridor.
    pub bins: usize,
    /// Posterior spread of the width (standard deviation under the segment's own potential
    /// with its prior), metres; `None` where not computed (results written before it).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub width_sd_m: Option<f64>,
}

/// Estimates of all segments with usable bins; the counts of segments skipped as shorter than a bin.
#[derive(Debug, Clone, PartialEq)]
pub struct Estimates {
    /// One per estimated segment.
    pub segments: Vec<SegmentEstimate>,
    /// Segments shorter than a bin.
    pub too_short: usize,
    /// Segments without usable bins (not observed or masked entirely).
    pub unobserved: usize,
    /// Whether inference was exact (every connected component of the coupled network a tree).
    pub exact: bool,
}

/// Narrowest corridor bin a model file may ask for, metres (the thesis uses 0.2).
pub const MIN_BIN_M: f64 = 0.05;
/// Most corridor columns a model file may ask for (the thesis' 40 m corridor has 200).
pub const MAX_CORRIDOR_COLS: usize = 1000;

impl StreetModel {
    /// Trains a model for `target` on every usable labelled bin of a dataset (default
    /// geometry options) and fits the geometry prior to its segments.
    pub fn train(
        ds: &crate::dataset::StreetsDataset,
        target: Target,
        classifier: &ClassifierOptions,
    ) -> Result<StreetModel> {
        let geometry = GeometryOptions::default();
        let bins = dataset_bins(ds, &geometry, target);
        let classifier = BinClassifier::train(&bins.features, &bins.labels, classifier)?;
        Ok(StreetModel {
            target,
            geometry,
            classifier,
            prior: GeometryPrior::fit(&bins.geometries),
            tag_prior: Some(bins.tag_prior(target)),
            sidewalk_prior: bins.sidewalk_prior(target),
        })
    }

    /// Trains one model on the labelled bins of several datasets together (simulated
    /// `streets` datasets and registered real sequences), with the given geometry options
    /// (e.g. [`FeatureOptions::normalise`] on, colour off, for clouds of other sensors).
    ///
    /// Each source contributes at most an equal share of the classifier's training and
    /// calibration bins (a seeded subset), so a large simulated cloud does not drown a real
    /// sequence; the geometry prior is fitted on every source's segments.
    pub fn train_sources(
        sources: &[&crate::dataset::StreetsDataset],
        target: Target,
        geometry: GeometryOptions,
        classifier: &ClassifierOptions,
    ) -> Result<StreetModel> {
        if sources.is_empty() {
            return Err(StreetsError::InvalidOption {
                name: "training sources",
                value: 0.0,
                expected: "at least one dataset or sequence",
            });
        }
        let per_source = (classifier.max_train_bins + classifier.calibration_bins)
            .div_ceil(sources.len())
            .max(1);
        let mut all = TrainingBins::default();
        for (i, ds) in sources.iter().enumerate() {
            let bins = dataset_bins(ds, &geometry, target);
            let n = bins.labels.len();
            let mut order: Vec<usize> = (0..n).collect();
            order.shuffle(&mut ChaCha8Rng::seed_from_u64(
                classifier.seed ^ (i as u64).wrapping_mul(0x9E37_79B9),
            ));
            order.truncate(per_source);
            for &k in &order {
                all.features
                    .extend_from_slice(&bins.features[k * FEATURE_DIMS..(k + 1) * FEATURE_DIMS]);
                all.labels.push(bins.labels[k]);
            }
            all.geometries.extend_from_slice(&bins.geometries);
            all.tags.extend(bins.tags);
            all.margins.extend(bins.margins);
        }
        let classifier = BinClassifier::train(&all.features, &all.labels, classifier)?;
        Ok(StreetModel {
            target,
            geometry,
            classifier,
            prior: GeometryPrior::fit(&all.geometries),
            tag_prior: Some(all.tag_prior(target)),
            sidewalk_prior: all.sidewalk_prior(target),
        })
    }

    /// Reads a model written by `urbansem streets train` (JSON) and checks every value
    /// [`StreetModel::estimate`] relies on: feature dimensions, finite numbers, positive
    /// scales, and a corridor of at most [`MAX_CORRIDOR_COLS`] bins of at least
    /// [`MIN_BIN_M`]. `path` names the file in errors.
    pub fn from_json(bytes: &[u8], path: &Path) -> Result<StreetModel> {
        let model: StreetModel =
            serde_json::from_slice(bytes).map_err(|e| StreetsError::Model {
                path: path.to_path_buf(),
                message: format!("line {} column {}: {e}", e.line(), e.column()),
            })?;
        model.check().map_err(|message| StreetsError::Model {
            path: path.to_path_buf(),
            message,
        })?;
        Ok(model)
    }

    /// The model shipped with urbansem, for a user without labels of their own.
    ///
    /// Built by `urbansem streets train --dataset target/streets-emb-s1,target/streets-hel-s1
    /// --normalise --no-colour --out crates/streets/models/default.json` from `urbansem sim
    /// dataset --kind streets --seed 1` of the embedded procedural city and of OSM Helsinki
    /// centre (© OpenStreetMap contributors, ODbL 1.0); a test rebuilds it byte for byte.
    /// Its measured accuracy on real scans is in the crate README ("The shipped default model").
    pub fn shipped_default() -> Result<StreetModel> {
        StreetModel::from_json(DEFAULT_MODEL_JSON, Path::new(DEFAULT_MODEL_NAME))
    }

    /// The shipped model for `target`: [`StreetModel::shipped_default`] for the driving area;
    /// with sidewalk, the model built by the same command with `--target with-sidewalk --out
    /// crates/streets/models/with_sidewalk.json` (same data and licence, its sidewalk margins
    /// learnt on the same segments; a test rebuilds it byte for byte).
    pub fn shipped(target: Target) -> Result<StreetModel> {
        match target {
            Target::DrivingArea => StreetModel::shipped_default(),
            Target::WithSidewalk => StreetModel::from_json(
                WITH_SIDEWALK_MODEL_JSON,
                Path::new(WITH_SIDEWALK_MODEL_NAME),
            ),
        }
    }

    /// The first value out of range, described with its field and the accepted range.
    fn check(&self) -> std::result::Result<(), String> {
        let range = |name: &str, v: f64, ok: bool, accepted: &str| {
            if ok {
                Ok(())
            } else {
                Err(format!(
                    "{name} = {v} is out of range (expected {accepted})"
                ))
            }
        };
        let positive =
            |name: &str, v: f64| range(name, v, v.is_finite() && v > 0.0, "a finite number > 0");
        let finite = |name: &str, v: f64| range(name, v, v.is_finite(), "a finite number");
        let g = &self.geometry;
        positive("geometry.corridor.width_m", g.corridor.width_m)?;
        range(
            "geometry.corridor.bin_m",
            g.corridor.bin_m,
            g.corridor.bin_m.is_finite() && g.corridor.bin_m >= MIN_BIN_M,
            "a finite number >= 0.05",
        )?;
        let cols = g.corridor.width_m / g.corridor.bin_m;
        range(
            "geometry.corridor.width_m / bin_m",
            cols,
            cols.round() <= MAX_CORRIDOR_COLS as f64,
            "at most 1000 columns",
        )?;
        let radius = g.corridor.intersection_radius_m;
        range(
            "geometry.corridor.intersection_radius_m",
            radius,
            radius.is_finite() && radius >= 0.0,
            "a finite number >= 0",
        )?;
        let window = g.features.ground_window_m;
        range(
            "geometry.features.ground_window_m",
            window,
            window.is_finite() && (0.0..=g.corridor.width_m).contains(&window),
            "a finite number from 0 to the corridor width",
        )?;
        range(
            "geometry.max_width_m",
            g.max_width_m,
            g.max_width_m.is_finite() && g.max_width_m > 0.0 && g.max_width_m <= g.corridor.width_m,
            "a finite number > 0, at most the corridor width",
        )?;
        positive("geometry.sigma_m", g.sigma_m)?;
        finite("geometry.max_turn_deg", g.max_turn_deg)?;
        let t = &g.tempering;
        positive("geometry.tempering.tau", t.tau)?;
        range(
            "geometry.tempering.floor_nats",
            t.floor_nats,
            t.floor_nats > 0.0,
            "a number > 0 or null",
        )?;
        range(
            "geometry.tempering.prior_weight",
            t.prior_weight,
            t.prior_weight.is_finite() && t.prior_weight >= 0.0,
            "a finite number >= 0",
        )?;
        range(
            "geometry.tempering.coupling_cap_nats",
            t.coupling_cap_nats,
            t.coupling_cap_nats > 0.0,
            "a number > 0 or null",
        )?;
        let c = &self.classifier;
        for (name, v) in [("mean", &c.scaler.mean), ("std", &c.scaler.std)] {
            if v.len() != FEATURE_DIMS {
                return Err(format!(
                    "classifier.scaler.{name} has {} values, expected {FEATURE_DIMS}",
                    v.len()
                ));
            }
        }
        for (k, (&m, &s)) in c.scaler.mean.iter().zip(&c.scaler.std).enumerate() {
            finite(&format!("classifier.scaler.mean[{k}]"), f64::from(m))?;
            positive(&format!("classifier.scaler.std[{k}]"), f64::from(s))?;
        }
        let svm = &c.svm;
        if svm.dims != FEATURE_DIMS {
            return Err(format!(
                "classifier.svm.dims = {}, expected {FEATURE_DIMS}",
                svm.dims
            ));
        }
        if Some(svm.support.len()) != svm.coef.len().checked_mul(FEATURE_DIMS) {
            return Err(format!(
                "classifier.svm.support has {} values for {} coefficients of {FEATURE_DIMS} features",
                svm.support.len(),
                svm.coef.len()
            ));
        }
        range(
            "classifier.svm.gamma",
            svm.gamma,
            svm.gamma.is_finite() && svm.gamma >= 0.0,
            "a finite number >= 0",
        )?;
        finite("classifier.svm.rho", svm.rho)?;
        if let Some(k) = svm.coef.iter().position(|v| !v.is_finite()) {
            return Err(format!(
                "classifier.svm.coef[{k}] = {} is not finite",
                svm.coef[k]
            ));
        }
        if let Some(k) = svm.support.iter().position(|v| !v.is_finite()) {
            return Err(format!(
                "classifier.svm.support[{k}] = {} is not finite",
                svm.support[k]
            ));
        }
        let counts = c.confusion.counts;
        if counts.iter().flatten().any(|&n| n > u64::MAX / 4) {
            return Err(format!(
                "classifier.confusion.counts {counts:?} holds a count above 2^62"
            ));
        }
        let geometry_prior = |name: &str, p: &GeometryPrior| {
            finite(&format!("{name}.mean_offset_m"), p.mean_offset_m)?;
            positive(&format!("{name}.sigma_offset_m"), p.sigma_offset_m)?;
            finite(&format!("{name}.mean_log_width"), p.mean_log_width)?;
            positive(&format!("{name}.sigma_log_width"), p.sigma_log_width)
        };
        geometry_prior("prior", &self.prior)?;
        if let Some(t) = &self.tag_prior {
            geometry_prior("tag_prior.global", &t.global)?;
            t.check()?;
        }
        if let Some(sp) = &self.sidewalk_prior {
            if self.target != Target::WithSidewalk {
                return Err(format!(
                    "sidewalk_prior is set on a {} model (only with-sidewalk models have one)",
                    self.target.key()
                ));
            }
            sp.check()?;
        }
        Ok(())
    }
}

/// What the potential step found for one drivable segment.
#[derive(Debug, Clone, PartialEq)]
pub enum SegmentOutcome {
    /// Shorter than one bin outside the intersection masks (no corridor).
    TooShort,
    /// No usable bin (not observed, or masked entirely).
    Unobserved,
    /// Observed: its potential and the number of usable bins behind it.
    Observed {
        /// The tempered segment potential with the prior (eq. 4.2).
        potential: SegmentPotential,
        /// Usable bins in the corridor.
        bins: usize,
    },
}

/// The per-segment step of [`StreetModel::estimate`] (corridor → features → labels →
/// potential) with the cloud indexed once; a segment's outcome depends on that segment, the
/// map and the cloud only, not on which other segments are asked for with it.
pub struct PotentialStep<'a> {
    model: &'a StreetModel,
    cloud: &'a PointCloud,
    source: CorridorSource<'a>,
    grid: ThetaGrid,
    confusion_log: [[f64; 2]; 2],
    /// Prior tables of every segment of the map.
    prior: PriorTables,
}

impl<'a> PotentialStep<'a> {
    /// Indexes `cloud` against the corridors of `map`'s segments (O(P + S)).
    pub fn new(model: &'a StreetModel, map: &'a OsmMap, cloud: &'a PointCloud) -> Self {
        let grid = model.geometry.theta_grid();
        let prior = model.prior_tables(map, &grid);
        Self::with_prior(model, map, cloud, prior)
    }

    /// [`PotentialStep::new`] with the given prior tables (one per segment of `map`).
    fn with_prior(
        model: &'a StreetModel,
        map: &'a OsmMap,
        cloud: &'a PointCloud,
        prior: PriorTables,
    ) -> Self {
        let grid = model.geometry.theta_grid();
        PotentialStep {
            model,
            cloud,
            source: CorridorSource::new(
                &map.streets.segments,
                &map.streets.intersections,
                &cloud.positions,
                &model.geometry.corridor,
            ),
            confusion_log: model.classifier.confusion.log_likelihood(),
            prior,
            grid,
        }
    }

    /// The column counts of the classifier's labels in each segment's corridor and its usable
    /// bins, in the order of `which` (parallel over segments); `None`: too short (no
    /// corridor), `Some(None)`: no usable bin.
    #[allow(clippy::type_complexity)]
    pub fn column_counts(
        &self,
        which: &[usize],
    ) -> Result<Vec<Option<Option<(ColumnCounts, usize)>>>> {
        let geometry = &self.model.geometry;
        let results = self
            .source
            .map(which, |corridor| -> Result<Option<(ColumnCounts, usize)>> {
                if corridor.grid.point_ids.is_empty() {
                    return Ok(None);
                }
                let b = SegmentBins::of(corridor, self.cloud, &geometry.features);
                let rows = b.usable_rows();
                if rows.is_empty() {
                    return Ok(None);
                }
                let labels = self.model.classifier.predict(&rows)?;
                Ok(Some((b.counts(&labels), labels.len())))
            });
        results.into_iter().map(|r| r.transpose()).collect()
    }

    /// The outcome of each segment of `which`, in order (parallel over segments).
    pub fn outcomes(&self, which: &[usize]) -> Result<Vec<SegmentOutcome>> {
        let flat = GeometryPrior::flat();
        let geometry = &self.model.geometry;
        // Per segment: corridor → features → labels → potential, keeping only the potential.
        let results = self
            .source
            .map(which, |corridor| -> Result<SegmentOutcome> {
                if corridor.grid.point_ids.is_empty() {
                    return Ok(SegmentOutcome::Unobserved);
                }
                let segment = corridor.segment;
                let b = SegmentBins::of(corridor, self.cloud, &geometry.features);
                let rows = b.usable_rows();
                if rows.is_empty() {
                    return Ok(SegmentOutcome::Unobserved);
                }
                let labels = self.model.classifier.predict(&rows)?;
                let potential = tempered_with_prior(
                    &segment_potential(&b.counts(&labels), &self.confusion_log, &flat, &self.grid),
                    &geometry.tempering,
                    self.prior.table(segment),
                );
                Ok(SegmentOutcome::Observed {
                    potential,
                    bins: labels.len(),
                })
            });
        results
            .into_iter()
            .map(|r| r.unwrap_or(Ok(SegmentOutcome::TooShort)))
            .collect()
    }
}

/// The drivable segments of a map (streets for cars only: footways have no driving area),
/// ascending; [`StreetsError::NoStreets`] when there are none.
pub fn drivable_segments(map: &OsmMap, map_name: &str) -> Result<Vec<usize>> {
    let segs = &map.streets.segments;
    let which: Vec<usize> = (0..segs.len())
        .filter(|&s| geodata::osm::tags::is_drivable(&segs[s].highway))
        .collect();
    if which.is_empty() {
        return Err(StreetsError::NoStreets {
            path: map_name.to_string(),
        });
    }
    Ok(which)
}

impl StreetModel {
    /// The prior of segment `s` of `map`: its tag group's when the model has tag priors.
    pub fn segment_prior(&self, map: &OsmMap, s: usize) -> GeometryPrior {
        match &self.tag_prior {
            Some(t) => t.for_tags(&SegmentTags::of(map, s)),
            None => self.prior,
        }
    }

    /// Prior tables of every segment of `map` (indexed by segment).
    fn prior_tables(&self, map: &OsmMap, grid: &ThetaGrid) -> PriorTables {
        let priors: Vec<GeometryPrior> = (0..map.streets.segments.len())
            .map(|s| self.segment_prior(map, s))
            .collect();
        PriorTables::new(&priors, grid)
    }

    /// The prior of every segment of `map` given driving-area estimates of the same cloud:
    /// with a [`SidewalkPrior`], a segment with an estimate (and its width spread) gets a
    /// prior centred on that driving area plus its class' sidewalk margins, as `streets
    /// eval` does; every other segment its [`StreetModel::segment_prior`].
    pub fn priors_given_driving_area(
        &self,
        map: &OsmMap,
        driving: &[SegmentEstimate],
    ) -> Vec<GeometryPrior> {
        let mut priors: Vec<GeometryPrior> = (0..map.streets.segments.len())
            .map(|s| self.segment_prior(map, s))
            .collect();
        if let Some(sp) = &self.sidewalk_prior {
            for e in driving {
                if let (Some(p), Some(sd)) = (priors.get_mut(e.segment), e.width_sd_m) {
                    *p = sp.given_driving_area(
                        &SegmentTags::of(map, e.segment),
                        (e.offset_m, e.width_m),
                        sd,
                    );
                }
            }
        }
        priors
    }

    /// Estimates offset and width of every segment of `map` that `cloud` covers.
    ///
    /// Inference is [`Network::max_product`], which solves each connected component of the
    /// coupled network on its own; so a segment's estimate depends only on the potentials of
    /// its component, and [`crate::tiles`] reproduces this result bit for bit tile by tile.
    pub fn estimate(
        &self,
        map: &OsmMap,
        cloud: &PointCloud,
        map_name: &str,
        cloud_name: &str,
    ) -> Result<Estimates> {
        let step = PotentialStep::new(self, map, cloud);
        self.estimate_with(step, map, map_name, cloud_name)
    }

    /// Whether this model centres its priors on a driving-area estimate: a with-sidewalk
    /// model with sidewalk margins.
    pub fn wants_driving_area(&self) -> bool {
        self.target == Target::WithSidewalk && self.sidewalk_prior.is_some()
    }

    /// What is wrong with a model of target `driving` as the model that estimates this
    /// model's driving area, if anything: given to a model that does not [want
    /// one](StreetModel::wants_driving_area) (whatever its target), or not a driving-area
    /// model. The callers (CLI, Python) name the files around it.
    pub fn driving_model_mismatch(&self, driving: Target) -> Option<String> {
        if !self.wants_driving_area() {
            return Some(format!(
                "a driving model is for a with-sidewalk model with sidewalk margins; this is {}",
                if self.target == Target::WithSidewalk {
                    "a with-sidewalk model without them (trained before they existed: train it again)"
                } else {
                    "a driving-area model"
                }
            ));
        }
        (driving != Target::DrivingArea).then(|| {
            format!(
                "the driving model is a {} model; it must be a driving-area model (`streets train --target driving-area`)",
                driving.key()
            )
        })
    }

    /// [`StreetModel::estimate`], or, for a model that [wants the driving
    /// area](StreetModel::wants_driving_area) and a driving-area model `driving`, the driving
    /// area estimated first and then [`StreetModel::estimate_given_driving_area`];
    /// `self_calibrate` > 0: both self-calibrated with at most that many rounds
    /// ([`StreetModel::estimate_self_calibrated`]). `names`: (map, cloud) for messages.
    pub fn estimate_with_driving(
        &self,
        driving: Option<&StreetModel>,
        map: &OsmMap,
        cloud: &PointCloud,
        names: (&str, &str),
        self_calibrate: usize,
    ) -> Result<Estimates> {
        let (map_name, cloud_name) = names;
        let driving = driving.filter(|d| self.driving_model_mismatch(d.target).is_none());
        let plain = |m: &StreetModel| {
            if self_calibrate > 0 {
                m.estimate_self_calibrated(map, cloud, cloud_name, map_name, self_calibrate)
            } else {
                m.estimate(map, cloud, map_name, cloud_name)
            }
        };
        let Some(d) = driving else {
            return plain(self);
        };
        let de = plain(d)?;
        if self_calibrate > 0 {
            self.estimate_self_calibrated_given_driving_area(
                map,
                cloud,
                cloud_name,
                map_name,
                self_calibrate,
                &de.segments,
            )
        } else {
            self.estimate_given_driving_area(map, cloud, map_name, cloud_name, &de.segments)
        }
    }

    /// [`StreetModel::estimate`] for a with-sidewalk model, each segment's prior centred on
    /// its estimated driving area (`driving`, e.g. the [`StreetModel::estimate`] of a
    /// driving-area model on the same cloud) where the model has a [`SidewalkPrior`]
    /// ([`StreetModel::priors_given_driving_area`]).
    pub fn estimate_given_driving_area(
        &self,
        map: &OsmMap,
        cloud: &PointCloud,
        map_name: &str,
        cloud_name: &str,
        driving: &[SegmentEstimate],
    ) -> Result<Estimates> {
        let step = self.step_given_driving_area(map, cloud, driving);
        self.estimate_with(step, map, map_name, cloud_name)
    }

    /// The potential step with [`StreetModel::priors_given_driving_area`].
    pub(crate) fn step_given_driving_area<'a>(
        &'a self,
        map: &'a OsmMap,
        cloud: &'a PointCloud,
        driving: &[SegmentEstimate],
    ) -> PotentialStep<'a> {
        let priors = self.priors_given_driving_area(map, driving);
        let tables = PriorTables::new(&priors, &self.geometry.theta_grid());
        PotentialStep::with_prior(self, map, cloud, tables)
    }

    /// The estimate with the given potential step.
    fn estimate_with(
        &self,
        step: PotentialStep<'_>,
        map: &OsmMap,
        map_name: &str,
        cloud_name: &str,
    ) -> Result<Estimates> {
        let cloud = step.cloud;
        let which = drivable_segments(map, map_name)?;
        let outcomes = step.outcomes(&which)?;
        let too_short = outcomes
            .iter()
            .filter(|o| matches!(o, SegmentOutcome::TooShort))
            .count();
        if too_short == which.len() {
            return Err(StreetsError::SegmentsTooShort {
                segments: which.len(),
                bin_m: self.geometry.corridor.bin_m,
            });
        }
        let unobserved = outcomes
            .iter()
            .filter(|o| matches!(o, SegmentOutcome::Unobserved))
            .count();
        let observed: Vec<(usize, SegmentPotential, usize)> = which
            .iter()
            .zip(outcomes)
            .filter_map(|(&s, o)| match o {
                SegmentOutcome::Observed { potential, bins } => Some((s, potential, bins)),
                _ => None,
            })
            .collect();
        if observed.is_empty() {
            return Err(no_overlap(map, cloud, cloud_name));
        }
        let (segments, exact) = self.infer(map, observed);
        Ok(Estimates {
            segments,
            too_short,
            unobserved,
            exact,
        })
    }

    /// [`StreetModel::estimate`] with the classifier's confusion matrix re-estimated on the
    /// cloud itself instead of taken from the training data's calibration bins (hard EM, at
    /// most `iterations` rounds, until no estimate changes): each round estimates every
    /// segment with the current matrix, then counts the labels inside and outside the
    /// estimated strips as the new matrix, with the calibration matrix as a prior of
    /// [`SELF_CALIBRATION_PSEUDO_BINS`] per true class. For a cloud of another sensor or city,
    /// whose bins the classifier labels with other error rates than its calibration bins.
    /// The whole cloud shares one matrix, so this is not tile-local ([`crate::tiles`]
    /// reproduces [`StreetModel::estimate`] only).
    pub fn estimate_self_calibrated(
        &self,
        map: &OsmMap,
        cloud: &PointCloud,
        cloud_name: &str,
        map_name: &str,
        iterations: usize,
    ) -> Result<Estimates> {
        let step = PotentialStep::new(self, map, cloud);
        self.self_calibrated_with(step, map, cloud_name, map_name, iterations)
    }

    /// [`StreetModel::estimate_self_calibrated`] with the priors of
    /// [`StreetModel::estimate_given_driving_area`].
    pub fn estimate_self_calibrated_given_driving_area(
        &self,
        map: &OsmMap,
        cloud: &PointCloud,
        cloud_name: &str,
        map_name: &str,
        iterations: usize,
        driving: &[SegmentEstimate],
    ) -> Result<Estimates> {
        let step = self.step_given_driving_area(map, cloud, driving);
        self.self_calibrated_with(step, map, cloud_name, map_name, iterations)
    }

    /// The self-calibrated estimate with the given potential step.
    fn self_calibrated_with(
        &self,
        step: PotentialStep<'_>,
        map: &OsmMap,
        cloud_name: &str,
        map_name: &str,
        iterations: usize,
    ) -> Result<Estimates> {
        let cloud = step.cloud;
        let which = drivable_segments(map, map_name)?;
        let counted = step.column_counts(&which)?;
        let too_short = counted.iter().filter(|c| c.is_none()).count();
        let unobserved = counted.iter().filter(|c| matches!(c, Some(None))).count();
        if too_short == which.len() {
            return Err(StreetsError::SegmentsTooShort {
                segments: which.len(),
                bin_m: self.geometry.corridor.bin_m,
            });
        }
        let observed: Vec<(usize, ColumnCounts, usize)> = which
            .iter()
            .zip(counted)
            .filter_map(|(&s, c)| c.flatten().map(|(c, n)| (s, c, n)))
            .collect();
        if observed.is_empty() {
            return Err(no_overlap(map, cloud, cloud_name));
        }
        let grid = self.geometry.theta_grid();
        let flat = GeometryPrior::flat();
        let pseudo: [[f64; 2]; 2] = self.classifier.confusion.counts.map(|row| {
            let total = (row[0] + row[1]).max(1) as f64;
            row.map(|c| SELF_CALIBRATION_PSEUDO_BINS * c as f64 / total)
        });
        let mut counts = [[0.0f64; 2]; 2];
        let mut last: Option<Vec<SegmentEstimate>> = None;
        let mut exact = true;
        for round in 0..=iterations {
            let clog: [[f64; 2]; 2] = if round == 0 {
                self.classifier.confusion.log_likelihood()
            } else {
                let mut out = [[0.0; 2]; 2];
                for t in 0..2 {
                    let n: [f64; 2] = [counts[t][0] + pseudo[t][0], counts[t][1] + pseudo[t][1]];
                    let total = n[0] + n[1] + 2.0;
                    for p in 0..2 {
                        out[t][p] = ((n[p] + 1.0) / total).ln();
                    }
                }
                out
            };
            let potentials: Vec<(usize, SegmentPotential, usize)> = observed
                .par_iter()
                .map(|(s, c, n)| {
                    let p = tempered_with_prior(
                        &segment_potential(c, &clog, &flat, &grid),
                        &self.geometry.tempering,
                        step.prior.table(*s),
                    );
                    (*s, p, *n)
                })
                .collect();
            let (segments, ex) = self.infer(map, potentials);
            exact = ex;
            let same_geometry = |a: &[SegmentEstimate], b: &[SegmentEstimate]| {
                a.len() == b.len()
                    && a.iter().zip(b).all(|(x, y)| {
                        (x.segment, x.offset_m, x.width_m) == (y.segment, y.offset_m, y.width_m)
                    })
            };
            if last.as_deref().is_some_and(|l| same_geometry(l, &segments)) {
                break;
            }
            counts = [[0.0; 2]; 2];
            for ((_, c, _), e) in observed.iter().zip(&segments) {
                let (a, b) = grid.columns_of(e.offset_m, e.width_m);
                for j in 0..grid.cols {
                    let inside = usize::from(a <= j && j <= b);
                    counts[inside][1] += f64::from(c.ones.get(j).copied().unwrap_or(0));
                    counts[inside][0] += f64::from(c.zeros.get(j).copied().unwrap_or(0));
                }
            }
            last = Some(segments);
        }
        let segments = last.unwrap_or_default();
        Ok(Estimates {
            segments,
            too_short,
            unobserved,
            exact,
        })
    }

    /// Max-product over the coupled network of `observed` segments (ascending segment index,
    /// each with its potential and usable bins): their estimates in that order and whether
    /// every connected component was a tree (inference exact).
    pub(crate) fn infer(
        &self,
        map: &OsmMap,
        observed: Vec<(usize, SegmentPotential, usize)>,
    ) -> (Vec<SegmentEstimate>, bool) {
        let grid = self.geometry.theta_grid();
        let ids: Vec<usize> = observed.iter().map(|o| o.0).collect();
        let mut used = Vec::with_capacity(observed.len());
        let mut potentials = Vec::with_capacity(observed.len());
        for (s, p, n) in observed {
            used.push((s, n, crate::potentials::width_spread_m(&p, &grid)));
            potentials.push(p);
        }
        let net = Network {
            potentials,
            edges: network_edges(map, &ids, &self.geometry),
            lambda: (self.geometry.corridor.bin_m / self.geometry.sigma_m).powi(2) / 2.0,
            truncation: self.geometry.tempering.coupling_cap_nats,
        };
        let sol = net.max_product(20);
        let segments = used
            .iter()
            .zip(&sol.states)
            .map(|(&(s, n, sd), &(a, b))| {
                let (offset_m, width_m) = grid.geometry(a, b);
                SegmentEstimate {
                    segment: s,
                    offset_m,
                    width_m,
                    bins: n,
                    width_sd_m: sd.is_finite().then_some(sd),
                }
            })
            .collect();
        (segments, sol.exact)
    }
}

/// [`StreetsError::NoOverlap`] with the extents of the cloud and of the map's streets.
fn no_overlap(map: &OsmMap, cloud: &PointCloud, cloud_name: &str) -> StreetsError {
    let cb = cloud.bounds();
    let (mut min, mut max) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
    for s in &map.streets.segments {
        for p in [s.a, s.b] {
            for k in 0..2 {
                min[k] = min[k].min(p[k]);
                max[k] = max[k].max(p[k]);
            }
        }
    }
    let (c0, c1) = cb.map_or(([f64::NAN; 3], [f64::NAN; 3]), |b| (b.min, b.max));
    StreetsError::NoOverlap {
        cloud: cloud_name.to_string(),
        cx0: c0[0],
        cx1: c1[0],
        cy0: c0[1],
        cy1: c1[1],
        sx0: min[0],
        sx1: max[0],
        sy0: min[1],
        sy1: max[1],
    }
}

/// Default MCMC settings of the evaluation (thesis: 50 chains × 10⁶ iterations).
pub fn default_mcmc(seed: u64) -> McmcOptions {
    McmcOptions {
        seed,
        ..McmcOptions::default()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::potentials::Confusion;
    use crate::svm::TrainStats;

    fn small_model() -> StreetModel {
        StreetModel {
            target: Target::DrivingArea,
            geometry: GeometryOptions::default(),
            classifier: BinClassifier {
                scaler: Scaler {
                    mean: vec![0.0; FEATURE_DIMS],
                    std: vec![1.0; FEATURE_DIMS],
                },
                svm: Svm {
                    gamma: 0.1,
                    dims: FEATURE_DIMS,
                    support: vec![0.5; 2 * FEATURE_DIMS],
                    coef: vec![1.0, -1.0],
                    rho: 0.0,
                    stats: TrainStats::default(),
                },
                confusion: Confusion {
                    counts: [[90, 10], [5, 95]],
                },
            },
            prior: GeometryPrior::fit(&[(0.0, 7.0), (0.5, 9.0)]),
            sidewalk_prior: None,
            tag_prior: Some(TagPrior::fit(
                &[(0.0, 7.0), (0.5, 9.0), (0.2, 4.0)].map(|g| {
                    let tags = SegmentTags {
                        class: "residential".into(),
                        width_m: None,
                        lanes: None,
                        no_sidewalk: false,
                        mapped_sidewalk_m: None,
                    };
                    (tags, g)
                }),
                false,
            )),
        }
    }

    /// Issue 16: a model file is a reader like any other — it comes back equal, and a file
    /// `estimate` could not use (a scaler without features would make `Scaler::apply` call
    /// `chunks_exact_mut(0)`; a tiny bin, corridors of billions of bins) is an error naming
    /// the file and the field.
    #[test]
    fn issue_16_model_files_are_checked_when_read() {
        let model = small_model();
        let path = Path::new("m.json");
        let bytes = serde_json::to_vec(&model).unwrap();
        assert_eq!(StreetModel::from_json(&bytes, path).unwrap(), model);

        let mut no_features = model.clone();
        no_features.classifier.scaler.mean.clear();
        let mut tiny_bin = model.clone();
        tiny_bin.geometry.corridor.bin_m = 1e-6;
        let mut short_support = model.clone();
        short_support.classifier.svm.support.pop();
        let mut zero_sigma = model.clone();
        zero_sigma.prior.sigma_log_width = 0.0;
        let mut zero_group = model.clone();
        if let Some(t) = zero_group.tag_prior.as_mut() {
            t.groups
                .get_mut("highway=residential")
                .expect("the fitted group")
                .sigma = 0.0;
        }
        for (bad, field) in [
            (no_features, "classifier.scaler.mean"),
            (tiny_bin, "geometry.corridor.bin_m"),
            (short_support, "classifier.svm.support"),
            (zero_sigma, "prior.sigma_log_width"),
            (zero_group, "tag_prior.groups[highway=residential].sigma"),
        ] {
            let bytes = serde_json::to_vec(&bad).unwrap();
            let err = StreetModel::from_json(&bytes, path).unwrap_err();
            let message = err.to_string();
            assert!(matches!(err, StreetsError::Model { .. }), "{message}");
            assert!(
                message.contains("m.json") && message.contains(field),
                "{message}"
            );
        }
        let err =
            StreetModel::from_json(b"{\"target\": \"driving_area\",\n  \"geometry\": 7}", path)
                .unwrap_err()
                .to_string();
        assert!(err.contains("m.json") && err.contains("line 2"), "{err}");
        // A model written before tag priors reads with one prior for every segment.
        let mut value = serde_json::to_value(&model).unwrap();
        value.as_object_mut().unwrap().remove("tag_prior");
        let old = StreetModel::from_json(&serde_json::to_vec(&value).unwrap(), path).unwrap();
        assert_eq!(old.tag_prior, None);
    }

    #[test]
    fn coupling_ends_where_the_width_tags_change() {
        // One straight street north: way 10 (nodes 1–3) and way 11 (3–4) with two lanes,
        // way 12 (4–5) with one lane.
        let xml = r#"<?xml version="1.0"?><osm version="0.6">
<node id="1" lat="48.0000" lon="11.0"/><node id="2" lat="48.0005" lon="11.0"/>
<node id="3" lat="48.0010" lon="11.0"/><node id="4" lat="48.0015" lon="11.0"/>
<node id="5" lat="48.0020" lon="11.0"/>
<way id="10"><nd ref="1"/><nd ref="2"/><nd ref="3"/><tag k="highway" v="residential"/><tag k="lanes" v="2"/></way>
<way id="11"><nd ref="3"/><nd ref="4"/><tag k="highway" v="residential"/><tag k="lanes" v="2"/></way>
<way id="12"><nd ref="4"/><nd ref="5"/><tag k="highway" v="residential"/><tag k="lanes" v="1"/></way>
</osm>"#;
        let map = OsmMap::from_xml_str(xml).expect("map");
        let seg = |from: i64| {
            map.streets
                .segments
                .iter()
                .position(|s| s.from_node == from)
                .expect("segment")
        };
        let (s12, s23, s34, s45) = (seg(1), seg(2), seg(3), seg(4));
        let mut geometry = GeometryOptions::default();
        // One way; two ways with the same tags; a change of `lanes`.
        assert_eq!(coupling(&map, s12, s23, &geometry), Some(false));
        assert_eq!(coupling(&map, s23, s34, &geometry), Some(false));
        assert_eq!(coupling(&map, s34, s45, &geometry), None);
        let all = [s12, s23, s34, s45];
        assert_eq!(network_edges(&map, &all, &geometry).len(), 2);
        geometry.couple_across_tag_changes = true;
        assert_eq!(coupling(&map, s34, s45, &geometry), Some(false));
        assert_eq!(network_edges(&map, &all, &geometry).len(), 3);
        // The thesis' coupling is written into a model file; the default is not.
        let json = |g: &GeometryOptions| serde_json::to_string(g).expect("json");
        assert!(json(&geometry).contains("couple_across_tag_changes"));
        assert!(!json(&GeometryOptions::default()).contains("couple_across_tag_changes"));
    }
}
