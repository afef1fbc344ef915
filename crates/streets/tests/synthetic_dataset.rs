//! The whole pipeline on a synthetic `streets` dataset with known offsets and widths:
//! evaluation, estimation, GeoJSON output and the bad-input messages.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use geodata::cloud::write_cloud;
use geodata::osm::OsmMap;
use std::path::PathBuf;
use streets::dataset::{SegmentTruth, StreetsDataset};
use streets::eval::{evaluate, EvalOptions};
use streets::model::{BinClassifier, ClassifierOptions, GeometryOptions, StreetModel, Target};
use streets::potentials::GeometryPrior;
use streets::StreetsError;

use streets::synthetic::osm_node as node;

/// A T-free cross: way 1 along x (6 segments of 40 m), way 2 along y through node 4.
fn cross_xml() -> String {
    let mut s = String::from(r#"<?xml version="1.0"?><osm version="0.6">"#);
    for k in 0..7 {
        s += &node(1 + k, 40.0 * k as f64, 0.0);
    }
    for (id, y) in [
        (11, -120.0),
        (12, -80.0),
        (13, -40.0),
        (14, 40.0),
        (15, 80.0),
    ] {
        s += &node(id, 120.0, y);
    }
    s += r#"<way id="100"><nd ref="1"/><nd ref="2"/><nd ref="3"/><nd ref="4"/><nd ref="5"/><nd ref="6"/><nd ref="7"/><tag k="highway" v="residential"/></way>"#;
    s += r#"<way id="200"><nd ref="11"/><nd ref="12"/><nd ref="13"/><nd ref="4"/><nd ref="14"/><nd ref="15"/><tag k="highway" v="residential"/></way>"#;
    s += "</osm>";
    s
}

fn truths(map: &OsmMap) -> Vec<SegmentTruth> {
    map.streets
        .segments
        .iter()
        .enumerate()
        .map(|(i, s)| {
            let horizontal = (s.b[1] - s.a[1]).abs() < 1.0;
            let k = s.index_in_way as f64;
            SegmentTruth {
                segment: i,
                offset_m: if horizontal {
                    0.6 - 0.1 * k
                } else {
                    -0.8 + 0.1 * k
                },
                width_m: if horizontal {
                    7.0 + 0.2 * k
                } else {
                    5.4 + 0.2 * k
                },
                sidewalk_m: 2.0,
                outer_offset_m: None,
                outer_observed: true,
                drivable: true,
                observed: true,
                points: 1000,
            }
        })
        .collect()
}

/// Writes the fixture into a fresh folder under the target dir.
fn fixture(name: &str) -> PathBuf {
    let dir = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join(name);
    std::fs::create_dir_all(&dir).unwrap();
    let xml = cross_xml();
    std::fs::write(dir.join("map.osm"), &xml).unwrap();
    let map = OsmMap::from_xml_str(&xml).unwrap();
    let truth = truths(&map);
    let cloud = streets::synthetic::ground_cloud(&map, &truth, 0.3, 20.0, 5);
    write_cloud(dir.join("cloud.ply"), &cloud).unwrap();
    std::fs::write(
        dir.join("segments.json"),
        serde_json::to_string(&truth).unwrap(),
    )
    .unwrap();
    std::fs::write(
        dir.join("dataset.json"),
        r#"{"kind": "streets", "map": "map.osm", "seed": 5, "poses": []}"#,
    )
    .unwrap();
    dir
}

fn small_options() -> EvalOptions {
    let mut o = EvalOptions {
        classifier: ClassifierOptions {
            max_train_bins: 800,
            calibration_bins: 800,
            ..ClassifierOptions::default()
        },
        ..EvalOptions::default()
    };
    o.mcmc.chains = 4;
    o.mcmc.iterations = 20_000;
    o
}

#[test]
fn evaluation_recovers_known_widths() {
    let ds = StreetsDataset::load(fixture("eval")).unwrap();
    assert_eq!(ds.map.streets.segments.len(), 11);
    let r = evaluate(&ds, &small_options()).unwrap();
    assert_eq!(r.segments, 11);
    for (name, t) in [("driving", &r.driving_area), ("sidewalk", &r.with_sidewalk)] {
        let full = t.full_model.rmse_w.unwrap();
        assert!(full < 1.0, "{name}: full-model RMSE_w {full}");
        assert!(t.true_geometry.rmse_w.unwrap() < 0.15);
        assert!(
            t.opt_on_truth.rmse_w.unwrap() < 0.5,
            "{name}: {:?}",
            t.opt_on_truth
        );
        assert!(t.raw.rmse_w.is_none());
        assert!(t.true_geometry.f1 > 0.9, "{name}: {:?}", t.true_geometry);
        assert!(t.full_model.f1 > 0.8, "{name}: {:?}", t.full_model);
    }
    // The interface keys of issue 5.
    let v = serde_json::to_value(&r).unwrap();
    for target in ["driving_area", "with_sidewalk"] {
        for m in [
            "raw",
            "single_segment",
            "full_model",
            "opt_on_truth",
            "true_geometry",
        ] {
            for k in ["precision", "recall", "f1", "rmse_w"] {
                assert!(v[target][m].get(k).is_some(), "{target}.{m}.{k}");
            }
        }
    }
    assert!(v["seconds"]["per_metre"].as_f64().unwrap() > 0.0);
    // MCMC ends no worse than its start and max-product is exact on this tree-shaped network.
    let d = &r.details["driving_area"];
    assert!(d.exact);
    assert!(d.mcmc_log_p <= d.max_product_log_p + 1e-6);
}

fn model_for(ds: &StreetsDataset) -> StreetModel {
    let geometry = GeometryOptions::default();
    let (x, y) =
        streets::synthetic::labelled_rows(&ds.map, &ds.cloud, &geometry, Target::DrivingArea);
    let classifier = BinClassifier::train(
        &x,
        &y,
        &ClassifierOptions {
            max_train_bins: 800,
            ..ClassifierOptions::default()
        },
    )
    .unwrap();
    let prior = GeometryPrior::fit(
        &ds.segments
            .iter()
            .map(|s| (s.offset_m, s.width_m))
            .collect::<Vec<_>>(),
    );
    StreetModel {
        target: Target::DrivingArea,
        geometry,
        classifier,
        prior,
        sidewalk_prior: None,
        tag_prior: None,
    }
}

#[test]
fn estimate_writes_valid_geojson_and_bad_inputs_are_named() {
    let ds = StreetsDataset::load(fixture("estimate")).unwrap();
    let model = model_for(&ds);
    let est = model
        .estimate(&ds.map, &ds.cloud, "map.osm", "cloud.ply")
        .unwrap();
    assert_eq!(est.segments.len(), 11);
    for e in &est.segments {
        let t = &ds.segments[e.segment];
        assert!((e.width_m - t.width_m).abs() < 1.0, "{e:?} vs {t:?}");
    }
    let fc = streets::geojson::feature_collection(&ds.map, &est.segments, model.target);
    streets::geojson::validate(&fc).unwrap();
    assert_eq!(fc["attribution"], geodata::geojson::OSM_ATTRIBUTION);
    assert_eq!(fc["features"][0]["properties"]["target"], "driving_area");
    let text = serde_json::to_string(&fc).unwrap();
    let back: serde_json::Value = serde_json::from_str(&text).unwrap();
    assert_eq!(back["features"].as_array().unwrap().len(), 11);
    let lonlat = &back["features"][0]["geometry"]["coordinates"][0][0];
    assert!((lonlat[0].as_f64().unwrap() - streets::synthetic::ORIGIN_LON).abs() < 0.01);
    assert!((lonlat[1].as_f64().unwrap() - streets::synthetic::ORIGIN_LAT).abs() < 0.01);
    assert!(back["features"][0]["properties"]["width"].as_f64().unwrap() > 4.0);

    // A cloud far away from the streets.
    let mut far = ds.cloud.clone();
    for p in &mut far.positions {
        p[0] += 5000.0;
    }
    let err = model
        .estimate(&ds.map, &far, "map.osm", "far.ply")
        .unwrap_err();
    assert!(matches!(err, StreetsError::NoOverlap { .. }), "{err}");
    assert!(err.to_string().contains("far.ply"));

    // A map without streets.
    let no_streets = OsmMap::from_xml_str(
        r#"<osm version="0.6"><node id="1" lat="48.0" lon="11.0"/><node id="2" lat="48.0001" lon="11.0"/><node id="3" lat="48.0001" lon="11.0001"/><way id="5"><nd ref="1"/><nd ref="2"/><nd ref="3"/><nd ref="1"/><tag k="building" v="yes"/></way></osm>"#,
    )
    .unwrap();
    let err = model
        .estimate(&no_streets, &ds.cloud, "buildings.osm", "cloud.ply")
        .unwrap_err();
    assert!(matches!(err, StreetsError::NoStreets { .. }), "{err}");
    assert!(err.to_string().contains("buildings.osm"));

    // Segments shorter than a bin.
    let tiny = OsmMap::from_xml_str(
        r#"<osm version="0.6"><node id="1" lat="48.0" lon="11.0"/><node id="2" lat="48.0000001" lon="11.0"/><way id="5"><nd ref="1"/><nd ref="2"/><tag k="highway" v="residential"/></way></osm>"#,
    )
    .unwrap();
    let err = model
        .estimate(&tiny, &ds.cloud, "tiny.osm", "cloud.ply")
        .unwrap_err();
    assert!(
        matches!(err, StreetsError::SegmentsTooShort { .. }),
        "{err}"
    );
    assert!(err.to_string().contains("shorter than one"));
}

#[test]
fn malformed_dataset_files_are_named_with_their_line() {
    let dir = fixture("malformed");
    std::fs::write(dir.join("segments.json"), "[\n{\"segment\": 0,\n").unwrap();
    let err = StreetsDataset::load(&dir).err().unwrap().to_string();
    assert!(
        err.contains("segments.json") && err.contains("line"),
        "{err}"
    );
    std::fs::write(dir.join("segments.json"), "[]").unwrap();
    let err = StreetsDataset::load(&dir).err().unwrap().to_string();
    assert!(err.contains("0 entries but the map"), "{err}");
    std::fs::write(
        dir.join("dataset.json"),
        r#"{"kind": "relations", "map": "map.osm"}"#,
    )
    .unwrap();
    let err = StreetsDataset::load(&dir).err().unwrap().to_string();
    assert!(err.contains("expected \"streets\""), "{err}");
}

#[test]
fn a_with_sidewalk_model_centres_its_prior_on_the_estimated_driving_area() {
    let ds = StreetsDataset::load(fixture("sidewalk-prior")).unwrap();
    let options = ClassifierOptions {
        max_train_bins: 800,
        calibration_bins: 800,
        ..ClassifierOptions::default()
    };
    let driving = StreetModel::train(&ds, Target::DrivingArea, &options).unwrap();
    let sidewalk = StreetModel::train(&ds, Target::WithSidewalk, &options).unwrap();
    // Only the with-sidewalk model learns margins: every fixture segment has 2 m sidewalks
    // on both sides, centred on its driving area.
    assert_eq!(driving.sidewalk_prior, None);
    let margins = sidewalk.sidewalk_prior.clone().unwrap();
    assert_eq!(margins.global.segments, 11);
    assert!((margins.global.mean_m - 2.0).abs() < 1e-9, "{margins:?}");
    assert!(margins.global.mean_shift_m.abs() < 1e-9);
    // The prior of an estimated segment is centred on its driving area plus both margins;
    // a segment without a driving-area estimate keeps its tag group's.
    let d = driving
        .estimate(&ds.map, &ds.cloud, "map.osm", "cloud.ply")
        .unwrap();
    assert_eq!(d.segments.len(), 11);
    let mut partial = d.segments.clone();
    let dropped = partial.remove(0);
    let priors = sidewalk.priors_given_driving_area(&ds.map, &partial);
    assert_eq!(priors.len(), 11);
    for e in &partial {
        let p = &priors[e.segment];
        assert!(
            (p.mean_log_width.exp() - (e.width_m + 4.0)).abs() < 1e-9,
            "{p:?} {e:?}"
        );
        assert!((p.mean_offset_m - e.offset_m).abs() < 1e-9);
    }
    assert_eq!(
        priors[dropped.segment],
        sidewalk.segment_prior(&ds.map, dropped.segment)
    );
    // Estimated with that prior, every width is within 1 m of the truth.
    let w = sidewalk
        .estimate_given_driving_area(&ds.map, &ds.cloud, "map.osm", "cloud.ply", &d.segments)
        .unwrap();
    assert_eq!(w.segments.len(), 11);
    for e in &w.segments {
        let t = &ds.segments[e.segment];
        let truth = t.width_m + 2.0 * t.sidewalk_m;
        assert!((e.width_m - truth).abs() < 1.0, "{e:?} vs {truth}");
    }
    // The margins survive the model file; a NaN margin is named when the file is read.
    let mut v = serde_json::to_value(&sidewalk).unwrap();
    let back = StreetModel::from_json(
        &serde_json::to_vec(&v).unwrap(),
        std::path::Path::new("m.json"),
    )
    .unwrap();
    assert_eq!(back, sidewalk);
    v["sidewalk_prior"]["global"]["sigma_m"] = serde_json::json!(-1.0);
    let err = StreetModel::from_json(
        &serde_json::to_vec(&v).unwrap(),
        std::path::Path::new("m.json"),
    )
    .unwrap_err();
    assert!(
        err.to_string().contains("sidewalk_prior.global.sigma_m"),
        "{err}"
    );
    assert!(err.to_string().contains("m.json"), "{err}");
}

#[test]
fn the_single_segment_model_takes_nothing_from_the_network() {
    // With sidewalk, every segment's prior is centred on its estimated driving area; the
    // single-segment model must centre it on the single-segment driving area, so that its
    // scores do not move when the coupling between segments does (one tempering: no
    // selection through the network).
    let ds = StreetsDataset::load(fixture("eval")).unwrap();
    let mut options = small_options();
    options.mcmc.chains = 1;
    options.mcmc.iterations = 100;
    options.temperings = vec![streets::potentials::Tempering {
        tau: 512.0,
        floor_nats: 8.0,
        prior_weight: 1.0,
        coupling_cap_nats: f64::INFINITY,
    }];
    let coupled = evaluate(&ds, &options).unwrap();
    options.geometry.sigma_m = 1e9;
    let loose = evaluate(&ds, &options).unwrap();
    // The coupling matters here: the driving area's full model moves with it …
    assert_ne!(
        coupled.driving_area.full_model.rmse_w,
        loose.driving_area.full_model.rmse_w
    );
    // … and neither single-segment row does.
    for (a, b) in [
        (&coupled.driving_area, &loose.driving_area),
        (&coupled.with_sidewalk, &loose.with_sidewalk),
    ] {
        assert_eq!(a.single_segment.rmse_w, b.single_segment.rmse_w);
        assert_eq!(a.single_segment.f1, b.single_segment.f1);
    }
}
