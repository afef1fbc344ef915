//! `urbansem streets …`: street offset and width per OSM segment from a labelled or raw
//! point cloud (issue 5, thesis ch. 4): evaluation, training, estimation, real-data
//! classifier check on KITTI-360, and the SVM side of the libsvm comparison.

use anyhow::Context;
use clap::{Args, Subcommand, ValueEnum};
use geodata::osm::OsmMap;
use std::path::PathBuf;
use streets::eval::EvalOptions;
use streets::model::{ClassifierOptions, StreetModel, Target};
use streets::svm::SvmOptions;

/// Arguments of `urbansem streets`.
#[derive(Args)]
pub struct StreetsArgs {
    /// What to do.
    #[command(subcommand)]
    pub command: StreetsCommand,
}

/// Which street area a model is for.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum TargetArg {
    /// Driving area only (road and parking).
    DrivingArea,
    /// Driving area and sidewalk.
    WithSidewalk,
}

impl From<TargetArg> for Target {
    fn from(t: TargetArg) -> Target {
        match t {
            TargetArg::DrivingArea => Target::DrivingArea,
            TargetArg::WithSidewalk => Target::WithSidewalk,
        }
    }
}

/// Options shared by the commands that train.
#[derive(Args, Clone)]
pub struct TrainingArgs {
    /// Largest number of training bins per SVM (a seeded subset) [default: 3000; `streets
    /// eval` and `eval-real`: 6000 per fold].
    #[arg(long)]
    pub max_train_bins: Option<usize>,
    /// SVM box constraint C.
    #[arg(long, default_value_t = 4.0)]
    pub svm_c: f64,
    /// Seed of every random step.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
}

impl TrainingArgs {
    /// The classifier options of `streets train` and `transfer`.
    fn classifier(&self) -> ClassifierOptions {
        self.classifier_with(ClassifierOptions::default().max_train_bins)
    }

    /// The classifier options, with `default_bins` training bins unless given.
    fn classifier_with(&self, default_bins: usize) -> ClassifierOptions {
        ClassifierOptions {
            svm: SvmOptions {
                c: self.svm_c,
                ..SvmOptions::default()
            },
            max_train_bins: self.max_train_bins.unwrap_or(default_bins),
            seed: self.seed,
            ..ClassifierOptions::default()
        }
    }
}

/// Options shared by `streets eval` and `streets eval-real`.
#[derive(Args, Clone)]
pub struct EvalArgs {
    /// MCMC chains.
    #[arg(long, default_value_t = 50)]
    chains: usize,
    /// MCMC iterations per chain.
    #[arg(long, default_value_t = 1_000_000)]
    iterations: usize,
    /// Couple neighbouring segments only below this turn angle (180: all pairs of N).
    #[arg(long, default_value_t = 45.0)]
    max_turn_deg: f64,
    /// Couple neighbouring segments also where their width-prior tags (`highway` class,
    /// `width`, `lanes`, `sidewalk`) change, as the thesis does.
    #[arg(long)]
    couple_across_tag_changes: bool,
    /// One width prior for every segment (thesis §4.4.2) instead of one per OSM tag group
    /// (`width`, `lanes`, `highway` class).
    #[arg(long)]
    no_tag_prior: bool,
    /// With sidewalk: the width prior of the segment's tag group instead of one centred on
    /// its estimated driving area plus a sidewalk margin learnt per `highway` class.
    #[arg(long)]
    no_sidewalk_prior: bool,
    /// Training options.
    #[command(flatten)]
    pub training: TrainingArgs,
}

impl EvalArgs {
    fn options(&self) -> EvalOptions {
        let mut options = EvalOptions {
            classifier: self
                .training
                .classifier_with(streets::eval::EVAL_MAX_TRAIN_BINS),
            ..EvalOptions::default()
        };
        options.geometry.max_turn_deg = self.max_turn_deg;
        options.geometry.couple_across_tag_changes = self.couple_across_tag_changes;
        options.tag_prior = !self.no_tag_prior;
        options.sidewalk_prior = !self.no_sidewalk_prior;
        options.mcmc.chains = self.chains;
        options.mcmc.iterations = self.iterations;
        options.mcmc.seed = self.training.seed;
        options
    }
}

/// Subcommands of `urbansem streets`.
#[derive(Subcommand)]
pub enum StreetsCommand {
    /// Table 4.1 analogue on a simulated `streets` dataset (5-fold round robin over segments).
    Eval {
        /// Dataset folder (dataset.json, cloud.ply, segments.json).
        #[arg(long)]
        dataset: PathBuf,
        /// Print one JSON object.
        #[arg(long)]
        json: bool,
        /// Mask only near intersections, as the thesis (not bins nearer to another street).
        #[arg(long)]
        thesis_mask: bool,
        /// Write per-segment length, estimated, true and fitted-on-true-labels geometry (JSON) here.
        #[arg(long)]
        segments_out: Option<PathBuf>,
        /// Evaluation options.
        #[command(flatten)]
        eval: EvalArgs,
        /// A trained model to score instead.
        #[command(flatten)]
        score: ScoreModelArgs,
    },
    /// Table 4.1 analogue on a real labelled sequence (KITTI-360 or MCD layout) and an OSM
    /// map of its streets: scans registered by their poses, each segment's true offset and
    /// width derived from the labelled points, 5-fold round robin over segments.
    EvalReal {
        /// Sequence folder (KITTI-360: velodyne_points/, gt_labels/, velodyne_poses*.txt;
        /// MCD: lidar_bin/, gt_labels/, pose_inW.csv).
        #[arg(long)]
        dataset: PathBuf,
        /// OSM map of the sequence's streets (.osm or .osm.pbf).
        #[arg(long)]
        map: PathBuf,
        /// Print one JSON object (keys as `streets eval`, plus `coverage` and `truth`).
        #[arg(long)]
        json: bool,
        /// Write per-segment derived truth, estimates and support (JSON) here.
        #[arg(long)]
        segments_out: Option<PathBuf>,
        /// Evaluation options.
        #[command(flatten)]
        eval: EvalArgs,
        /// A trained model to score instead.
        #[command(flatten)]
        score: ScoreModelArgs,
    },
    /// Train a model (classifier, confusion matrix, prior) on whole `streets` datasets and
    /// labelled real sequences together.
    Train {
        /// Simulated `streets` dataset folders (comma-separated or repeated).
        #[arg(long, value_delimiter = ',')]
        dataset: Vec<PathBuf>,
        /// A labelled real sequence (KITTI-360 or MCD layout) and the OSM map of its streets,
        /// as DIR=MAP (repeatable): registered by its poses, truth derived from its labels as
        /// `streets eval-real` derives it.
        #[arg(long)]
        sequence: Vec<String>,
        /// Standardise the features per corridor (median / IQR), so the model transfers to
        /// other sensors' intensity scales and densities.
        #[arg(long)]
        normalise: bool,
        /// Leave out the colour histograms (for clouds without RGB).
        #[arg(long)]
        no_colour: bool,
        /// Street area to model.
        #[arg(long, value_enum, default_value = "driving-area")]
        target: TargetArg,
        /// Output model (JSON).
        #[arg(long)]
        out: PathBuf,
        /// Training options.
        #[command(flatten)]
        training: TrainingArgs,
    },
    /// Estimate offset and width per segment and write a WGS84 GeoJSON.
    Estimate {
        /// OSM map (.osm or .osm.pbf).
        #[arg(long)]
        map: PathBuf,
        /// Registered point cloud (in the frame --cloud-frame names).
        #[arg(long)]
        cloud: PathBuf,
        /// The bag message to read when --cloud is a ROS 2 bag (.mcap).
        #[command(flatten)]
        bag: super::BagPickArgs,
        /// The cloud's frame: local (the map's local frame), utm:ZONE[N|S] (e.g. utm:32N),
        /// or enu:LAT,LON (east/north/up metres about a WGS84 anchor); converted exactly.
        #[arg(long, default_value = "local")]
        cloud_frame: geodata::georef::CloudFrame,
        /// Model from `urbansem streets train` (default: the shipped model of --target,
        /// trained on simulated scans of the embedded city and of OSM Helsinki; see the
        /// streets README).
        #[arg(long)]
        model: Option<PathBuf>,
        /// Street area to estimate with the shipped models (with --model: must be the
        /// model's) [default: driving-area, or the --model's].
        #[arg(long, value_enum)]
        target: Option<TargetArg>,
        /// With a with-sidewalk --model: the driving-area model whose estimates on the same
        /// cloud centre each segment's with-sidewalk prior, plus its class' sidewalk margins
        /// learnt in training (default: the shipped model).
        #[arg(long)]
        driving_model: Option<PathBuf>,
        /// Output GeoJSON.
        #[arg(long)]
        out: PathBuf,
    },
    /// Bin classifier on real KITTI-360 scans: train on some scans, test on the others.
    Kitti {
        /// KITTI-360 sequence folder.
        #[arg(
            long,
            default_value = "../shared/data/lidar/kitti360_2013_05_28_drive_0009"
        )]
        data: PathBuf,
        /// Scans used for training (the first ones; the rest are tested).
        #[arg(long, default_value_t = 12)]
        train_scans: usize,
        /// Test scans (0: all the rest).
        #[arg(long, default_value_t = 0)]
        test_scans: usize,
        /// Also train on this simulated `streets` dataset and test on the KITTI test scans.
        #[arg(long)]
        sim_dataset: Option<PathBuf>,
        /// Print one JSON object.
        #[arg(long)]
        json: bool,
        /// Training options.
        #[command(flatten)]
        training: TrainingArgs,
    },
    /// Bin classifier across datasets: train on the labelled scans of some sequences
    /// (simulated car LiDAR from `sim dataset --kind localization --sensor hdl64`, MCD,
    /// KITTI-360, …), test on another sequence's scans.
    Transfer {
        /// Training sequences (comma-separated folders of any labelled layout).
        #[arg(long, value_delimiter = ',', required = true)]
        train: Vec<PathBuf>,
        /// Test sequence folder.
        #[arg(long)]
        test: PathBuf,
        /// Scans per training sequence, evenly spaced (0: all).
        #[arg(long, default_value_t = 40)]
        scans_per_source: usize,
        /// Scans of the test sequence, evenly spaced (0: all).
        #[arg(long, default_value_t = 0)]
        test_scans: usize,
        /// Raw features instead of features standardised per scan.
        #[arg(long)]
        raw_features: bool,
        /// Print one JSON object.
        #[arg(long)]
        json: bool,
        /// Training options.
        #[command(flatten)]
        training: TrainingArgs,
    },
    /// Train our SVM on bins of a dataset and write the same bins in libsvm format
    /// (used by scripts/bench_streets_svm.py for the side-by-side comparison).
    BenchSvm {
        /// Dataset folder.
        #[arg(long)]
        dataset: PathBuf,
        /// Training bins.
        #[arg(long, default_value_t = 20_000)]
        train: usize,
        /// Test bins.
        #[arg(long, default_value_t = 20_000)]
        test: usize,
        /// Write `train.svm` and `test.svm` (scaled features) into this folder.
        #[arg(long)]
        export: Option<PathBuf>,
        /// SVM box constraint C.
        #[arg(long, default_value_t = 4.0)]
        svm_c: f64,
        /// Kernel cache, MiB.
        #[arg(long, default_value_t = 100)]
        cache_mb: usize,
        /// Seed.
        #[arg(long, default_value_t = 1)]
        seed: u64,
        /// Print one JSON object.
        #[arg(long)]
        json: bool,
    },
}

/// Runs `urbansem streets`.
pub fn run(args: StreetsArgs) -> anyhow::Result<()> {
    match args.command {
        StreetsCommand::Eval {
            dataset,
            json,
            thesis_mask,
            segments_out,
            eval,
            score,
        } => {
            if let Some(scored) = score.load(segments_out.as_deref(), "streets eval")? {
                let r = streets::jobs::eval_dataset_model(
                    &dataset,
                    &scored.model,
                    scored.driving.as_ref(),
                    score.self_calibrate,
                )?;
                return print_model_report(&r, json, &scored.path, &dataset.display().to_string());
            }
            let mut options = eval.options();
            options.geometry.corridor.mask_nearer_segments = !thesis_mask;
            let report = streets::jobs::eval_dataset(&dataset, &options, segments_out.as_deref())?;
            if json {
                println!("{}", serde_json::to_string_pretty(&report)?);
                eprintln!("{}", report.details_text());
            } else {
                println!("{}", report.table_text());
                println!("{}", report.details_text());
            }
            Ok(())
        }
        StreetsCommand::EvalReal {
            dataset,
            map,
            json,
            segments_out,
            eval,
            score,
        } => {
            let progress = |done: usize, total: usize| {
                if done == total || done % 10 == 0 {
                    eprintln!("streets eval-real: {done}/{total} scans registered");
                }
            };
            if let Some(scored) = score.load(segments_out.as_deref(), "streets eval-real")? {
                let r = streets::jobs::eval_real_model(
                    &dataset,
                    &map,
                    &scored.model,
                    scored.driving.as_ref(),
                    score.self_calibrate,
                    &progress,
                )?;
                let what = format!("{} with {}", dataset.display(), map.display());
                return print_model_report(&r, json, &scored.path, &what);
            }
            let r = streets::jobs::eval_real(
                &dataset,
                &map,
                &eval.options(),
                segments_out.as_deref(),
                &progress,
            )?;
            if json {
                super::print_json(&r)?;
                eprintln!("{}", r.report.details_text());
            } else {
                print!("{}", r.text(&dataset, &map));
            }
            Ok(())
        }
        StreetsCommand::Train {
            dataset,
            sequence,
            normalise,
            no_colour,
            target,
            out,
            training,
        } => {
            if dataset.is_empty() && sequence.is_empty() {
                super::usage!("streets train needs at least one --dataset or --sequence DIR=MAP");
            }
            let mut geometry = streets::model::GeometryOptions::default();
            geometry.features.normalise = normalise;
            geometry.features.colour = !no_colour;
            let mut sources = Vec::new();
            for d in &dataset {
                sources.push(streets::jobs::load_dataset(d)?);
            }
            for pair in &sequence {
                let Some((dir, map)) = pair.rsplit_once('=') else {
                    super::usage!("--sequence {pair:?}: expected DIR=MAP");
                };
                let real = streets::real::load_sequence(
                    std::path::Path::new(dir),
                    std::path::Path::new(map),
                    &geometry.corridor,
                    &streets::real::TruthOptions::default(),
                    &|done, total| {
                        if done == total || done % 10 == 0 {
                            eprintln!("streets train: {dir}: {done}/{total} scans registered");
                        }
                    },
                )
                .with_context(|| format!("reading the sequence {dir} with the map {map}"))?;
                sources.push(real.dataset);
            }
            let refs: Vec<&streets::dataset::StreetsDataset> = sources.iter().collect();
            let model = if dataset.len() == 1 && sequence.is_empty() && !normalise && !no_colour {
                // One simulated dataset with the defaults: the model of issue 5, unchanged.
                StreetModel::train(&sources[0], target.into(), &training.classifier())?
            } else {
                StreetModel::train_sources(&refs, target.into(), geometry, &training.classifier())?
            };
            geodata::fsio::write_atomic(&out, serde_json::to_vec(&model)?)
                .with_context(|| format!("writing {}", out.display()))?;
            println!(
                "{}: {} support vectors, held-out confusion {:?}",
                out.display(),
                model.classifier.svm.support_count(),
                model.classifier.confusion.counts
            );
            Ok(())
        }
        StreetsCommand::Estimate {
            map,
            cloud,
            bag,
            cloud_frame,
            model,
            target,
            driving_model,
            out,
        } => {
            let model_name = model.as_ref().map(|p| p.display().to_string());
            let model = match model {
                Some(path) => {
                    let m = read_model(&path)?;
                    if let Some(t) = target.map(Target::from).filter(|&t| t != m.target) {
                        super::usage!(
                            "--target {} but the model {} is a {} model",
                            t.key().replace('_', "-"),
                            path.display(),
                            m.target.key().replace('_', "-")
                        );
                    }
                    m
                }
                None => {
                    eprintln!(
                        "streets estimate: no --model, using the shipped default model (trained on simulated scans; its accuracy on real scans is in crates/streets/README.md)"
                    );
                    StreetModel::shipped(target.map_or(Target::DrivingArea, Target::from))?
                }
            };
            // A with-sidewalk model with sidewalk margins centres its prior on the driving
            // area of the same cloud: the driving-area model is checked before any data is read.
            let driving = driving_model_for(
                &model,
                model_name
                    .as_deref()
                    .unwrap_or(if model.target == Target::WithSidewalk {
                        streets::model::WITH_SIDEWALK_MODEL_NAME
                    } else {
                        streets::model::DEFAULT_MODEL_NAME
                    }),
                driving_model.as_deref(),
                "streets estimate",
            )?;
            let osm = OsmMap::load(&map).with_context(|| format!("loading {}", map.display()))?;
            let (mut pc, _, _) = bag.read(&cloud)?;
            cloud_frame
                .into_map_frame(&mut pc, &osm.frame)
                .with_context(|| format!("moving {} into the map's frame", cloud.display()))?;
            let (map_name, cloud_name) = (map.display().to_string(), cloud.display().to_string());
            let est = model.estimate_with_driving(
                driving.as_ref(),
                &osm,
                &pc,
                (&map_name, &cloud_name),
                0,
            )?;
            let fc = streets::geojson::feature_collection(&osm, &est.segments, model.target);
            streets::geojson::validate(&fc).map_err(|e| anyhow::anyhow!("internal: {e}"))?;
            geodata::fsio::write_atomic(&out, serde_json::to_vec_pretty(&fc)?)
                .with_context(|| format!("writing {}", out.display()))?;
            println!(
                "{}: {} segments estimated ({} exact inference), {} shorter than a bin, {} without observed bins",
                out.display(),
                est.segments.len(),
                if est.exact { "tree," } else { "loopy," },
                est.too_short,
                est.unobserved
            );
            Ok(())
        }
        StreetsCommand::Kitti {
            data,
            train_scans,
            test_scans,
            sim_dataset,
            json,
            training,
        } => {
            let report = streets::jobs::kitti_eval(
                &data,
                train_scans,
                test_scans,
                sim_dataset.as_deref(),
                &training.classifier(),
            )?;
            if json {
                super::print_json(&report)?;
            } else {
                print!("{}", report.text(&data));
            }
            Ok(())
        }
        StreetsCommand::Transfer {
            train,
            test,
            scans_per_source,
            test_scans,
            raw_features,
            json,
            training,
        } => {
            let open = |dir: &PathBuf| -> anyhow::Result<streets::transfer::NamedSequence> {
                eprintln!("streets transfer: opening {}", dir.display());
                let seq = geosim::sequence::open_sequence(dir)
                    .with_context(|| format!("opening {}", dir.display()))?;
                Ok((dir.display().to_string(), seq))
            };
            let sources = train.iter().map(open).collect::<anyhow::Result<Vec<_>>>()?;
            let test = open(&test)?;
            let report = streets::transfer::transfer(
                &sources,
                &test,
                &streets::transfer::TransferOptions {
                    scans_per_source,
                    test_scans,
                    normalise: !raw_features,
                    classifier: training.classifier(),
                },
            )?;
            if json {
                super::print_json(&report)?;
            } else {
                print!("{}", report.text());
            }
            Ok(())
        }
        StreetsCommand::BenchSvm {
            dataset,
            train,
            test,
            export,
            svm_c,
            cache_mb,
            seed,
            json,
        } => urbansem_bench::streets_svm::bench_svm(
            &dataset,
            train,
            test,
            export.as_deref(),
            svm_c,
            cache_mb,
            seed,
            json,
        ),
    }
}

/// The model of `streets eval --model` / `eval-real --model`, read and checked; a usage error
/// with `--segments-out`, which belongs to the 5-fold evaluation.
/// The driving-area model that centres a with-sidewalk model's priors (`None`: the model
/// has no sidewalk margins): `path`, else the shipped default (said on stderr by `command`).
/// A driving model of the wrong kind, or one given to a model without margins, is a usage
/// error naming the files.
fn driving_model_for(
    model: &StreetModel,
    model_name: &str,
    path: Option<&std::path::Path>,
    command: &str,
) -> anyhow::Result<Option<StreetModel>> {
    let driving = match path {
        Some(p) => {
            // A model that wants none is refused before the file is read.
            let mismatch = |target| model.driving_model_mismatch(target);
            if let Some(message) = mismatch(Target::DrivingArea) {
                super::usage!(
                    "{model_name} with --driving-model {}: {message}",
                    p.display()
                );
            }
            let driving = read_model(p)?;
            if let Some(message) = mismatch(driving.target) {
                super::usage!(
                    "{model_name} with --driving-model {}: {message}",
                    p.display()
                );
            }
            driving
        }
        None if model.wants_driving_area() => {
            eprintln!(
                "{command}: no --driving-model, estimating the driving area that centres the with-sidewalk prior with the shipped default model"
            );
            StreetModel::shipped_default()?
        }
        None => return Ok(None),
    };
    Ok(Some(driving))
}

/// `streets eval` and `eval-real`: score a trained model instead of the 5-fold evaluation.
#[derive(Args)]
pub struct ScoreModelArgs {
    /// Score this trained model (`streets train`) instead of the 5-fold evaluation: its
    /// estimate of every observed drivable segment against the truth (the simulator's, or
    /// the one derived from a real sequence's labels).
    #[arg(long)]
    model: Option<PathBuf>,
    /// With --model: re-estimate the classifier's confusion matrix on the data's own cloud,
    /// at most this many rounds (0: the model's calibration matrix as it is).
    #[arg(long, default_value_t = 0)]
    self_calibrate: usize,
    /// With a with-sidewalk --model: the driving-area model whose estimates centre the
    /// with-sidewalk priors, as in `streets estimate` (default: the shipped model).
    #[arg(long)]
    driving_model: Option<PathBuf>,
}

/// A model to score, read and checked, with the driving-area model its priors need.
struct ScoredModel {
    path: PathBuf,
    model: StreetModel,
    driving: Option<StreetModel>,
}

impl ScoreModelArgs {
    /// The model to score (`None`: run the 5-fold evaluation, which refuses the options
    /// that only a model takes).
    fn load(
        &self,
        segments_out: Option<&std::path::Path>,
        command: &str,
    ) -> anyhow::Result<Option<ScoredModel>> {
        let Some(path) = &self.model else {
            if self.self_calibrate > 0 {
                super::usage!("--self-calibrate needs --model (the 5-fold evaluation calibrates on the other folds)");
            }
            if self.driving_model.is_some() {
                super::usage!("--driving-model needs --model (the 5-fold evaluation estimates the driving area itself)");
            }
            return Ok(None);
        };
        if segments_out.is_some() {
            super::usage!(
                "--segments-out is for the 5-fold evaluation; --model lists every segment in its JSON"
            );
        }
        let model = read_model(path)?;
        let driving = driving_model_for(
            &model,
            &path.display().to_string(),
            self.driving_model.as_deref(),
            command,
        )?;
        Ok(Some(ScoredModel {
            path: path.clone(),
            model,
            driving,
        }))
    }
}

/// A model file from `urbansem streets train`, checked as it is read: dimensions, finite
/// values, bin sizes (issue 16).
fn read_model(path: &std::path::Path) -> anyhow::Result<StreetModel> {
    let bytes =
        std::fs::read(path).with_context(|| format!("reading the model {}", path.display()))?;
    Ok(StreetModel::from_json(&bytes, path)?)
}

/// Prints the report of `streets eval --model` / `eval-real --model` (`what`: the data).
fn print_model_report(
    r: &streets::jobs::ModelRealReport,
    json: bool,
    model: &std::path::Path,
    what: &str,
) -> anyhow::Result<()> {
    if json {
        return super::print_json(r);
    }
    let m = |v: Option<f64>| v.map_or("n/a".to_owned(), |v| format!("{v:.2} m"));
    println!(
        "{} on {what} (the model as trained, not retrained on the data): {} segments, {} with a truth, {} covered; raw bins P/R/F1 {:.3}/{:.3}/{:.3}, both classes weighted by their bins {:.3}/{:.3}/{:.3} ({} bins); RMSE_w {}, RMSE_d {}",
        model.display(),
        r.passed,
        r.with_truth,
        r.covered,
        r.raw.precision,
        r.raw.recall,
        r.raw.f1,
        r.raw_weighted.precision,
        r.raw_weighted.recall,
        r.raw_weighted.f1,
        r.raw_bins,
        m(r.rmse_w),
        m(r.rmse_d)
    );
    if r.driving_area_prior {
        println!("with-sidewalk priors centred on the driving area estimated first, plus the model's sidewalk margins");
    }
    print!("{}", streets::eval::edges_text(&r.edges));
    Ok(())
}
