//! `relations train` and `relations eval` as library calls: load the datasets, train or read
//! the model, evaluate, write the per-pair errors; the binary prints what they return.

use crate::dataset::RelationsDataset;
use crate::error::{Result, SrtreeError};
use crate::map::MapOptions;
use crate::objects::ObjectOptions;
use crate::relations::{evaluate, train, Evaluation, RelationModel, TrainOptions};
use geodata::context::WithContext;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// Loads a simulated relations dataset with its name in the error.
pub fn load_dataset(dir: &Path) -> Result<RelationsDataset> {
    Ok(
        RelationsDataset::load(dir, &MapOptions::default(), &ObjectOptions::default())
            .context(|| format!("loading the relations dataset {}", dir.display()))?,
    )
}

/// Reads a relation model written by `relations train`.
/// Its dimensions and values are checked against this build's features
/// ([`RelationModel::check`]): a model written by a build with other features is an error
/// naming the file, never a silently different answer.
pub fn read_model(path: &Path) -> Result<RelationModel> {
    let text = std::fs::read_to_string(path).context(|| format!("reading {}", path.display()))?;
    let model: RelationModel = serde_json::from_str(&text)
        .context(|| format!("{}: not a relation model", path.display()))?;
    model.check().map_err(|message| SrtreeError::Model {
        path: path.to_path_buf(),
        message,
    })?;
    Ok(model)
}

/// Writes `text` to `path` atomically.
fn write(path: &Path, text: String) -> Result<()> {
    geodata::fsio::write_atomic(path, text).context(|| format!("writing {}", path.display()))?;
    Ok(())
}

/// A model trained by [`train_model`].
#[derive(Debug, Clone)]
pub struct TrainRun {
    /// The model (also written to the output file).
    pub model: RelationModel,
    /// Training scenes.
    pub scenes: usize,
    /// Seconds loading the dataset.
    pub load_s: f64,
    /// Seconds training.
    pub train_s: f64,
}

/// `relations train`: trains on the dataset's training scenes and writes the model to `out`.
pub fn train_model(dataset: &Path, out: &Path, seed: u64) -> Result<TrainRun> {
    let t = Instant::now();
    let ds = load_dataset(dataset)?;
    let load_s = t.elapsed().as_secs_f64();
    let t = Instant::now();
    let model = train(&ds.train, &TrainOptions::seeded(seed))
        .context(|| "training the relation model".into())?;
    let json = serde_json::to_string_pretty(&model).context(|| "serialising the model".into())?;
    write(out, json)?;
    Ok(TrainRun {
        model,
        scenes: ds.train.len(),
        load_s,
        train_s: t.elapsed().as_secs_f64(),
    })
}

/// What `relations eval` evaluates: a dataset's test scenes (all of them when trained on
/// other datasets), with a given model or one trained here.
#[derive(Debug, Clone)]
pub struct EvalJob {
    /// The dataset tested.
    pub dataset: PathBuf,
    /// A model to test; `None`: train one on the training scenes.
    pub model: Option<PathBuf>,
    /// Datasets to train on instead of `dataset`'s own training scenes (cross-dataset split).
    pub train_datasets: Vec<PathBuf>,
    /// Where to write every wrong pair as JSON lines.
    pub errors_out: Option<PathBuf>,
    /// Seed of training and inference.
    pub seed: u64,
}

/// The outcome of [`eval_relations`].
#[derive(Debug, Clone)]
pub struct EvalRun {
    /// The Table 3.6 analogue.
    pub evaluation: Evaluation,
    /// The model tested.
    pub model: RelationModel,
    /// Training scenes (of the training datasets in a cross-dataset split).
    pub train_scenes: usize,
    /// Test scenes.
    pub test_scenes: usize,
    /// Seconds loading, training and testing.
    pub seconds: [f64; 3],
}

/// `relations eval`: loads, trains (unless a model is given), evaluates, writes the errors.
/// A training dataset that is the test dataset is [`SrtreeError::TestAmongTraining`].
pub fn eval_relations(job: &EvalJob) -> Result<EvalRun> {
    let t = Instant::now();
    // Across datasets every scene of the test dataset is unseen: test on all of them (a
    // 14-scene test split holds as few as 7 Behind pairs).
    let (ds, train_scenes) = if job.train_datasets.is_empty() {
        (load_dataset(&job.dataset)?, None)
    } else {
        let split = match RelationsDataset::load_across(
            &job.dataset,
            &job.train_datasets,
            &MapOptions::default(),
            &ObjectOptions::default(),
        ) {
            Err(e @ SrtreeError::TestAmongTraining { .. }) => return Err(e),
            r => {
                r.context(|| format!("loading the relations datasets {}", job.dataset.display()))?
            }
        };
        (split.test, Some(split.train))
    };
    let load_s = t.elapsed().as_secs_f64();
    let t = Instant::now();
    let model = match &job.model {
        Some(p) => read_model(p)?,
        None => {
            let scenes = train_scenes.as_ref().unwrap_or(&ds.train);
            train(scenes, &TrainOptions::seeded(job.seed))
                .context(|| "training the relation model".into())?
        }
    };
    let train_s = t.elapsed().as_secs_f64();
    let t = Instant::now();
    let mut infer = mln::infer::InferOptions::default();
    infer.walksat.seed = job.seed;
    let evaluation = evaluate(&model, &ds, &infer).context(|| "evaluating".into())?;
    if let Some(path) = &job.errors_out {
        let mut lines = String::new();
        for e in &evaluation.errors {
            lines += &serde_json::to_string(e).context(|| "serialising an error".into())?;
            lines.push('\n');
        }
        write(path, lines)?;
    }
    Ok(EvalRun {
        evaluation,
        model,
        train_scenes: train_scenes.as_ref().map_or(ds.train.len(), Vec::len),
        test_scenes: ds.test.len(),
        seconds: [load_s, train_s, t.elapsed().as_secs_f64()],
    })
}

impl EvalRun {
    /// The table as `relations eval` prints it: scenes and pairs, the Table 3.6 analogue,
    /// the MLN weights and the timings.
    pub fn text(&self, job: &EvalJob) -> String {
        let ev = &self.evaluation;
        let of = if job.train_datasets.is_empty() {
            String::new()
        } else {
            let names: Vec<String> = job
                .train_datasets
                .iter()
                .map(|p| p.display().to_string())
                .collect();
            format!(" (of {})", names.join(", "))
        };
        format!(
            "{}: {} train{of} / {} test scenes, {} test pairs ({} with an object missing from the map)\n{}MLN weights: transitivity {:?}, evidence {:?}; {:.1} s loading, {:.1} s training, {:.1} s testing\n",
            job.dataset.display(),
            self.train_scenes,
            self.test_scenes,
            ev.pairs,
            ev.missing_pairs,
            ev.table_text(),
            self.model.mln.transitivity,
            self.model.mln.evidence,
            self.seconds[0],
            self.seconds[1],
            self.seconds[2]
        )
    }
}

/// `urbansem map build` from a ROS 2 bag: every scan of a point cloud topic placed by the
/// pose of an odometry/TF topic at its stamp.
#[derive(Debug, Clone)]
pub struct BagBuildJob {
    /// The bag (.mcap).
    pub bag: PathBuf,
    /// Its `sensor_msgs/msg/PointCloud2` topic.
    pub cloud_topic: String,
    /// Its Odometry, PoseStamped or TF topic giving the sensor's pose in the map frame.
    pub pose_topic: String,
    /// For a TF topic: the child frame whose transform places the scans.
    pub child_frame: Option<String>,
    /// Use every n-th scan (1: all).
    pub every: usize,
    /// A scan more than this many seconds from both poses around it is skipped.
    pub max_gap_s: f64,
    /// Scans inserted per batch (the batch's new cells are indexed once).
    pub batch: usize,
    /// The map's options.
    pub options: MapOptions,
}

/// What [`build_from_bag`] did.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct BagBuild {
    /// Scans on the cloud topic.
    pub scans: usize,
    /// Scans inserted.
    pub inserted: usize,
    /// Scans skipped: no pose within `max_gap_s` of their stamp.
    pub skipped_without_pose: usize,
    /// Poses on the pose topic.
    pub poses: usize,
    /// Summed insertion statistics.
    #[serde(skip)]
    pub stats: crate::map::InsertStats,
    /// Seconds reading and decoding the bag (poses and scans).
    pub seconds_read: f64,
    /// Seconds inserting.
    pub seconds_insert: f64,
}

/// Builds a map from a bag's scans placed by its poses (sensor origin = the pose's
/// translation, so ray casting clears the space each scan saw). The map frame is the pose
/// topic's parent frame. A scan's time is its `header.stamp` (its log time when unstamped).
pub fn build_from_bag(job: &BagBuildJob) -> Result<(crate::map::SrMap, BagBuild)> {
    use geodata::cloud::mcap::{for_each_bag_cloud, Next, PoseTrack};
    use geodata::cloud::{PointCloud, ReadOptions};
    if job.every == 0 || job.batch == 0 || job.max_gap_s.is_nan() || job.max_gap_s < 0.0 {
        return Err(SrtreeError::InvalidOption {
            name: "every/batch/max_gap_s",
            value: job.max_gap_s,
            expected: "every ≥ 1, batch ≥ 1 and a gap ≥ 0 s",
        });
    }
    let t0 = Instant::now();
    let track = PoseTrack::read(
        &job.bag,
        &job.pose_topic,
        job.child_frame.as_deref(),
        job.max_gap_s,
    )?;
    let mut map = crate::map::SrMap::new(job.options.clone())?;
    let mut report = BagBuild {
        scans: 0,
        inserted: 0,
        skipped_without_pose: 0,
        poses: track.poses.len(),
        stats: crate::map::InsertStats::default(),
        seconds_read: 0.0,
        seconds_insert: 0.0,
    };
    let mut pending: Vec<(PointCloud, [f64; 3])> = Vec::new();
    let mut failure: Option<SrtreeError> = None;
    let mut insert_s = 0.0;
    let mut flush = |map: &mut crate::map::SrMap,
                     pending: &mut Vec<(PointCloud, [f64; 3])>,
                     report: &mut BagBuild|
     -> Result<()> {
        let t = Instant::now();
        let scans: Vec<(&PointCloud, Option<[f64; 3]>)> =
            pending.iter().map(|(c, o)| (c, Some(*o))).collect();
        let s = map.insert_scans(&scans)?;
        report.stats.points += s.points;
        report.stats.new_cells += s.new_cells;
        report.stats.touched_cells += s.touched_cells;
        report.stats.rays += s.rays;
        report.stats.misses += s.misses;
        report.stats.bulk_loaded |= s.bulk_loaded;
        report.inserted += pending.len();
        pending.clear();
        insert_s += t.elapsed().as_secs_f64();
        Ok(())
    };
    let scans = for_each_bag_cloud(
        &job.bag,
        &job.cloud_topic,
        &ReadOptions::default(),
        |scan| {
            if scan.index % job.every != 0 {
                return Next::Continue;
            }
            let Some(pose) = track.at(&scan) else {
                report.skipped_without_pose += 1;
                return Next::Continue;
            };
            let mut cloud = scan.cloud;
            for p in &mut cloud.positions {
                *p = pose.apply(*p);
            }
            pending.push((cloud, pose.translation));
            if pending.len() >= job.batch {
                if let Err(e) = flush(&mut map, &mut pending, &mut report) {
                    failure = Some(e);
                    return Next::Stop;
                }
            }
            Next::Continue
        },
    )?;
    if let Some(e) = failure {
        return Err(e);
    }
    if !pending.is_empty() {
        flush(&mut map, &mut pending, &mut report)?;
    }
    report.scans = scans;
    report.seconds_insert = insert_s;
    report.seconds_read = t0.elapsed().as_secs_f64() - insert_s;
    Ok((map, report))
}
