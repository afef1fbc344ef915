//! Demo stage of srtree: a semantic map and its spatial relations.

use crate::{DemoArgs, StageOutput};
use anyhow::Context;
use serde::Serialize;
use srtree::dataset::RelationsDataset;
use srtree::features::ViewObject;
use srtree::graph::Relation;
use srtree::io::write_map;
use srtree::map::{MapOptions, SrMap};
use srtree::objects::{extract_objects, ObjectOptions};
use srtree::relations::{evaluate, relation_graph, train, EvalReport, TrainOptions};

/// Scenes used for training and testing.
#[derive(Debug, Clone, Serialize)]
pub struct SceneCounts {
    /// Training scenes.
    pub train: usize,
    /// Test scenes.
    pub test: usize,
}

/// Relation edges of the drawn scene, per relation.
#[derive(Debug, Clone, Serialize)]
#[serde(rename_all = "PascalCase")]
pub struct EdgeCounts {
    /// On edges.
    pub on: usize,
    /// LeftOf edges.
    pub left_of: usize,
    /// Behind edges.
    pub behind: usize,
}

/// The srtree stage's summary entry (`srtree` in `summary.json`).
#[derive(Debug, Clone, Serialize)]
pub struct SrtreeSummary {
    /// Scenes of the dataset.
    pub scenes: SceneCounts,
    /// Seconds simulating the dataset.
    pub sim_seconds: f64,
    /// The Table 3.6 analogue.
    pub evaluation: EvalReport,
    /// The test scene drawn.
    pub scene: usize,
    /// Cells of its map.
    pub cells: usize,
    /// Bytes per cell of its map.
    pub bytes_per_cell: f64,
    /// Objects near the viewpoint.
    pub objects: usize,
    /// Relation edges of its graph.
    pub edges: EdgeCounts,
}
use srtree::semantic::SemanticMap;
use std::time::Instant;

/// The demo stage: a small simulated relations dataset, a model trained on it, and one test
/// scene's labelled map (top view) with its relation graph.
pub fn stage(args: &DemoArgs) -> anyhow::Result<StageOutput> {
    use crate::report::{encode_png_rgb, escape, Html};
    use geodata::svg::Svg;
    use geodata::topview::TopView;
    use geosim::dataset::{write_relations, RelationsOptions};
    use geosim::sensor::SensorOptions;

    let map = geosim::city::default_city_map().context("generating the embedded default city")?;
    let dir = args.out.join("relations-dataset");
    std::fs::create_dir_all(&dir).with_context(|| format!("creating {}", dir.display()))?;
    let defaults = RelationsOptions::default();
    let options = RelationsOptions {
        scenes: 10,
        train: 8,
        annotator_noise: 0.05,
        sensor: SensorOptions {
            h_step_deg: 1.0,
            v_step_deg: 1.0,
            ..defaults.sensor.clone()
        },
        ..defaults
    };
    let t = Instant::now();
    write_relations(
        &map,
        "embedded default city",
        &dir,
        &options,
        args.seed,
        &|_, _| {},
    )
    .context("simulating the relations dataset")?;
    let sim_s = t.elapsed().as_secs_f64();
    let ds = RelationsDataset::load(&dir, &MapOptions::default(), &ObjectOptions::default())
        .with_context(|| format!("loading the relations dataset {}", dir.display()))?;
    let mut train_opts = TrainOptions::seeded(args.seed);
    train_opts.folds = 4;
    train_opts.cs = vec![0.01, 0.1];
    train_opts.positive_weights = vec![1.0, 2.0];
    train_opts.learn.epochs = 2;
    let model = train(&ds.train, &train_opts).context("training the demo relation model")?;
    let mut infer = mln::infer::InferOptions::default();
    infer.walksat.seed = args.seed;
    let ev = evaluate(&model, &ds, &infer).context("evaluating the demo model")?;

    // One test scene as a map: labelled top view and relation graph.
    let scene = ds
        .test
        .first()
        .context("the demo dataset has no test scene")?;
    let ply = dir.join(format!("scene_{:03}.ply", scene.index));
    let cloud =
        geodata::cloud::read_cloud(&ply).with_context(|| format!("reading {}", ply.display()))?;
    let mut m = SrMap::new(MapOptions::default())?;
    m.insert_cloud(&cloud, Some(scene.viewpoint.position))?;
    let vp = scene.viewpoint;
    let objects: Vec<_> = extract_objects(&m, &ObjectOptions::default())
        .into_iter()
        .filter(|o| {
            let v = vp.to_view(o.centroid);
            v[0].hypot(v[1]) < 25.0
        })
        .collect();
    let view: Vec<ViewObject> = objects
        .iter()
        .map(|o| ViewObject::from_map_object(&m, o, &vp))
        .collect();
    let out = model
        .infer(&view, &infer)
        .context("inferring the demo scene")?;
    let nodes: Vec<_> = objects.iter().map(|o| o.node()).collect();
    let graph = relation_graph(&nodes, &out.mln, vp);
    let semantic = SemanticMap {
        cells: m,
        relations: graph,
    };
    let map_path = args.out.join("relations-scene.srt");
    write_map(&map_path, &semantic).with_context(|| format!("writing {}", map_path.display()))?;
    // The map for other tools (issue 18): PLY (CloudCompare, Rerun) and a ROS 2 bag (Foxglove).
    for (name, write) in [
        (
            "semantic_map.ply",
            srtree::export::write_ply as fn(&std::path::Path, &SemanticMap) -> _,
        ),
        ("semantic_map.mcap", srtree::export::write_mcap),
    ] {
        let path = args.out.join(name);
        write(&path, &semantic).with_context(|| format!("writing {}", path.display()))?;
    }
    let SemanticMap {
        cells: m,
        relations: graph,
    } = semantic;

    // Top view raster, 0.2 m per pixel, 60 m around the viewpoint; the highest cell wins.
    let (half, px_m) = (30.0, 0.2);
    let side = (2.0 * half / px_m) as usize;
    let centre = [vp.position[0], vp.position[1]];
    let mut view = TopView::new(centre, px_m, side, [244; 3]);
    for c in m.cells() {
        view.plot(m.centre(c.key), c.class().color_rgb());
    }
    let png = encode_png_rgb(side as u32, side as u32, view.rgb())?;
    let mut svg = Svg::new(
        600.0,
        [vp.position[0] - half, vp.position[1] - half],
        [vp.position[0] + half, vp.position[1] + half],
    );
    for o in &objects {
        let [r, g, b] = o.class.color_rgb();
        svg.polygon(
            &o.bbox.footprint(),
            &format!(
                "fill:rgb({r},{g},{b});fill-opacity:0.35;stroke:rgb({r},{g},{b});stroke-width:1"
            ),
        );
    }
    let centre = |id: u32| graph.object(id).map(|o| [o.centroid[0], o.centroid[1]]);
    // LeftOf and Behind drawn as their transitive reductions (a chain, not every implied
    // pair); On as it is.
    for (rel, colour) in [
        (Relation::LeftOf, "#d62728"),
        (Relation::Behind, "#1f77b4"),
        (Relation::On, "#2ca02c"),
    ] {
        let edges: Vec<(u32, u32)> = if rel == Relation::On {
            graph
                .edges
                .iter()
                .filter(|e| e.has(rel))
                .map(|e| (e.a, e.b))
                .collect()
        } else {
            graph.transitive_reduction(rel)
        };
        for (ea, eb) in edges {
            if let (Some(a), Some(b)) = (centre(ea), centre(eb)) {
                // Arrow shaft plus a short head at b.
                let d = [b[0] - a[0], b[1] - a[1]];
                let len = d[0].hypot(d[1]).max(1e-9);
                let u = [d[0] / len, d[1] / len];
                let tip = [b[0] - 0.8 * u[0], b[1] - 0.8 * u[1]];
                let l = [
                    tip[0] - 0.8 * u[0] + 0.4 * u[1],
                    tip[1] - 0.8 * u[1] - 0.4 * u[0],
                ];
                let r = [
                    tip[0] - 0.8 * u[0] - 0.4 * u[1],
                    tip[1] - 0.8 * u[1] + 0.4 * u[0],
                ];
                let w = if rel == Relation::LeftOf { 0.8 } else { 1.4 };
                svg.polyline(
                    &[a, tip],
                    &format!("stroke:{colour};stroke-width:{w};stroke-opacity:0.7"),
                );
                svg.polyline(&[l, tip, r], &format!("stroke:{colour};stroke-width:{w}"));
            }
        }
    }
    let ahead = [
        vp.position[0] + 4.0 * vp.yaw_rad.cos(),
        vp.position[1] + 4.0 * vp.yaw_rad.sin(),
    ];
    svg.circle([vp.position[0], vp.position[1]], 6.0, "fill:black");
    svg.polyline(
        &[[vp.position[0], vp.position[1]], ahead],
        "stroke:black;stroke-width:3",
    );
    svg.scale_bar(10.0);

    let counts = |bit: Relation| graph.edges.iter().filter(|e| e.has(bit)).count();
    let rows: Vec<Vec<String>> = Relation::BASE
        .into_iter()
        .enumerate()
        .map(|(k, r)| {
            vec![
                r.name().to_string(),
                format!("{:.3}", ev.svm.confusion[k].true_value().f1),
                format!("{:.3}", ev.mln.confusion[k].true_value().f1),
            ]
        })
        .collect();
    let table = Html::table(&["relation", "SVM True-F1", "SVM+MLN True-F1"], &rows);
    let mem = m.memory();
    Ok(StageOutput {
        key: "srtree",
        summary: serde_json::to_value(SrtreeSummary {
            scenes: SceneCounts {
                train: ds.train.len(),
                test: ds.test.len(),
            },
            sim_seconds: sim_s,
            evaluation: ev.report(),
            scene: scene.index,
            cells: m.len(),
            bytes_per_cell: mem.bytes_per_cell,
            objects: objects.len(),
            edges: EdgeCounts {
                on: counts(Relation::On),
                left_of: counts(Relation::LeftOf),
                behind: counts(Relation::Behind),
            },
        })?,
        title: "srtree: semantic R-tree map and spatial relations (SVM + MLN)",
        text_html: format!(
            "{} simulated viewpoint scenes of the default city (5 % annotator noise); linear SVMs and the relation MLN \
             trained on {}, scored on {} against the noise-free truth. Left: test scene {} as an SRTree map ({} cells of 0.1 m, \
             {:.0} bytes per cell), top view coloured by the Dirichlet/majority cell class. Right: its objects' oriented boxes \
             and the MAP relation graph from the viewpoint (black): LeftOf red, Behind blue (both as transitive reductions: \
             chains without the implied pairs), On green. {} hard-rule violations \
             in the SVM output, {} after the MLN.{table}",
            ds.train.len() + ds.test.len(),
            ds.train.len(),
            ds.test.len(),
            scene.index,
            m.len(),
            mem.bytes_per_cell,
            ev.svm.violations,
            ev.mln.violations,
        ),
        figures: vec![
            Html::png_img(&png, &escape("labelled top view"), 600),
            svg.finish(),
        ],
        files: vec![("relations-graph.dot", graph.to_dot().into_bytes())],
    })
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::expect_used)]
    use super::*;

    #[test]
    fn demo_stage_draws_the_map_and_graph() {
        let out = std::env::temp_dir().join(format!("urbansem-srtree-demo-{}", std::process::id()));
        let args = DemoArgs {
            out: out.clone(),
            seed: 1,
        };
        let stage = stage(&args).unwrap();
        assert_eq!(stage.key, "srtree");
        assert!(stage.figures[1].contains("<polygon"));
        assert_eq!(stage.summary["evaluation"]["violations"]["mln"], 0);
        // The map for other tools: the same points in the PLY and the bag.
        let ply = geodata::cloud::read_cloud(out.join("semantic_map.ply")).unwrap();
        let bag = geodata::cloud::read_cloud(out.join("semantic_map.mcap")).unwrap();
        assert!(ply.len() > 100, "{}", ply.len());
        assert_eq!(ply.positions, bag.positions);
        assert_eq!(ply.label, bag.label);
        assert_eq!(ply.object, bag.object);
        let _ = std::fs::remove_dir_all(out);
    }
}
