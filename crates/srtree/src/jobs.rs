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
pub fn read_model(path: &Path) -> Result<RelationModel> {
    let text = std::fs::read_to_string(path).context(|| format!("reading {}", path.display()))?;
    Ok(serde_json::from_str(&text)
        .context(|| format!("{}: not a relation model", path.display()))?)
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
