//! A synthetic labelled ground cloud around a map's segments with known offsets and widths:
//! small fixtures of the `streets` dataset format for tests, independent of the simulator.
//!
//! Driving area at z = 0, sidewalks and grass 0.15 m higher; intensity and colour differ per
//! class but overlap (noise), so a classifier is good but not perfect.

use crate::corridor::SegmentFrame;
use crate::dataset::SegmentTruth;
use geodata::classes::Class;
use geodata::cloud::{Columns, PointCloud, PointRecord, Precision};
use geodata::osm::OsmMap;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// Ground points every `spacing_m` (jittered) within `margin_m` of any segment.
pub fn ground_cloud(
    map: &OsmMap,
    truth: &[SegmentTruth],
    spacing_m: f64,
    margin_m: f64,
    seed: u64,
) -> PointCloud {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let segs = &map.streets.segments;
    let frames: Vec<Option<SegmentFrame>> = segs.iter().map(SegmentFrame::of).collect();
    let (mut min, mut max) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
    for s in segs {
        for p in [s.a, s.b] {
            for k in 0..2 {
                min[k] = min[k].min(p[k] - margin_m);
                max[k] = max[k].max(p[k] + margin_m);
            }
        }
    }
    let columns = Columns {
        intensity: true,
        rgb: true,
        label: true,
        object: true,
        ..Columns::default()
    };
    let mut cloud = PointCloud::with_columns(columns, Precision::F32, 0);
    if !min[0].is_finite() {
        return cloud;
    }
    let nx = ((max[0] - min[0]) / spacing_m) as usize;
    let ny = ((max[1] - min[1]) / spacing_m) as usize;
    for i in 0..nx {
        for j in 0..ny {
            let p = [
                min[0] + (i as f64 + rng.gen::<f64>()) * spacing_m,
                min[1] + (j as f64 + rng.gen::<f64>()) * spacing_m,
            ];
            // Distance-to-segment test and the class from the strips.
            let mut near = false;
            let mut class = Class::Grass;
            for (s, f) in frames.iter().enumerate() {
                let (Some(f), Some(t)) = (f, truth.get(s)) else {
                    continue;
                };
                let (tt, u) = f.local(p);
                if tt < -margin_m || tt > f.length_m + margin_m || u.abs() > margin_m {
                    continue;
                }
                near = true;
                if (0.0..=f.length_m).contains(&tt) {
                    let du = (u - t.offset_m).abs();
                    if t.drivable && du <= 0.5 * t.width_m {
                        class = Class::Street;
                    } else if du <= 0.5 * t.width_m + t.sidewalk_m && class != Class::Street {
                        class = Class::Sidewalk;
                    }
                }
            }
            if !near {
                continue;
            }
            let (z, intensity, rgb): (f64, f64, [f64; 3]) = match class {
                Class::Street => (0.0, 0.25, [90.0, 90.0, 95.0]),
                Class::Sidewalk => (0.15, 0.4, [150.0, 140.0, 130.0]),
                _ => (0.15, 0.45, [70.0, 130.0, 60.0]),
            };
            let noise = |rng: &mut ChaCha8Rng, s: f64| (rng.gen::<f64>() - 0.5) * 2.0 * s;
            let rgb = rgb.map(|c| (c + noise(&mut rng, 45.0)).clamp(0.0, 255.0) as u8);
            cloud.push(&PointRecord {
                position: [p[0], p[1], z + noise(&mut rng, 0.04)],
                intensity: (intensity + noise(&mut rng, 0.2)).clamp(0.0, 1.0) as f32,
                rgb,
                label: class.id(),
                ..PointRecord::default()
            });
        }
    }
    cloud
}

/// Latitude of the synthetic maps' local origin, degrees.
pub const ORIGIN_LAT: f64 = 48.0;
/// Longitude of the synthetic maps' local origin, degrees.
pub const ORIGIN_LON: f64 = 11.0;

/// An OSM XML `<node>` at local metres `(x, y)` east and north of
/// ([`ORIGIN_LAT`], [`ORIGIN_LON`]).
pub fn osm_node(id: i64, x: f64, y: f64) -> String {
    let lat = ORIGIN_LAT + y / 111_320.0;
    let lon = ORIGIN_LON + x / (111_320.0 * ORIGIN_LAT.to_radians().cos());
    format!(r#"<node id="{id}" lat="{lat:.8}" lon="{lon:.8}"/>"#)
}

/// A 4 × 4 lattice of residential streets 50 m apart (one way per row and per column, 24
/// segments), a footway across it, and a spur way leaving the lattice to the east.
pub fn lattice_osm_xml() -> String {
    let mut s = String::from(r#"<?xml version="1.0"?><osm version="0.6">"#);
    let id = |i: i64, j: i64| 1 + i + 4 * j;
    for j in 0..4 {
        for i in 0..4 {
            s += &osm_node(id(i, j), 50.0 * i as f64, 50.0 * j as f64 + 3.0 * i as f64);
        }
    }
    s += &osm_node(100, 230.0, 60.0);
    s += &osm_node(101, 300.0, 70.0);
    let way = |wid: i64, nodes: &[i64], highway: &str| {
        let refs: String = nodes
            .iter()
            .map(|n| format!(r#"<nd ref="{n}"/>"#))
            .collect();
        format!(r#"<way id="{wid}">{refs}<tag k="highway" v="{highway}"/></way>"#)
    };
    for j in 0..4 {
        let row: Vec<i64> = (0..4).map(|i| id(i, j)).collect();
        s += &way(200 + j, &row, "residential");
        let col: Vec<i64> = (0..4).map(|i| id(j, i)).collect();
        s += &way(300 + j, &col, "residential");
    }
    s += &way(400, &[id(0, 0), id(1, 1), id(2, 2)], "footway");
    s += &way(401, &[id(3, 1), 100, 101], "tertiary");
    s += "</osm>";
    s
}

/// The street lattice of [`lattice_osm_xml`] with its ground cloud and truth.
#[derive(Debug, Clone)]
pub struct Lattice {
    /// The map.
    pub map: OsmMap,
    /// Ground points around its segments; the far end of the spur is not covered.
    pub cloud: PointCloud,
    /// Every segment's true offset and width (widths 5–8 m, offsets −0.5–0.5 m).
    pub truth: Vec<SegmentTruth>,
}

/// The street lattice: map, ground cloud (seeded) and truth; a fixture whose tiles, shards
/// and whole-map estimates the tests compare.
pub fn lattice() -> crate::Result<Lattice> {
    let map = OsmMap::from_xml_str(&lattice_osm_xml())?;
    let truth: Vec<SegmentTruth> = map
        .streets
        .segments
        .iter()
        .enumerate()
        .map(|(i, s)| SegmentTruth {
            segment: i,
            offset_m: 0.1 * (i % 11) as f64 - 0.5,
            width_m: 5.0 + 0.4 * (i % 8) as f64,
            sidewalk_m: 2.0,
            outer_offset_m: None,
            outer_observed: true,
            drivable: geodata::osm::tags::is_drivable(&s.highway),
            observed: true,
            points: 1000,
        })
        .collect();
    let full = ground_cloud(&map, &truth, 0.8, 12.0, 19);
    // The map's local frame is not the lattice's: cut 5 m before node 100.
    let cut = map
        .streets
        .segments
        .iter()
        .find(|s| s.from_node == 100)
        .map_or(f64::INFINITY, |spur| spur.a[0] - 5.0);
    let cloud = full.filter(|k| full.positions.get(k).is_some_and(|p| p[0] <= cut));
    Ok(Lattice { map, cloud, truth })
}

/// A model trained on the lattice's own labelled bins (a few hundred, seeded); a 24 m
/// corridor (120 columns) keeps loopy max-product on the lattice quick.
pub fn lattice_model(lattice: &Lattice) -> crate::Result<crate::model::StreetModel> {
    use crate::model::{BinClassifier, ClassifierOptions, GeometryOptions, StreetModel, Target};
    let geometry = GeometryOptions {
        corridor: crate::corridor::CorridorOptions {
            width_m: 24.0,
            ..crate::corridor::CorridorOptions::default()
        },
        max_width_m: 12.0,
        ..GeometryOptions::default()
    };
    let (x, y) = labelled_rows(&lattice.map, &lattice.cloud, &geometry, Target::DrivingArea);
    let options = ClassifierOptions {
        max_train_bins: 150,
        calibration_bins: 150,
        ..ClassifierOptions::default()
    };
    let drivable: Vec<(f64, f64)> = lattice
        .truth
        .iter()
        .filter(|t| t.drivable)
        .map(|t| (t.offset_m, t.width_m))
        .collect();
    Ok(StreetModel {
        target: Target::DrivingArea,
        geometry,
        classifier: BinClassifier::train(&x, &y, &options)?,
        prior: crate::potentials::GeometryPrior::fit(&drivable),
        sidewalk_prior: None,
        tag_prior: None,
    })
}

/// A with-sidewalk model for [`lattice`] with sidewalk margins learnt from its truth, so that
/// its priors are centred on a driving-area estimate ([`lattice_model`]'s).
pub fn lattice_sidewalk_model(lattice: &Lattice) -> crate::Result<crate::model::StreetModel> {
    use crate::model::{BinClassifier, ClassifierOptions, Target};
    let mut model = lattice_model(lattice)?;
    let (x, y) = labelled_rows(
        &lattice.map,
        &lattice.cloud,
        &model.geometry,
        Target::WithSidewalk,
    );
    let options = ClassifierOptions {
        max_train_bins: 150,
        calibration_bins: 150,
        ..ClassifierOptions::default()
    };
    let samples: Vec<crate::prior::MarginSample> = lattice
        .truth
        .iter()
        .filter(|t| t.drivable)
        .map(|t| {
            let outer = (t.offset_m, t.width_m + 2.0 * t.sidewalk_m);
            (
                crate::prior::SegmentTags::of(&lattice.map, t.segment),
                (t.offset_m, t.width_m),
                outer,
            )
        })
        .collect();
    let outer: Vec<(f64, f64)> = samples.iter().map(|s| s.2).collect();
    model.target = Target::WithSidewalk;
    model.classifier = BinClassifier::train(&x, &y, &options)?;
    model.prior = crate::potentials::GeometryPrior::fit(&outer);
    model.sidewalk_prior = crate::prior::SidewalkPrior::fit(&samples);
    Ok(model)
}

/// The feature rows and `target` labels of every usable labelled bin of the map's segments
/// in the cloud: a classifier's training set.
pub fn labelled_rows(
    map: &OsmMap,
    cloud: &PointCloud,
    geometry: &crate::model::GeometryOptions,
    target: crate::model::Target,
) -> (Vec<f32>, Vec<bool>) {
    let which: Vec<usize> = (0..map.streets.segments.len()).collect();
    let bins = crate::model::segment_bins(map, cloud, &which, geometry);
    let (mut x, mut y) = (Vec::new(), Vec::new());
    for b in bins.iter().flatten() {
        for k in b.usable() {
            if let Some(c) = b.features.truth[k] {
                x.extend_from_slice(b.features.row(k));
                y.push(target.positive(c));
            }
        }
    }
    (x, y)
}
