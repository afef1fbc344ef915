//! `urbansem map …` and `urbansem relations …`: the semantic R-tree map and spatial relations.

use anyhow::Context;
use clap::Subcommand;
use geodata::classes::Class;
use srtree::amodal::MapOutlines;
use srtree::graph::Viewpoint;
use srtree::io::{read_map, write_map};
use srtree::map::{MapOptions, SrMap};
use srtree::objects::ObjectOptions;
use srtree::report::{BuildReport, QueryReport};
use srtree::semantic::SemanticMap;
use srtree::SrtreeError;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// Subcommands of `urbansem map`.
#[derive(Subcommand)]
pub enum MapCommand {
    /// Insert a labelled cloud into a new SRTree map and save it (.srt).
    Build {
        /// The cloud (.ply, .pcd, .las, .laz, .bin) in the map frame, or a ROS 2 bag (.mcap):
        /// one message of --topic, or with --poses every scan placed by its pose.
        #[arg(long)]
        cloud: PathBuf,
        /// The bag message to read (with --poses: the topic of the scans).
        #[command(flatten)]
        bag: super::BagPickArgs,
        /// The bag's Odometry, PoseStamped or TF topic placing each scan (sensor pose in the map
        /// frame): builds the map from every scan of --topic.
        #[arg(long, value_name = "TOPIC", requires = "topic")]
        poses: Option<String>,
        /// With a TF topic in --poses: the child frame whose transform places the scans.
        #[arg(long, requires = "poses")]
        child_frame: Option<String>,
        /// With --poses: use every n-th scan.
        #[arg(long, default_value_t = 1, requires = "poses")]
        every: usize,
        /// With --poses: skip a scan more than this many seconds from both poses around it.
        #[arg(long, default_value_t = 0.5, requires = "poses")]
        max_gap: f64,
        /// Sensor origin `x,y,z` (for free-space ray casting).
        #[arg(long)]
        origin: Option<String>,
        /// The map file to write.
        #[arg(long)]
        out: PathBuf,
        /// Cell size, metres.
        #[arg(long, default_value_t = 0.1)]
        resolution: f64,
        /// Cast rays from --origin (or each scan's pose, with --poses) to every point
        /// (OctoMap-like free-space updates).
        #[arg(long)]
        ray_casting: bool,
        /// A Dirichlet label model (JSON, as written by `urbansem map dirichlet`) for the cell labels.
        #[arg(long)]
        dirichlet: Option<PathBuf>,
        /// Print one JSON object.
        #[arg(long)]
        json: bool,
    },
    /// Query a map: cells in a box, near a point, of a class or of an object.
    Query {
        /// The map file.
        map: PathBuf,
        /// Box `xmin,ymin,zmin,xmax,ymax,zmax` (metres).
        #[arg(long = "box", value_name = "BOX")]
        box_: Option<String>,
        /// Point `x,y,z`: the --k nearest cells (or all within --radius).
        #[arg(long)]
        near: Option<String>,
        /// Number of nearest cells.
        #[arg(long, default_value_t = 10)]
        k: usize,
        /// With --near: every cell within this radius instead of the k nearest.
        #[arg(long)]
        radius: Option<f64>,
        /// Class name (car, building, street, sidewalk, …).
        #[arg(long)]
        class: Option<String>,
        /// Object id.
        #[arg(long)]
        object: Option<u32>,
        /// Print one JSON object.
        #[arg(long)]
        json: bool,
    },
    /// Export a map for other tools: one point per occupied cell with its class colour,
    /// class id (`label`) and object id (`object`); the format by OUT's extension: `.ply`,
    /// or `.mcap` (ROS 2 bag: PointCloud2 on /semantic_map/cells, Foxglove SceneUpdate with
    /// object boxes and relation lines on /semantic_map/objects).
    Export {
        /// The map file (.srt).
        map: PathBuf,
        /// The file to write (.ply or .mcap).
        out: PathBuf,
    },
    /// Dirichlet label choice vs majority vote on the real labelled scans (KITTI-360, MCD).
    EvalLabels {
        /// The folder holding `kitti360_2013_05_28_drive_0009/` and `mcd_kth_day_06/`.
        #[arg(long, default_value = "../shared/data/lidar")]
        data: PathBuf,
        /// Cell size, metres.
        #[arg(long, default_value_t = 0.1)]
        resolution: f64,
        /// Use at most this many scans per sequence (evenly spread).
        #[arg(long)]
        max_scans: Option<usize>,
        /// Write the fitted Dirichlet model (JSON, for `map build --dirichlet`).
        #[arg(long)]
        model_out: Option<PathBuf>,
        /// Print one JSON object.
        #[arg(long)]
        json: bool,
    },
}

/// Subcommands of `urbansem relations`.
#[derive(Subcommand)]
pub enum RelationsCommand {
    /// Train the relation classifiers and MLN weights on a relations dataset's train scenes.
    Train {
        /// The dataset folder (`urbansem sim dataset --kind relations`).
        #[arg(long)]
        dataset: PathBuf,
        /// The model file to write (JSON).
        #[arg(long)]
        out: PathBuf,
        /// Seed of every random step.
        #[arg(long, default_value_t = 1)]
        seed: u64,
    },
    /// Infer the relations between a map's objects from a viewpoint.
    Infer {
        /// The map file.
        #[arg(long)]
        map: PathBuf,
        /// The model file.
        #[arg(long)]
        model: PathBuf,
        /// Viewpoint `x,y,yaw` (metres, radians counter-clockwise from x).
        #[arg(long, allow_hyphen_values = true)]
        viewpoint: String,
        /// Print the relation graph as JSON.
        #[arg(long)]
        json: bool,
        /// Print the relation graph as Graphviz DOT.
        #[arg(long, conflicts_with = "json")]
        dot: bool,
        /// Also write the map with its relation graph to this file.
        #[arg(long)]
        save: Option<PathBuf>,
        /// OSM map (.osm, .osm.pbf) whose building outlines complete the map's buildings
        /// (how deep a building is, which the scan never sees).
        #[arg(long)]
        osm: Option<PathBuf>,
        /// Frame of the map's coordinates (the cloud it was built from): local (the OSM
        /// map's local frame), utm:ZONE[N|S] or enu:LAT,LON; used with --osm.
        #[arg(long, default_value = "local", requires = "osm")]
        cloud_frame: geodata::georef::CloudFrame,
        /// Seed of the MAP search.
        #[arg(long, default_value_t = 1)]
        seed: u64,
    },
    /// Train on the train scenes, score SVM and SVM+MLN on the test scenes (Table 3.6).
    Eval {
        /// The dataset folder.
        #[arg(long)]
        dataset: PathBuf,
        /// Use this model instead of training one.
        #[arg(long)]
        model: Option<PathBuf>,
        /// Train on these datasets' train scenes instead (other cities; comma-separated for
        /// several) and test on every scene of --dataset (none of them was seen in training).
        #[arg(long, value_delimiter = ',', conflicts_with = "model")]
        train_dataset: Vec<PathBuf>,
        /// Write every test pair and relation that SVM or SVM + MLN got wrong to this file
        /// (JSON lines: scene, relation, ids, classes, truth, svm, mln).
        #[arg(long)]
        errors: Option<PathBuf>,
        /// Print one JSON object.
        #[arg(long)]
        json: bool,
        /// Seed of every random step.
        #[arg(long, default_value_t = 1)]
        seed: u64,
    },
}

fn parse_floats<const N: usize>(s: &str, what: &str) -> anyhow::Result<[f64; N]> {
    let v: Vec<f64> = s
        .split(',')
        .map(|t| t.trim().parse::<f64>())
        .collect::<Result<_, _>>()
        .with_context(|| format!("{what} {s:?}: expected {N} comma-separated numbers"))?;
    if v.len() != N || v.iter().any(|x| !x.is_finite()) {
        super::usage!("{what} {s:?}: expected {N} comma-separated finite numbers");
    }
    let mut out = [0.0; N];
    out.copy_from_slice(&v);
    Ok(out)
}

/// `urbansem map export MAP OUT`: the format by OUT's extension.
fn export(map: &Path, out: &Path) -> anyhow::Result<()> {
    let ext = out
        .extension()
        .and_then(|e| e.to_str())
        .unwrap_or("")
        .to_ascii_lowercase();
    if ext != "ply" && ext != "mcap" {
        super::usage!(
            "{}: expected a .ply or .mcap file to export to",
            out.display()
        );
    }
    let m = read_map(map).with_context(|| format!("reading {}", map.display()))?;
    let n = if ext == "ply" {
        srtree::export::write_ply(out, &m)
    } else {
        srtree::export::write_mcap(out, &m)
    }
    .with_context(|| format!("writing {}", out.display()))?;
    println!(
        "{}: {n} occupied cells (class colour, label, object), {} objects, {} related pairs",
        out.display(),
        m.relations.objects.len(),
        m.relations.edges.len()
    );
    Ok(())
}

/// Runs one `urbansem map` subcommand.
pub fn run_map(command: MapCommand) -> anyhow::Result<()> {
    match command {
        MapCommand::Build {
            cloud,
            bag,
            poses,
            child_frame,
            every,
            max_gap,
            origin,
            out,
            resolution,
            ray_casting,
            dirichlet,
            json,
        } => {
            let origin = origin
                .map(|s| parse_floats::<3>(&s, "--origin"))
                .transpose()?;
            if poses.is_some() && (bag.index.is_some() || bag.time.is_some()) {
                super::usage!(
                    "--index and --time pick one message; --poses reads every scan of --topic"
                );
            }
            if ray_casting && origin.is_none() && poses.is_none() {
                super::usage!("--ray-casting casts rays from the sensor: give --origin (or --poses for a bag)");
            }
            if poses.is_some() && origin.is_some() {
                super::usage!("--origin and --poses: with --poses each scan's origin is its pose");
            }
            let options = MapOptions {
                resolution_m: resolution,
                ray_casting,
                ..MapOptions::default()
            };
            let dirichlet = dirichlet
                .map(|p| -> anyhow::Result<_> {
                    let text = std::fs::read_to_string(&p)
                        .with_context(|| format!("reading {}", p.display()))?;
                    serde_json::from_str(&text)
                        .with_context(|| format!("{}: not a Dirichlet model", p.display()))
                })
                .transpose()?;
            let (map, stats, read_s, insert_s, bag) = if let Some(pose_topic) = poses {
                let job = srtree::jobs::BagBuildJob {
                    bag: cloud.clone(),
                    cloud_topic: bag.topic.clone().unwrap_or_default(),
                    pose_topic,
                    child_frame,
                    every,
                    max_gap_s: max_gap,
                    batch: 16,
                    options: options.clone(),
                };
                let (mut map, b) = srtree::jobs::build_from_bag(&job)
                    .with_context(|| format!("building a map from {}", cloud.display()))?;
                // The Dirichlet model picks labels from the histograms when they are read.
                map.set_dirichlet(dirichlet);
                (map, b.stats, b.seconds_read, b.seconds_insert, Some(b))
            } else {
                let (c, _, read_s) = bag.read(&cloud)?;
                let mut map = SrMap::new(options)?;
                map.set_dirichlet(dirichlet);
                let t = Instant::now();
                let stats = map
                    .insert_cloud(&c, origin)
                    .with_context(|| format!("inserting {}", cloud.display()))?;
                (map, stats, read_s, t.elapsed().as_secs_f64(), None)
            };
            let semantic = SemanticMap::with_objects(map, &ObjectOptions::default());
            write_map(&out, &semantic).with_context(|| format!("writing {}", out.display()))?;
            let mut report = BuildReport::new(&semantic, &stats, read_s, insert_s, &out);
            report.bag = bag;
            if json {
                super::print_json(&report)?;
            } else {
                print!("{}", report.text());
            }
            Ok(())
        }
        MapCommand::Export { map, out } => export(&map, &out),
        MapCommand::Query {
            map,
            box_,
            near,
            k,
            radius,
            class,
            object,
            json,
        } => {
            let m = read_map(&map)
                .with_context(|| format!("reading {}", map.display()))?
                .cells;
            let t = Instant::now();
            let cells: Vec<u32> = match (box_, near, class, object) {
                (Some(b), None, None, None) => {
                    let v = parse_floats::<6>(&b, "--box")?;
                    let mut c = m.cells_in_box([v[0], v[1], v[2]], [v[3], v[4], v[5]]);
                    c.sort_unstable();
                    c
                }
                (None, Some(p), None, None) => {
                    let p = parse_floats::<3>(&p, "--near")?;
                    match radius {
                        Some(r) => {
                            let mut c = m.cells_within_radius(p, r);
                            c.sort_unstable();
                            c
                        }
                        None => m.nearest_cells(p, k),
                    }
                }
                (None, None, Some(c), None) => {
                    let class = Class::from_name(&c.to_lowercase()).with_context(|| {
                        format!("unknown class {c:?}: expected one of car, building, street, sidewalk, bicycle, other, tree, pole, grass, unlabelled")
                    })?;
                    m.cells_of_class(class)
                }
                (None, None, None, Some(o)) => m.cells_of_object(o),
                _ => super::usage!("give exactly one of --box, --near, --class, --object"),
            };
            let report = QueryReport::new(&m, &cells, t.elapsed().as_secs_f64());
            if json {
                super::print_json(&report)?;
            } else {
                print!("{}", report.text());
            }
            Ok(())
        }
        MapCommand::EvalLabels {
            data,
            resolution,
            max_scans,
            model_out,
            json,
        } => eval_labels(&data, resolution, max_scans, model_out.as_deref(), json),
    }
}

/// `urbansem map eval-labels`: runs [`srtree::label_eval`] and prints both agreements.
fn eval_labels(
    data: &Path,
    resolution: f64,
    max_scans: Option<usize>,
    model_out: Option<&Path>,
    json: bool,
) -> anyhow::Result<()> {
    use srtree::label_eval::{evaluate_labels, LabelEvalOptions, LabelEvalReport};
    let t = Instant::now();
    let sequences = srtree::scans::load_sequences(data, max_scans)
        .with_context(|| format!("reading the labelled scans under {}", data.display()))?;
    let load_s = t.elapsed().as_secs_f64();
    let t = Instant::now();
    let options = LabelEvalOptions {
        resolution_m: resolution,
        ..LabelEvalOptions::default()
    };
    let ev = evaluate_labels(&sequences, &options)?;
    let eval_s = t.elapsed().as_secs_f64();
    if let Some(p) = model_out {
        geodata::fsio::write_atomic(p, serde_json::to_string_pretty(&ev.model)?)
            .with_context(|| format!("writing {}", p.display()))?;
    }
    let report = LabelEvalReport::new(&sequences, &ev, &options, load_s, eval_s);
    if json {
        super::print_json(&report)?;
    } else {
        print!("{}", report.table_text());
    }
    Ok(())
}

/// Runs one `urbansem relations` subcommand.
pub fn run_relations(command: RelationsCommand) -> anyhow::Result<()> {
    match command {
        RelationsCommand::Train { dataset, out, seed } => {
            let run = srtree::jobs::train_model(&dataset, &out, seed)?;
            println!(
                "{}: trained on {} scenes ({:.1} s loading, {:.1} s training); MLN weights {:?}",
                out.display(),
                run.scenes,
                run.load_s,
                run.train_s,
                run.model.mln
            );
            Ok(())
        }
        RelationsCommand::Infer {
            map,
            model,
            viewpoint,
            json,
            dot,
            save,
            osm,
            cloud_frame,
            seed,
        } => {
            let v = parse_floats::<3>(&viewpoint, "--viewpoint")?;
            let outlines = match &osm {
                None => MapOutlines::default(),
                Some(path) => {
                    let osm = geodata::osm::OsmMap::load(path)
                        .with_context(|| format!("loading {}", path.display()))?;
                    MapOutlines::from_osm(&osm, &cloud_frame).with_context(|| {
                        format!("moving {}'s outlines into the map's frame", path.display())
                    })?
                }
            };
            let mut m = read_map(&map).with_context(|| format!("reading {}", map.display()))?;
            let model = srtree::jobs::read_model(&model)?;
            let vp = Viewpoint {
                position: [v[0], v[1], 1.8],
                yaw_rad: v[2],
            };
            let mut infer = mln::infer::InferOptions::default();
            infer.walksat.seed = seed;
            let graph = model
                .infer_map_graph(&m.cells, vp, &outlines, &infer)
                .context("inferring relations")?;
            if json {
                println!("{}", serde_json::to_string_pretty(&graph)?);
            } else if dot {
                print!("{}", graph.to_dot());
            } else {
                print!("{}", graph.text());
            }
            if let Some(path) = save {
                m.relations = graph;
                write_map(&path, &m).with_context(|| format!("writing {}", path.display()))?;
            }
            Ok(())
        }
        RelationsCommand::Eval {
            dataset,
            model,
            train_dataset,
            errors,
            json,
            seed,
        } => {
            let job = srtree::jobs::EvalJob {
                dataset,
                model,
                train_datasets: train_dataset,
                errors_out: errors,
                seed,
            };
            let run = match srtree::jobs::eval_relations(&job) {
                Err(SrtreeError::TestAmongTraining { path }) => crate::cmd::usage!(
                    "--train-dataset {} is the test dataset: its scenes would be tested after training on them; leave --train-dataset out to use its own train/test split",
                    path.display()
                ),
                r => r?,
            };
            if json {
                super::print_json(&run.evaluation.report())?;
            } else {
                print!("{}", run.text(&job));
            }
            Ok(())
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bad_coordinates_are_errors() {
        assert!(parse_floats::<3>("1,2", "--near").is_err());
        assert!(parse_floats::<3>("1,x,3", "--near").is_err());
        assert_eq!(
            parse_floats::<3>("1,-2,3.5", "--near").unwrap(),
            [1.0, -2.0, 3.5]
        );
    }
}
