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
