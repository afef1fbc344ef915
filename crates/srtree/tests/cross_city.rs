//! The README's cross-city relations claim: a model trained on one city's scenes holds its
//! True-F1 on every scene of another (Helsinki → KTH, seed 1, no annotator noise, as
//! `urbansem sim dataset --kind relations --map M --seed 1 --annotator-noise 0 --train 48`
//! and `urbansem relations eval --dataset KTH --train-dataset HELSINKI`).

#![allow(clippy::unwrap_used, clippy::expect_used)]

use geodata::osm::OsmMap;
use geosim::dataset::{write_relations, RelationsOptions};
use mln::infer::InferOptions;
use srtree::dataset::RelationsDataset;
use srtree::map::MapOptions;
use srtree::objects::ObjectOptions;
use srtree::relations::{evaluate, train, TrainOptions};
use std::path::{Path, PathBuf};

fn osm(name: &str) -> PathBuf {
    let p = PathBuf::from(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../../shared/data/osm"
    ))
    .join(name);
    assert!(p.exists(), "missing shared data: {}", p.display());
    p
}

fn dataset(map: &Path, out: &Path) {
    let osm = OsmMap::load(map).unwrap();
    let options = RelationsOptions {
        train: 48,
        annotator_noise: 0.0,
        ..RelationsOptions::default()
    };
    write_relations(
        &osm,
        &map.display().to_string(),
        out,
        &options,
        1,
        &|_, _| {},
    )
    .unwrap();
}

#[test]
fn a_model_trained_in_helsinki_holds_at_kth() {
    let dir = std::env::temp_dir().join(format!("srtree-cross-city-{}", std::process::id()));
    let (hel, kth) = (dir.join("hel"), dir.join("kth"));
    dataset(&osm("helsinki_centre.osm.pbf"), &hel);
    dataset(&osm("kth_campus_stockholm.osm"), &kth);
    let (m, o) = (MapOptions::default(), ObjectOptions::default());
    // The test dataset among the training ones is refused.
    let err = RelationsDataset::load_across(&kth, &[hel.clone(), kth.clone()], &m, &o).unwrap_err();
    assert!(err.to_string().contains("is the test dataset"), "{err}");
    let split = RelationsDataset::load_across(&kth, std::slice::from_ref(&hel), &m, &o).unwrap();
    std::fs::remove_dir_all(&dir).ok();
    // Every KTH scene is tested: none was seen in training.
    let kth = split.test;
    assert_eq!(
        (split.train.len(), kth.test.len(), kth.train.len()),
        (48, 62, 0)
    );
    let mut options = TrainOptions::default();
    options.svm.seed = 1;
    options.learn.infer.walksat.seed = 1;
    let model = train(&split.train, &options).unwrap();
    let mut infer = InferOptions::default();
    infer.walksat.seed = 1;
    let ev = evaluate(&model, &kth, &infer).unwrap();
    // Measured 2026-12-02 on the scenes redrawn with the sidewalks as the maps draw them
    // (README, *Redrawn 2026-12-02*): On 0.953, LeftOf 0.986, Behind 0.962 (SVM + MLN);
    // pinned 0.03 below (about three of the true Behind pairs).
    let f1: Vec<f64> = ev.mln.confusion.iter().map(|c| c.true_value().f1).collect();
    eprintln!("Helsinki → KTH True-F1 On, LeftOf, Behind (SVM + MLN): {f1:.3?}");
    for (name, got, want) in [
        ("On", f1[0], 0.953),
        ("LeftOf", f1[1], 0.986),
        ("Behind", f1[2], 0.962),
    ] {
        assert!(got >= want - 0.03, "{name} True-F1 {got:.3}, README {want}");
    }
    assert_eq!(ev.mln.violations, 0);
    // The consistency step does not lose what the classifiers found.
    let svm: Vec<f64> = ev.svm.confusion.iter().map(|c| c.true_value().f1).collect();
    for k in 0..3 {
        assert!(
            f1[k] >= svm[k] - 0.01,
            "{k}: SVM + MLN {} < SVM {}",
            f1[k],
            svm[k]
        );
    }
}
