//! `urbansem demo`: every capability that exists so far, run on the embedded default city,
//! with a report (`summary.json`, `timings.json`, `index.html` with figures, figure files).
//!
//! A harness above every crate of the pipeline, as `urbansem-bench` is: one module per
//! crate's stage (`city`, `sim`, `pbo`, `mln`, `streets`, `localize`, `srtree`), each a
//! [`Stage`] giving its summary entry (a typed value per stage, e.g.
//! [`localize::TrackSummary`], serialised into `summary.json`) and report section; [`run`] runs them in pipeline order
//! and writes the report. Like the binary, it reports errors with `anyhow`. The `urbansem`
//! binary only parses `urbansem demo`'s options, shows progress and prints where the report is.

pub mod city;
pub mod localize;
pub mod mln;
pub mod pbo;
pub mod report;
pub mod sim;
pub mod srtree;
pub mod streets;

use anyhow::Context;
use report::Html;
use serde_json::{json, Map, Value};
use std::path::PathBuf;
use std::time::Instant;

/// Options of the demo.
#[derive(Clone, Debug)]
pub struct DemoArgs {
    /// Output folder for summary.json and index.html.
    pub out: PathBuf,
    /// Seed of every random step (same seed, same report numbers).
    pub seed: u64,
}

/// Where the demo wrote its report.
#[derive(Clone, Debug)]
pub struct DemoOutcome {
    /// `summary.json`: every stage's numbers, timings aside.
    pub summary_path: PathBuf,
    /// `timings.json`: every stage's timings.
    pub timings_path: PathBuf,
    /// `index.html`: the report with figures.
    pub html_path: PathBuf,
    /// Wall time of the whole demo.
    pub seconds: f64,
}

/// One stage's contribution: its summary entry and its report section.
pub struct StageOutput {
    /// Key of the stage's entry in `summary.json`.
    pub key: &'static str,
    /// The stage's entry in `summary.json` (an object; its timings move to `timings.json`).
    pub summary: Value,
    /// Section title in `index.html`.
    pub title: &'static str,
    /// Section text (HTML).
    pub text_html: String,
    /// Inline figures (HTML: `<svg>` or `<img>`).
    pub figures: Vec<String>,
    /// Figures also written as files into the output folder: (file name, bytes).
    pub files: Vec<(&'static str, Vec<u8>)>,
}

/// One demo stage: a capability run on the embedded data, giving its summary entry and its
/// report section. The stages live one module per crate (`city`, `sim`, `pbo`, `mln`,
/// `streets`, `localize`, `srtree`); this module only runs them and writes the report.
pub trait Stage {
    /// The name shown while the stage runs.
    fn name(&self) -> &'static str;
    /// Runs the stage.
    fn run(&self, args: &DemoArgs) -> anyhow::Result<StageOutput>;
}

/// A [`Stage`] made of a name and a function.
struct FnStage(&'static str, fn(&DemoArgs) -> anyhow::Result<StageOutput>);

impl Stage for FnStage {
    fn name(&self) -> &'static str {
        self.0
    }

    fn run(&self, args: &DemoArgs) -> anyhow::Result<StageOutput> {
        (self.1)(args)
    }
}

/// The stages, in pipeline order.
pub fn stages() -> Vec<Box<dyn Stage>> {
    vec![
        Box::new(FnStage("geodata: embedded default city", city::stage)),
        Box::new(FnStage("geodata: simulated scans", sim::stage)),
        Box::new(FnStage(
            "pbo: binary image denoising (QPBO)",
            pbo::denoise_stage,
        )),
        Box::new(FnStage(
            "pbo: higher-order functions (QSSR per quadratizer)",
            pbo::higher_order_stage,
        )),
        Box::new(FnStage(
            "mln: MAP on the thesis' synthetic problems",
            mln::stage,
        )),
        Box::new(FnStage("streets: widths and offsets", streets::stage)),
        Box::new(FnStage("localize: one scan on the map", localize::stage)),
        Box::new(FnStage(
            "localize: a car-LiDAR drive along its track",
            localize::track_stage,
        )),
        Box::new(FnStage(
            "srtree: semantic map and spatial relations",
            srtree::stage,
        )),
    ]
}

/// Runs every stage in pipeline order and writes the report into `args.out`; `progress` is
/// called before each stage with (stage index, stage count, stage name).
pub fn run(args: &DemoArgs, progress: &dyn Fn(usize, usize, &str)) -> anyhow::Result<DemoOutcome> {
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("creating the output folder {}", args.out.display()))?;
    let stages = stages();
    let t0 = Instant::now();
    let mut summary = Map::new();
    let mut timings = Map::new();
    let mut html = Html::default();
    for (k, stage) in stages.iter().enumerate() {
        let name = stage.name();
        progress(k, stages.len(), name);
        let t = Instant::now();
        let out = stage
            .run(args)
            .with_context(|| format!("demo stage {name:?}"))?;
        let mut entry = out.summary;
        let mut stage_timings = take_timings(&mut entry).unwrap_or_else(|| json!({}));
        if let Value::Object(m) = &mut stage_timings {
            m.insert("seconds".into(), json!(t.elapsed().as_secs_f64()));
        }
        summary.insert(out.key.into(), entry);
        timings.insert(out.key.into(), stage_timings);
        html.section(out.title, &out.text_html, &out.figures);
        for (name, bytes) in &out.files {
            let path = args.out.join(name);
            geodata::fsio::write_atomic(&path, bytes)
                .with_context(|| format!("writing {}", path.display()))?;
        }
    }
    progress(stages.len(), stages.len(), "done");
    summary.insert("seed".into(), json!(args.seed));
    timings.insert("seconds_total".into(), json!(t0.elapsed().as_secs_f64()));
    let summary_path = args.out.join("summary.json");
    geodata::fsio::write_atomic(
        &summary_path,
        serde_json::to_string_pretty(&Value::Object(summary))? + "\n",
    )
    .with_context(|| format!("writing {}", summary_path.display()))?;
    // Timings change from run to run; they live apart so that every other file is the same
    // bytes for the same seed.
    let timings_path = args.out.join("timings.json");
    geodata::fsio::write_atomic(
        &timings_path,
        serde_json::to_string_pretty(&Value::Object(timings))? + "\n",
    )
    .with_context(|| format!("writing {}", timings_path.display()))?;
    let html_path = args.out.join("index.html");
    geodata::fsio::write_atomic(&html_path, html.finish("urbansem demo"))
        .with_context(|| format!("writing {}", html_path.display()))?;
    Ok(DemoOutcome {
        summary_path,
        timings_path,
        html_path,
        seconds: t0.elapsed().as_secs_f64(),
    })
}

/// Whether a summary key holds a timing (seconds, or a rate per second).
fn is_timing_key(key: &str) -> bool {
    key.contains("second") || key.ends_with("_s") || key.ends_with("_per_s")
}

/// Moves every timing out of `value` into the returned value, keeping the nesting (arrays
/// keep their length, with `null` where an element had none); `None` when there was none.
fn take_timings(value: &mut Value) -> Option<Value> {
    match value {
        Value::Object(m) => {
            let mut taken = Map::new();
            let keys: Vec<String> = m.keys().cloned().collect();
            for key in keys {
                if is_timing_key(&key) {
                    if let Some(v) = m.remove(&key) {
                        taken.insert(key, v);
                    }
                } else if let Some(sub) = m.get_mut(&key).and_then(take_timings) {
                    taken.insert(key, sub);
                }
            }
            (!taken.is_empty()).then_some(Value::Object(taken))
        }
        Value::Array(items) => {
            let taken: Vec<Value> = items
                .iter_mut()
                .map(|v| take_timings(v).unwrap_or(Value::Null))
                .collect();
            taken
                .iter()
                .any(|v| !v.is_null())
                .then_some(Value::Array(taken))
        }
        _ => None,
    }
}
