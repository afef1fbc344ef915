//! The evaluation of thesis §4.5.3 (Table 4.1) on a `streets` dataset: 5-fold round robin
//! over segments, per-bin precision/recall/F1 and the length-weighted width RMSE for the raw
//! classifier, single segment, full model, the optimum on true labels and the true geometry,
//! for both targets; and the time per stage (Tables 4.2/4.3).

use crate::dataset::StreetsDataset;
use crate::inference::{McmcOptions, Network};
use crate::kitti::{ClassScores, Prf};
use crate::model::{
    has_truth, margin_sample, network_edges, segment_bins, true_geometry, BinClassifier,
    ClassifierOptions, GeometryOptions, SegmentBins, Target,
};
use crate::potentials::{
    segment_potential, tempered_with_prior, width_spread_m, Confusion, GeometryPrior,
    SegmentPotential, Tempering,
};
use crate::prior::{PriorTables, SegmentTags, SidewalkPrior, TagPrior};
use crate::{Result, StreetsError};
use rayon::prelude::*;
use serde::Serialize;
use std::collections::BTreeMap;
use std::time::Instant;

/// Options of the evaluation.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct EvalOptions {
    /// Geometry model.
    pub geometry: GeometryOptions,
    /// Bin classifier.
    pub classifier: ClassifierOptions,
    /// Folds of the round robin (thesis: 5).
    pub folds: usize,
    /// MCMC beside max-product.
    pub mcmc: McmcOptions,
    /// Candidate likelihood temperings; each fold takes the one with the smallest boundary
    /// error on its training segments (one candidate: no selection).
    pub temperings: Vec<Tempering>,
    /// Width priors per OSM tag group ([`crate::prior`]); off: one prior for every segment
    /// (thesis §4.4.2).
    pub tag_prior: bool,
    /// The with-sidewalk prior centred on the segment's estimated driving area plus a
    /// sidewalk margin learnt per class ([`crate::prior::SidewalkPrior`]); off: the tag prior
    /// of the with-sidewalk widths. Needs [`EvalOptions::tag_prior`] (the margins are learnt
    /// per tag group).
    pub sidewalk_prior: bool,
}

/// Training bins of each fold's SVM in the evaluation (at most; a seeded subset). Twice
/// [`ClassifierOptions`]' default for `streets train`, whose support vectors every user's
/// cloud pays for at prediction: with 3000, one fold's classifier missed a whole way's
/// sidewalk material on the embedded city in two of three seeds.
pub const EVAL_MAX_TRAIN_BINS: usize = 6000;

/// The default candidates: τ ∈ {8, 32, 128, 512} × floor ∈ {∞, 8} nats × prior weight ∈
/// {1, 4} × coupling cap ∈ {∞, 10} nats.
pub fn default_temperings() -> Vec<Tempering> {
    let mut out = Vec::new();
    for tau in [8.0, 32.0, 128.0, 512.0] {
        for floor_nats in [f64::INFINITY, 8.0] {
            for prior_weight in [1.0, 4.0] {
                for coupling_cap_nats in [f64::INFINITY, 10.0] {
                    out.push(Tempering {
                        tau,
                        floor_nats,
                        prior_weight,
                        coupling_cap_nats,
                    });
                }
            }
        }
    }
    out
}

impl Default for EvalOptions {
    fn default() -> Self {
        EvalOptions {
            geometry: GeometryOptions::default(),
            classifier: ClassifierOptions {
                max_train_bins: EVAL_MAX_TRAIN_BINS,
                ..ClassifierOptions::default()
            },
            folds: 5,
            mcmc: McmcOptions::default(),
            temperings: default_temperings(),
            tag_prior: true,
            sidewalk_prior: true,
        }
    }
}

/// Precision, recall, F1 and width RMSE of one method.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Scores {
    /// Per-bin precision.
    pub precision: f64,
    /// Per-bin recall.
    pub recall: f64,
    /// Per-bin F1.
    pub f1: f64,
    /// Length-weighted RMSE of the widths, metres (`None` for the raw classifier).
    pub rmse_w: Option<f64>,
    /// Length-weighted RMSE of the offsets (strip centre from the OSM centre line), metres
    /// (`None` for the raw classifier).
    pub rmse_d: Option<f64>,
    /// Precision, recall and F1 of both classes (street, not street) averaged, weighted by
    /// each class's bins: how the thesis' Table 4.1 reports them (see the README).
    pub weighted: Prf,
    /// The same, each class weighing the same.
    #[serde(rename = "macro")]
    pub macro_avg: Prf,
    /// Share of the scored bins labelled correctly.
    pub accuracy: f64,
    /// Share of the scored bins whose true class is the target.
    pub positive_share: f64,
}

/// Table 4.1 rows of one target.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct TargetScores {
    /// The classifier alone.
    pub raw: Scores,
    /// Each segment's own optimum (no intersegment potentials).
    pub single_segment: Scores,
    /// The full model (max-product: exact on trees, loopy otherwise).
    pub full_model: Scores,
    /// The geometry fitted to the true bin labels.
    pub opt_on_truth: Scores,
    /// The true geometry.
    pub true_geometry: Scores,
    /// The full model on the segments it is confident about.
    pub confident: Confident,
    /// The raw classifier near the true strips' edges, by band and true class.
    pub edges: Vec<EdgeBand>,
}

/// Bands beside a true strip's edge, metres from the edge (inside: negative).
pub const EDGE_BANDS: [(&str, f64, f64); 3] = [
    ("inside 0-2 m", -2.0, 0.0),
    ("outside 0-2 m", 0.0, 2.0),
    ("outside 2-5 m", 2.0, 5.0),
];

/// How the raw classifier labels the bins of one true class in one band beside the true
/// strips' edges (segments with a truth): where the edge is visible to it and where not.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct EdgeBand {
    /// The band ([`EDGE_BANDS`]).
    pub band: &'static str,
    /// The bins' true class (`unlabelled`: a car, pole, trunk or wall is lowest).
    pub class: &'static str,
    /// Usable bins.
    pub bins: u64,
    /// Share of them the classifier calls the target.
    pub predicted_positive: f64,
}

/// One line per band: the share of each true class the classifier calls the target.
pub fn edges_text(edges: &[EdgeBand]) -> String {
    let mut out = String::new();
    for &(band, _, _) in &EDGE_BANDS {
        let cells: Vec<String> = edges
            .iter()
            .filter(|e| e.band == band)
            .map(|e| format!("{} {:.2} of {}", e.class, e.predicted_positive, e.bins))
            .collect();
        if !cells.is_empty() {
            out += &format!(
                "  raw classifier {band} of the true edges, share called the target: {}\n",
                cells.join(", ")
            );
        }
    }
    out
}

/// Counts behind [`EdgeBand`]s, segment by segment.
#[derive(Debug, Clone, Default)]
pub struct EdgeCounts {
    counts: BTreeMap<(usize, &'static str), [u64; 2]>,
}

impl EdgeCounts {
    /// Adds a segment's usable bins (labelled `predicted`, in [`SegmentBins::usable`] order)
    /// beside its true strip `truth` (offset, width), metres.
    pub fn add(
        &mut self,
        bins: &SegmentBins,
        truth: (f64, f64),
        predicted: &[bool],
        grid: &crate::potentials::ThetaGrid,
    ) {
        let (lo, hi) = (truth.0 - 0.5 * truth.1, truth.0 + 0.5 * truth.1);
        for (k, &p) in bins.usable().zip(predicted) {
            let col = k % grid.cols;
            let u = grid.geometry(col, col).0;
            // Signed distance from the nearer edge, positive outside the strip.
            let out = (lo - u).max(u - hi);
            let Some(band) = EDGE_BANDS.iter().position(|&(_, a, b)| out > a && out <= b) else {
                continue;
            };
            let class = bins.features.truth[k].map_or("unlabelled", |c| c.name());
            let e = self.counts.entry((band, class)).or_default();
            e[0] += 1;
            e[1] += u64::from(p);
        }
    }

    /// The bands, in [`EDGE_BANDS`] order, classes by name.
    pub fn bands(self) -> Vec<EdgeBand> {
        self.counts
            .into_iter()
            .map(|((band, class), [n, p])| EdgeBand {
                band: EDGE_BANDS[band].0,
                class,
                bins: n,
                predicted_positive: p as f64 / n.max(1) as f64,
            })
            .collect()
    }
}

/// Largest posterior width spread (standard deviation, metres) of a confident estimate.
pub const CONFIDENT_WIDTH_SD_M: f64 = 1.0;

/// The full model's width and offset errors on the segments whose posterior width spread
/// ([`crate::potentials::width_spread_m`] of the segment's potential with its prior) is at
/// most [`CONFIDENT_WIDTH_SD_M`].
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Confident {
    /// The threshold, metres.
    pub width_sd_max_m: f64,
    /// Confident segments with a truth.
    pub segments: usize,
    /// Segments with a truth.
    pub of_segments: usize,
    /// Share of the length of the segments with a truth that is confident.
    pub coverage: f64,
    /// Length-weighted width RMSE of the confident segments, metres (`None`: none).
    pub rmse_w: Option<f64>,
    /// Length-weighted offset RMSE of the confident segments, metres (`None`: none).
    pub rmse_d: Option<f64>,
}

/// Diagnostics not in Table 4.1.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct TargetDetails {
    /// Full model by MCMC.
    pub mcmc: Scores,
    /// log P of the max-product solution.
    pub max_product_log_p: f64,
    /// log P of the MCMC solution.
    pub mcmc_log_p: f64,
    /// Whether max-product was exact (tree-shaped network).
    pub exact: bool,
    /// Coupled pairs.
    pub edges: usize,
    /// Mean SVM support vectors per fold.
    pub support_vectors: f64,
    /// Confusion counts of the classifiers on their own held-out bins (from the training
    /// segments), summed over folds.
    pub confusion: [[u64; 2]; 2],
    /// Confusion counts on the test segments (held-out folds), summed over folds.
    pub confusion_test: [[u64; 2]; 2],
    /// The tempering each fold selected.
    pub temperings: Vec<Tempering>,
}

/// The evaluation result.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct EvalReport {
    /// Driving area only.
    pub driving_area: TargetScores,
    /// Driving area and sidewalk.
    pub with_sidewalk: TargetScores,
    /// Seconds per stage, plus `per_metre` (incremental seconds per metre of street).
    pub seconds: BTreeMap<String, f64>,
    /// Extra diagnostics (not part of the JSON interface).
    #[serde(skip)]
    pub details: BTreeMap<&'static str, TargetDetails>,
    /// Segments evaluated.
    #[serde(skip)]
    pub segments: usize,
    /// Their total length, metres.
    #[serde(skip)]
    pub street_m: f64,
    /// Usable bins.
    #[serde(skip)]
    pub bins: usize,
    /// Full-model and true geometry per evaluated segment, per target.
    #[serde(skip)]
    pub geometries: BTreeMap<&'static str, Vec<SegmentGeometry>>,
}

/// Estimated and true geometry of one evaluated segment.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct SegmentGeometry {
    /// Segment index in the map.
    pub segment: usize,
    /// Segment length, metres (the weight of its width error in RMSE_w).
    pub length_m: f64,
    /// Full-model (offset, width), metres.
    pub estimate: (f64, f64),
    /// Single-segment (offset, width), metres.
    pub single: (f64, f64),
    /// True (offset, width), metres.
    pub truth: (f64, f64),
    /// The segment model fitted to the true bin labels (offset, width), metres.
    pub opt_on_truth: (f64, f64),
}

#[derive(Default, Clone, Copy)]
struct Counts {
    tp: u64,
    fp: u64,
    fn_: u64,
    tn: u64,
    w_err2: f64,
    d_err2: f64,
    w_len: f64,
    with_width: bool,
}

impl Counts {
    fn scores(&self) -> Scores {
        let c = ClassScores::from_counts(self.tp, self.fp, self.fn_, self.tn);
        Scores {
            precision: c.target.precision,
            recall: c.target.recall,
            f1: c.target.f1,
            weighted: c.weighted,
            macro_avg: c.macro_avg,
            accuracy: c.accuracy,
            positive_share: c.positive_share,
            rmse_w: self
                .with_width
                .then(|| (self.w_err2 / self.w_len.max(1e-12)).sqrt()),
            rmse_d: self
                .with_width
                .then(|| (self.d_err2 / self.w_len.max(1e-12)).sqrt()),
        }
    }

    /// Adds a segment of length `l` whose estimated (offset, width) is `est` to the
    /// length-weighted width and offset errors.
    fn add_segment(&mut self, l: f64, est: (f64, f64), truth: (f64, f64)) {
        self.w_err2 += l * (est.1 - truth.1).powi(2);
        self.d_err2 += l * (est.0 - truth.0).powi(2);
        self.w_len += l;
    }

    fn add_bin(&mut self, predicted: bool, truth: bool) {
        match (predicted, truth) {
            (true, true) => self.tp += 1,
            (true, false) => self.fp += 1,
            (false, true) => self.fn_ += 1,
            (false, false) => self.tn += 1,
        }
    }
}

/// Runs the evaluation.
pub fn evaluate(ds: &StreetsDataset, options: &EvalOptions) -> Result<EvalReport> {
    let mut seconds = BTreeMap::new();
    let segs = &ds.map.streets.segments;
    if segs.is_empty() {
        return Err(StreetsError::NoStreets {
            path: ds.map_path.display().to_string(),
        });
    }
    let candidates: Vec<usize> = (0..segs.len())
        .filter(|&s| ds.segments[s].drivable && ds.segments[s].observed)
        .collect();
    let t = Instant::now();
    let bins = segment_bins(&ds.map, &ds.cloud, &candidates, &options.geometry);
    seconds.insert(
        "corridors_and_features".to_string(),
        t.elapsed().as_secs_f64(),
    );
    let mut eval_ids = Vec::new();
    let mut eval_bins: Vec<SegmentBins> = Vec::new();
    for (&s, b) in candidates.iter().zip(bins) {
        if let Some(b) = b {
            if b.usable().next().is_some() {
                eval_ids.push(s);
                eval_bins.push(b);
            }
        }
    }
    if eval_ids.len() < options.folds.max(2) {
        return Err(StreetsError::Dataset {
            path: ds.dir.clone(),
            message: format!(
                "only {} observed drivable segments with usable bins; the {}-fold evaluation needs at least {}",
                eval_ids.len(),
                options.folds,
                options.folds.max(2)
            ),
        });
    }
    let folds = options.folds.max(2);
    let fold_of = |k: usize| k % folds;
    // Raw feature rows and true classes of the usable bins, per segment.
    let rows: Vec<Vec<f32>> = eval_bins.iter().map(SegmentBins::usable_rows).collect();
    let classes: Vec<Vec<Option<geodata::classes::Class>>> = eval_bins
        .iter()
        .map(|b| b.usable().map(|k| b.features.truth[k]).collect())
        .collect();
    let n_bins: usize = classes.iter().map(Vec::len).sum();
    let street_m: f64 = eval_ids.iter().map(|&s| segs[s].length_m).sum();
    let grid = options.geometry.theta_grid();
    let lambda = (options.geometry.corridor.bin_m / options.geometry.sigma_m).powi(2) / 2.0;
    let edges = network_edges(&ds.map, &eval_ids, &options.geometry);
    let tags: Vec<SegmentTags> = eval_ids
        .iter()
        .map(|&s| SegmentTags::of(&ds.map, s))
        .collect();
    let mut per_target = BTreeMap::new();
    let mut details = BTreeMap::new();
    let mut geometries = BTreeMap::new();
    let (mut train_s, mut predict_s, mut potentials_s, mut inference_s, mut mcmc_s) =
        (0.0, 0.0, 0.0, 0.0, 0.0);
    // The driving area's full-model and single-segment states and its width spreads, for the
    // with-sidewalk prior (the single-segment model's on the single-segment driving area, so
    // that it takes nothing from the network).
    type Driving = (Vec<(usize, usize)>, Vec<(usize, usize)>, Vec<f64>);
    let mut driving: Option<Driving> = None;
    for target in [Target::DrivingArea, Target::WithSidewalk] {
        let mut predicted: Vec<Vec<bool>> = vec![Vec::new(); eval_ids.len()];
        let mut priors = vec![GeometryPrior::flat(); eval_ids.len()];
        let mut fold_priors = Vec::with_capacity(folds);
        let mut fold_sidewalk: Vec<Option<SidewalkPrior>> = Vec::with_capacity(folds);
        // Segment k's prior: with sidewalk, centred on its estimated driving area (the full
        // model's, or with `single` the single-segment model's) when a margin prior was
        // fitted; else its tag group's.
        let segment_prior = |prior: &TagPrior,
                             sidewalk: Option<&SidewalkPrior>,
                             k: usize,
                             single: bool|
         -> GeometryPrior {
            match (sidewalk, &driving) {
                (Some(sp), Some((full, alone, spread)))
                    if target == Target::WithSidewalk && spread[k].is_finite() =>
                {
                    let states = if single { alone } else { full };
                    sp.given_driving_area(
                        &tags[k],
                        grid.geometry(states[k].0, states[k].1),
                        spread[k],
                    )
                }
                _ => prior.for_tags(&tags[k]),
            }
        };
        let mut conf_sum = [[0u64; 2]; 2];
        let mut sv_sum = 0usize;
        for fold in 0..folds {
            // Train on the other folds' labelled bins.
            let t = Instant::now();
            let mut x = Vec::new();
            let mut y = Vec::new();
            let mut train_geom: Vec<(SegmentTags, (f64, f64))> = Vec::new();
            let mut train_margin = Vec::new();
            for k in 0..eval_ids.len() {
                if fold_of(k) == fold {
                    continue;
                }
                if has_truth(ds, eval_ids[k], target) {
                    train_geom.push((tags[k].clone(), true_geometry(ds, eval_ids[k], target)));
                    if target == Target::WithSidewalk {
                        train_margin.extend(margin_sample(ds, eval_ids[k], &tags[k]));
                    }
                }
                for (j, c) in classes[k].iter().enumerate() {
                    if let Some(c) = c {
                        x.extend_from_slice(
                            &rows[k][j * crate::features::FEATURE_DIMS
                                ..(j + 1) * crate::features::FEATURE_DIMS],
                        );
                        y.push(target.positive(*c));
                    }
                }
            }
            let clf = BinClassifier::train(
                &x,
                &y,
                &ClassifierOptions {
                    seed: options.classifier.seed ^ fold as u64,
                    ..options.classifier.clone()
                },
            )?;
            let mut prior = TagPrior::fit(&train_geom, target == Target::WithSidewalk);
            if !options.tag_prior {
                // One prior for every segment: the city-wide fit alone.
                prior.groups.clear();
            }
            sv_sum += clf.svm.support_count();
            for (sum_row, row) in conf_sum.iter_mut().zip(&clf.confusion.counts) {
                for (s, c) in sum_row.iter_mut().zip(row) {
                    *s += c;
                }
            }
            train_s += t.elapsed().as_secs_f64();
            // Predict the test segments' bins.
            let t = Instant::now();
            let test: Vec<usize> = (0..eval_ids.len())
                .filter(|&k| fold_of(k) == fold)
                .collect();
            let mut flat = Vec::new();
            for &k in &test {
                flat.extend_from_slice(&rows[k]);
            }
            let labels = clf.predict(&flat)?;
            let mut off = 0;
            for &k in &test {
                let n = classes[k].len();
                predicted[k] = labels[off..off + n].to_vec();
                off += n;
            }
            predict_s += t.elapsed().as_secs_f64();
            let sidewalk = (options.sidewalk_prior && options.tag_prior)
                .then(|| SidewalkPrior::fit(&train_margin))
                .flatten();
            for &k in &test {
                priors[k] = segment_prior(&prior, sidewalk.as_ref(), k, false);
            }
            fold_priors.push(prior);
            fold_sidewalk.push(sidewalk);
        }
        // Potentials: C of fold f from the out-of-fold predictions of its training segments
        // (segments held out from the classifier that labelled them), the tempering selected on
        // those training segments, then the test segments' potentials.
        let t = Instant::now();
        let counts: Vec<_> = (0..eval_ids.len())
            .map(|k| eval_bins[k].counts(&predicted[k]))
            .collect();
        let mut potentials: Vec<Option<SegmentPotential>> = vec![None; eval_ids.len()];
        // Single-segment states where its prior differs from the full model's.
        let mut single_states: Vec<Option<(usize, usize)>> = vec![None; eval_ids.len()];
        let mut conf_test = [[0u64; 2]; 2];
        let mut chosen = Vec::with_capacity(folds);
        let truth_cols: Vec<(usize, usize)> = eval_ids
            .iter()
            .map(|&s| {
                let (d, w) = true_geometry(ds, s, target);
                grid.columns_of(d, w)
            })
            .collect();
        for (fold, (fold_prior, sidewalk)) in fold_priors.iter().zip(&fold_sidewalk).enumerate() {
            let mut truth = Vec::new();
            let mut pred = Vec::new();
            for k in (0..eval_ids.len()).filter(|&k| fold_of(k) != fold) {
                for (c, &p) in classes[k].iter().zip(&predicted[k]) {
                    if let Some(c) = c {
                        truth.push(target.positive(*c));
                        pred.push(p);
                    }
                }
            }
            let clog = Confusion::from_pairs(&truth, &pred).log_likelihood();
            let flat = GeometryPrior::flat();
            let tables = |single: bool| {
                PriorTables::new(
                    &(0..eval_ids.len())
                        .map(|k| segment_prior(fold_prior, sidewalk.as_ref(), k, single))
                        .collect::<Vec<_>>(),
                    &grid,
                )
            };
            let prior_log = tables(false);
            // The single-segment model's priors differ only where they rest on the driving
            // area's estimate.
            let single_log =
                (target == Target::WithSidewalk && driving.is_some()).then(|| tables(true));
            let ll: Vec<SegmentPotential> = counts
                .par_iter()
                .map(|c| segment_potential(c, &clog, &flat, &grid))
                .collect();
            let train: Vec<usize> = (0..eval_ids.len())
                .filter(|&k| fold_of(k) != fold)
                .collect();
            let selected = select_tempering(
                &options.temperings,
                &Selection {
                    ll: &ll,
                    members: &train,
                    truth: &truth_cols,
                    weights: &eval_ids
                        .iter()
                        .map(|&s| {
                            if has_truth(ds, s, target) {
                                segs[s].length_m
                            } else {
                                0.0
                            }
                        })
                        .collect::<Vec<_>>(),
                    edges: &edges,
                    lambda,
                    prior: &prior_log,
                },
            );
            chosen.push(selected);
            for k in (0..eval_ids.len()).filter(|&k| fold_of(k) == fold) {
                potentials[k] = Some(tempered_with_prior(&ll[k], &selected, prior_log.table(k)));
                single_states[k] = single_log
                    .as_ref()
                    .map(|t| tempered_with_prior(&ll[k], &selected, t.table(k)).argmax());
                for (c, &p) in classes[k].iter().zip(&predicted[k]) {
                    if let Some(c) = c {
                        conf_test[usize::from(target.positive(*c))][usize::from(p)] += 1;
                    }
                }
            }
        }
        potentials_s += t.elapsed().as_secs_f64();
        let spread: Vec<f64> = potentials
            .iter()
            .map(|p| {
                p.as_ref()
                    .map_or(f64::INFINITY, |p| width_spread_m(p, &grid))
            })
            .collect();
        let mut net = Network {
            potentials: potentials
                .into_iter()
                .map(|p| {
                    p.unwrap_or(SegmentPotential {
                        cols: grid.cols,
                        log: vec![0.0; grid.cols * grid.cols],
                    })
                })
                .collect(),
            edges: edges.clone(),
            lambda,
            truncation: chosen[0].coupling_cap_nats,
        };
        let mut single = net.single_segment();
        for (state, own) in single.states.iter_mut().zip(&single_states) {
            if let Some(own) = own {
                *state = *own;
            }
        }
        // The full model: a test fold's segments take their states from the whole network
        // with the coupling cap that fold selected (one run per distinct cap).
        let t = Instant::now();
        let mut full_states = single.states.clone();
        let mut done = vec![false; folds];
        let (mut full_exact, mut full_log_p) = (true, f64::NAN);
        for f in 0..folds {
            if done[f] {
                continue;
            }
            let cap = chosen[f].coupling_cap_nats;
            net.truncation = cap;
            let sol = net.max_product(20);
            full_exact &= sol.exact;
            if f == 0 {
                full_log_p = sol.log_probability;
            }
            for g in f..folds {
                if chosen[g].coupling_cap_nats.total_cmp(&cap).is_eq() {
                    done[g] = true;
                    for k in (g..eval_ids.len()).step_by(folds) {
                        full_states[k] = sol.states[k];
                    }
                }
            }
        }
        inference_s += t.elapsed().as_secs_f64();
        // MCMC on the network with fold 0's cap (its log P is compared with max-product's there).
        net.truncation = chosen[0].coupling_cap_nats;
        let t = Instant::now();
        let mcmc = net.mcmc(&options.mcmc);
        mcmc_s += t.elapsed().as_secs_f64();
        // The optimum on true labels: the segment model (with its fold's prior) and an almost
        // perfect classifier.
        let perfect = Confusion {
            counts: [[999, 1], [1, 999]],
        }
        .log_likelihood();
        let truth_states: Vec<(usize, usize)> = (0..eval_ids.len())
            .map(|k| {
                let truth: Vec<bool> = classes[k]
                    .iter()
                    .map(|c| c.is_some_and(|c| target.positive(c)))
                    .collect();
                // Unlabelled bins are left out of the fit.
                let mut counts = eval_bins[k].counts(&truth);
                for (j, (kk, c)) in eval_bins[k].usable().zip(&classes[k]).enumerate() {
                    let _ = j;
                    if c.is_none() {
                        counts.zeros[kk % grid.cols] -= 1;
                    }
                }
                segment_potential(&counts, &perfect, &priors[k], &grid).argmax()
            })
            .collect();
        let score = |states: Option<&[(usize, usize)]>| -> Scores {
            let mut c = Counts {
                with_width: states.is_some(),
                ..Counts::default()
            };
            for k in 0..eval_ids.len() {
                let cols = grid.cols;
                for (j, (bin, cls)) in eval_bins[k].usable().zip(&classes[k]).enumerate() {
                    let Some(cls) = cls else { continue };
                    let truth = target.positive(*cls);
                    let pred = match states {
                        None => predicted[k][j],
                        Some(st) => (st[k].0..=st[k].1).contains(&(bin % cols)),
                    };
                    c.add_bin(pred, truth);
                }
                if let Some(st) = states.filter(|_| has_truth(ds, eval_ids[k], target)) {
                    c.add_segment(
                        segs[eval_ids[k]].length_m,
                        grid.geometry(st[k].0, st[k].1),
                        true_geometry(ds, eval_ids[k], target),
                    );
                }
            }
            c.scores()
        };
        // The raw classifier beside the true edges, by band and true class.
        let mut edge_counts = EdgeCounts::default();
        for k in (0..eval_ids.len()).filter(|&k| has_truth(ds, eval_ids[k], target)) {
            edge_counts.add(
                &eval_bins[k],
                true_geometry(ds, eval_ids[k], target),
                &predicted[k],
                &grid,
            );
        }
        let edges = edge_counts.bands();
        let scores = TargetScores {
            raw: score(None),
            single_segment: score(Some(&single.states)),
            full_model: score(Some(&full_states)),
            opt_on_truth: score(Some(&truth_states)),
            true_geometry: score(Some(&truth_cols)),
            confident: {
                let (mut n, mut of, mut len_all) = (0, 0, 0.0);
                let mut c = Counts {
                    with_width: true,
                    ..Counts::default()
                };
                for k in (0..eval_ids.len()).filter(|&k| has_truth(ds, eval_ids[k], target)) {
                    let l = segs[eval_ids[k]].length_m;
                    of += 1;
                    len_all += l;
                    if spread[k] <= CONFIDENT_WIDTH_SD_M {
                        n += 1;
                        c.add_segment(
                            l,
                            grid.geometry(full_states[k].0, full_states[k].1),
                            true_geometry(ds, eval_ids[k], target),
                        );
                    }
                }
                let s = c.scores();
                Confident {
                    width_sd_max_m: CONFIDENT_WIDTH_SD_M,
                    segments: n,
                    of_segments: of,
                    coverage: c.w_len / len_all.max(1e-12),
                    rmse_w: s.rmse_w.filter(|_| n > 0),
                    rmse_d: s.rmse_d.filter(|_| n > 0),
                }
            },
            edges,
        };
        details.insert(
            target.key(),
            TargetDetails {
                mcmc: score(Some(&mcmc.states)),
                max_product_log_p: full_log_p,
                mcmc_log_p: mcmc.log_probability,
                exact: full_exact,
                edges: net.edges.len(),
                support_vectors: sv_sum as f64 / folds as f64,
                confusion: conf_sum,
                confusion_test: conf_test,
                temperings: chosen,
            },
        );
        geometries.insert(
            target.key(),
            (0..eval_ids.len())
                .filter(|&k| has_truth(ds, eval_ids[k], target))
                .map(|k| SegmentGeometry {
                    segment: eval_ids[k],
                    length_m: segs[eval_ids[k]].length_m,
                    estimate: grid.geometry(full_states[k].0, full_states[k].1),
                    single: grid.geometry(single.states[k].0, single.states[k].1),
                    truth: true_geometry(ds, eval_ids[k], target),
                    opt_on_truth: grid.geometry(truth_states[k].0, truth_states[k].1),
                })
                .collect(),
        );
        if target == Target::DrivingArea {
            driving = Some((full_states, single.states, spread));
        }
        per_target.insert(target, scores);
    }
    seconds.insert("svm_training".into(), train_s);
    seconds.insert("svm_prediction".into(), predict_s);
    seconds.insert("potentials".into(), potentials_s);
    seconds.insert("max_product".into(), inference_s);
    seconds.insert("mcmc".into(), mcmc_s);
    // Incremental cost per metre of street for one target: corridors and features, then
    // prediction and potentials of that target.
    let per_metre =
        (seconds["corridors_and_features"] + 0.5 * (predict_s + potentials_s)) / street_m.max(1e-9);
    seconds.insert("per_metre".into(), per_metre);
    let total: f64 = [
        "corridors_and_features",
        "svm_training",
        "svm_prediction",
        "potentials",
        "max_product",
        "mcmc",
    ]
    .iter()
    .map(|k| seconds[*k])
    .sum();
    seconds.insert("total".into(), total);
    let take = |m: &mut BTreeMap<Target, TargetScores>, t: Target| {
        m.remove(&t).ok_or_else(|| StreetsError::Dataset {
            path: ds.dir.clone(),
            message: "internal: target missing".into(),
        })
    };
    Ok(EvalReport {
        driving_area: take(&mut per_target, Target::DrivingArea)?,
        with_sidewalk: take(&mut per_target, Target::WithSidewalk)?,
        seconds,
        details,
        segments: eval_ids.len(),
        street_m,
        bins: n_bins,
        geometries,
    })
}

/// What [`select_tempering`] scores: a subnetwork of training segments with their truth.
struct Selection<'a> {
    /// Likelihood tables (flat prior) of all segments.
    ll: &'a [SegmentPotential],
    /// The training segments (indices into `ll`).
    members: &'a [usize],
    /// True column ranges of all segments.
    truth: &'a [(usize, usize)],
    /// Length weights of all segments.
    weights: &'a [f64],
    /// Edges among all segments.
    edges: &'a [crate::inference::Edge],
    /// Coupling.
    lambda: f64,
    /// The fold's prior tables of all segments.
    prior: &'a PriorTables,
}

/// The candidate whose full-model solution on the training subnetwork has the smallest
/// length-weighted squared boundary error (ties: the earlier candidate).
fn select_tempering(candidates: &[Tempering], sel: &Selection) -> Tempering {
    if candidates.len() < 2 {
        return candidates.first().copied().unwrap_or_default();
    }
    let mut pos = vec![usize::MAX; sel.ll.len()];
    for (i, &k) in sel.members.iter().enumerate() {
        pos[k] = i;
    }
    let edges: Vec<crate::inference::Edge> = sel
        .edges
        .iter()
        .filter(|e| pos[e.s1] != usize::MAX && pos[e.s2] != usize::MAX)
        .map(|e| crate::inference::Edge {
            s1: pos[e.s1],
            s2: pos[e.s2],
            flipped: e.flipped,
        })
        .collect();
    let errors: Vec<f64> = candidates
        .par_iter()
        .map(|t| {
            let net = Network {
                potentials: sel
                    .members
                    .iter()
                    .map(|&k| tempered_with_prior(&sel.ll[k], t, sel.prior.table(k)))
                    .collect(),
                edges: edges.clone(),
                lambda: sel.lambda,
                truncation: t.coupling_cap_nats,
            };
            let sol = net.max_product(20);
            sel.members
                .iter()
                .zip(&sol.states)
                .map(|(&k, &(a, b))| {
                    let (ta, tb) = sel.truth[k];
                    let da = a as f64 - ta as f64;
                    let db = b as f64 - tb as f64;
                    sel.weights[k] * (da * da + db * db)
                })
                .sum()
        })
        .collect();
    let mut best = 0;
    for (i, e) in errors.iter().enumerate() {
        if *e < errors[best] {
            best = i;
        }
    }
    candidates[best]
}

/// One method's row of the Table 4.1 analogue.
fn scores_row(name: &str, s: &Scores) -> String {
    let m = |v: Option<f64>| v.map_or("n/a".to_string(), |r| format!("{r:.2}"));
    format!(
        "  {name:<16} {:>6.3} {:>6.3} {:>6.3} {:>8} {:>8}",
        s.precision,
        s.recall,
        s.f1,
        m(s.rmse_w),
        m(s.rmse_d)
    )
}

impl EvalReport {
    /// The Table 4.1 analogue as text: per target, precision, recall, F1, RMSE_w and the
    /// offset RMSE of every method, then the seconds per stage.
    pub fn table_text(&self) -> String {
        let r = self;
        let mut out = format!(
            "{} segments, {:.0} m of street, {} usable bins\n",
            r.segments, r.street_m, r.bins
        );
        for (name, t) in [
            ("driving area & sidewalk", &r.with_sidewalk),
            ("driving area only", &r.driving_area),
        ] {
            out += &format!(
                "{name}\n  {:<16} {:>6} {:>6} {:>6} {:>8} {:>8}\n",
                "method", "P", "R", "F1", "RMSE_w", "RMSE_d"
            );
            out += &(scores_row("raw", &t.raw) + "\n");
            out += &(scores_row("single segment", &t.single_segment) + "\n");
            out += &(scores_row("full model", &t.full_model) + "\n");
            out += &(scores_row("opt. on truth", &t.opt_on_truth) + "\n");
            out += &(scores_row("true geometry", &t.true_geometry) + "\n");
            out += &format!(
                "  both classes averaged, weighted by their bins (as Table 4.1; {:.0} % of the bins are the target), P/R/F1:\n",
                100.0 * t.raw.positive_share
            );
            for (method, s) in [
                ("raw", &t.raw),
                ("single segment", &t.single_segment),
                ("full model", &t.full_model),
                ("opt. on truth", &t.opt_on_truth),
                ("true geometry", &t.true_geometry),
            ] {
                let w = &s.weighted;
                out += &format!(
                    "  {method:<16} {:>6.3} {:>6.3} {:>6.3}\n",
                    w.precision, w.recall, w.f1
                );
            }
            let c = &t.confident;
            let m = |v: Option<f64>| v.map_or("n/a".to_string(), |r| format!("{r:.2}"));
            out += &format!(
                "  full model where the width spread is at most {:.1} m: {} of {} segments, {:.0} % of their length, RMSE_w {}, RMSE_d {}\n",
                c.width_sd_max_m,
                c.segments,
                c.of_segments,
                100.0 * c.coverage,
                m(c.rmse_w),
                m(c.rmse_d)
            );
            out += &edges_text(&t.edges);
        }
        out += "seconds:";
        for (k, v) in &r.seconds {
            out += &format!(" {k}={v:.4}");
        }
        out
    }

    /// Diagnostics per target as text: max-product against MCMC, coupled pairs, support
    /// vectors, confusion, tempering.
    pub fn details_text(&self) -> String {
        let r = self;
        let mut out = format!(
            "cost per metre of street: {:.2} ms (thesis 7.6 s)",
            1000.0 * r.seconds.get("per_metre").copied().unwrap_or(f64::NAN)
        );
        for (k, d) in &r.details {
            out += &format!(
            "\n{k}: max-product ({}) log P {:.3}, MCMC log P {:.3} (gap {:.3}); MCMC F1 {:.3} RMSE_w {}; {} coupled pairs; {:.0} SVs/fold; confusion on the classifiers' held-out bins {:?}, on the test folds {:?}; tempering per fold (τ, floor, prior weight, coupling cap) {}",
            if d.exact { "exact, tree" } else { "loopy" },
            d.max_product_log_p,
            d.mcmc_log_p,
            d.max_product_log_p - d.mcmc_log_p,
            d.mcmc.f1,
            d.mcmc.rmse_w.map_or("n/a".into(), |v| format!("{v:.2}")),
            d.edges,
            d.support_vectors,
            d.confusion,
            d.confusion_test,
            d.temperings
                .iter()
                .map(|t| {
                    format!(
                        "({}, {}, {}, {})",
                        t.tau, t.floor_nats, t.prior_weight, t.coupling_cap_nats
                    )
                })
                .collect::<Vec<_>>()
                .join(" ")
        );
        }
        out
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::expect_used)]
    use super::*;

    /// Class-averaged scores recomputed bin by bin, per class, from the definitions.
    fn by_definition(bins: &[(bool, bool)]) -> (Prf, Prf, f64) {
        let class = |c: bool| {
            let tp = bins.iter().filter(|&&(p, t)| p == c && t == c).count() as f64;
            let predicted = bins.iter().filter(|&&(p, _)| p == c).count() as f64;
            let support = bins.iter().filter(|&&(_, t)| t == c).count() as f64;
            let p = if predicted > 0.0 { tp / predicted } else { 0.0 };
            let r = if support > 0.0 { tp / support } else { 0.0 };
            let f = if p + r > 0.0 {
                2.0 * p * r / (p + r)
            } else {
                0.0
            };
            (p, r, f, support)
        };
        let (a, b) = (class(true), class(false));
        let n = a.3 + b.3;
        let w = |x: f64, y: f64| (a.3 * x + b.3 * y) / n;
        let weighted = Prf {
            precision: w(a.0, b.0),
            recall: w(a.1, b.1),
            f1: w(a.2, b.2),
        };
        let macro_avg = Prf {
            precision: (a.0 + b.0) / 2.0,
            recall: (a.1 + b.1) / 2.0,
            f1: (a.2 + b.2) / 2.0,
        };
        let correct = bins.iter().filter(|&&(p, t)| p == t).count() as f64;
        (weighted, macro_avg, correct / n)
    }

    #[test]
    fn class_averaged_scores_follow_their_definitions() {
        // Every bin list of up to 6 bins over the four (predicted, true) outcomes.
        let outcomes = [(true, true), (true, false), (false, true), (false, false)];
        let close = |a: &Prf, b: &Prf| {
            (a.precision - b.precision).abs() < 1e-12
                && (a.recall - b.recall).abs() < 1e-12
                && (a.f1 - b.f1).abs() < 1e-12
        };
        let mut checked = 0;
        for len in 1..=6u32 {
            for code in 0..4usize.pow(len) {
                let bins: Vec<(bool, bool)> = (0..len)
                    .map(|i| outcomes[code / 4usize.pow(i) % 4])
                    .collect();
                let mut c = Counts::default();
                for &(p, t) in &bins {
                    c.add_bin(p, t);
                }
                let s = c.scores();
                let (predicted, truth): (Vec<bool>, Vec<bool>) = bins.iter().copied().unzip();
                assert_eq!(
                    ClassScores::of(&predicted, &truth),
                    ClassScores::from_counts(c.tp, c.fp, c.fn_, c.tn)
                );
                let (weighted, macro_avg, accuracy) = by_definition(&bins);
                assert!(close(&s.weighted, &weighted), "{bins:?}: {s:?}");
                assert!(close(&s.macro_avg, &macro_avg), "{bins:?}: {s:?}");
                assert!((s.accuracy - accuracy).abs() < 1e-12);
                // The support-weighted recall is the accuracy.
                assert!((s.weighted.recall - accuracy).abs() < 1e-12);
                checked += 1;
            }
        }
        assert_eq!(checked, 5460);
    }
}
