//! Why a scan of a simulated `localization` dataset (or of a real sequence, map in `MAP`) has no accurate candidate (4 m / 0.2 rad):
//! per scan, the cost of the best pose near the truth relative to the search's minimum (cut
//! by the factor?), and how many poses near the truth survive suppression and the filters,
//! with the per-segment costs at the best near-truth pose and at the minimum.
//!
//! `cargo run --release -p localize --example diagnose -- DATASET [SCAN_INDEX…]`
//!
//! Without indices only the scans without an accurate candidate are printed. Environment
//! overrides of the defaults: `YAW_STEP` (degrees), `FEASIBLE` (0: search every pose, filter
//! after), `MAX_ACCEPT`, `NMS` (metres), `MERGE_DIST`, `MERGE_ANGLE` (degrees), `MERGE_GAP`,
//! `FINAL_MIN`, `CLEARANCE`, `SENSOR=manual` (the options above as given; default: the sensor
//! profile measured per scan, as `localize` does); `DIAG_SVG=DIR` writes a figure per printed scan (cells and
//! segments at the true pose over the map); `TIMING=1` prints only the mean search effort.

use geodata::osm::index::MapIndex;
use geodata::osm::OsmMap;
use localize::candidates::{build_template, filter, pose_cost, suppress, StreetFilter, Template};
use localize::eval::{Accuracy, SimDataset};
use localize::pipeline::{LocalizeOptions, Localizer};
use localize::segments::extract_segments;
use localize::surfaces::vertical_cells;
use localize::{angle_diff, Pose2};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let dir = args.next().ok_or("usage: diagnose DATASET [SCAN_INDEX…]")?;
    let only: Vec<usize> = args.map(|a| a.parse()).collect::<Result<_, _>>()?;
    // A real sequence (KITTI-360, MCD) with its map in `MAP`, or a simulated dataset.
    let real = localize::eval::real_sequence(std::path::Path::new(&dir));
    let ds = match real {
        None => Some(SimDataset::open(&dir)?),
        Some(_) => None,
    };
    let map = match &ds {
        Some(d) => OsmMap::load(&d.map_path)?,
        None => {
            OsmMap::load(std::env::var("MAP").map_err(|_| "a real sequence needs MAP=map.osm")?)?
        }
    };
    let real_scans = match real {
        Some(kind) => localize::eval::real_scans(std::path::Path::new(&dir), kind, &map, 1)?,
        None => Vec::new(),
    };
    let n_scans = ds.as_ref().map_or(real_scans.len(), |d| d.truth.len());
    let load = |i: usize| -> Result<localize::eval::EvalScan, Box<dyn std::error::Error>> {
        match &ds {
            Some(d) => Ok(d.load(i)?),
            None => Ok(real_scans[i].clone()),
        }
    };
    // The sensor profile is measured per scan (as `localize` does) unless `SENSOR=manual`,
    // where the environment variables below set the extraction options themselves.
    let manual = std::env::var("SENSOR").is_ok_and(|v| v == "manual");
    let mut options = LocalizeOptions {
        sensor: if manual {
            localize::sensor::SensorChoice::Manual
        } else {
            localize::sensor::SensorChoice::Auto
        },
        ..LocalizeOptions::default()
    };
    let env = |k: &str| std::env::var(k).ok().and_then(|v| v.parse::<f64>().ok());
    if let Some(v) = env("FEASIBLE") {
        options.search.feasible_only = v != 0.0;
    }
    if let Some(v) = env("MAX_ACCEPT") {
        options.max_accept_cost_m = v;
    }
    if let Some(v) = env("YAW_STEP") {
        options.search.yaw_step_deg = v;
    }
    if let Some(v) = env("MERGE_DIST") {
        options.segments.merge_distance_m = v;
    }
    if let Some(v) = env("MERGE_ANGLE") {
        options.segments.merge_angle_rad = v.to_radians();
    }
    if let Some(v) = env("MERGE_GAP") {
        options.segments.merge_gap_m = v;
    }
    if let Some(v) = env("FINAL_MIN") {
        options.segments.final_min_length_m = v;
    }
    if let Some(v) = env("CLEARANCE") {
        options.surfaces.clearance_m = v;
        options.overrides.clearance_m = Some(v);
    }
    if let Some(v) = env("NMS") {
        options.search.nms_radius_m = v;
    }
    let localizer = Localizer::new(&map, options)?;
    println!(
        "map prep {:?}, feasible cells {:?} of {}",
        localizer.seconds,
        localizer.feasible.as_ref().map(|m| m.feasible_cells),
        localizer.domain.cells()
    );
    let index = MapIndex::new(&map);
    let o = &localizer.options;
    let acc = Accuracy::THESIS;
    let failing_only = only.is_empty();
    let scans: Vec<usize> = if only.is_empty() {
        (0..n_scans).collect()
    } else {
        only
    };
    if std::env::var("TIMING").is_ok() {
        // Search effort only: boxes and leaves bounded (load-independent) and seconds.
        let (mut boxes, mut leaves, mut search_s, mut total_s) = (0u64, 0u64, 0.0, 0.0);
        for &i in &scans {
            let scan = load(i)?;
            let r = localizer.localize_points(&scan.points)?;
            boxes += r.search.boxes;
            leaves += r.search.leaves;
            search_s += r.seconds.search;
            total_s += r.seconds.total;
        }
        let n = scans.len().max(1) as f64;
        println!(
            "{} scans: mean boxes {:.2} M, leaves {:.2} M, search {:.3} s, total {:.3} s",
            scans.len(),
            boxes as f64 / n / 1e6,
            leaves as f64 / n / 1e6,
            search_s / n,
            total_s / n
        );
        return Ok(());
    }
    for i in scans {
        let scan = load(i)?;
        let truth = scan.truth;
        let r = localizer.localize_points(&scan.points)?;
        let in_set = r.candidates.iter().any(|c| acc.accepts(&c.pose, &truth));
        if in_set && failing_only {
            continue;
        }
        let (_, surf_o, seg_o) = localize::sensor::options_for_scan(
            o.sensor,
            &o.overrides,
            (&o.surfaces, &o.segments),
            &scan.points,
        );
        let cells = vertical_cells(&scan.points, &surf_o)?;
        let segments = extract_segments(&cells, &seg_o);
        let seg_len: f64 = segments.iter().map(|s| s.length()).sum();
        let n_yaw = ((360.0 / o.search.yaw_step_deg).round() as usize).max(1);
        let templates: Vec<Template> = (0..n_yaw)
            .map(|k| {
                let yaw = k as f64 * std::f64::consts::TAU / n_yaw as f64;
                build_template(&segments, yaw, &localizer.dt, localizer.pyramid.top())
            })
            .collect();
        // Searched as the pipeline searched it: over a car's headings for a car's scan.
        let car = o.vehicle.along_streets(r.sensor.as_ref());
        let heading = car.then(|| localizer.car_headings(&templates)).flatten();
        let (raw, _) = localizer.search_masked(&templates, heading.as_deref());
        let min = raw.first().map_or(0, |p| p.cost);
        // Best pose near the truth (exhaustive within 4 m and 0.2 rad).
        let (ti, tj) = localizer.dt.cell_of([truth.x, truth.y]);
        let mut near_best: Option<(u64, usize, i64, i64)> = None;
        let mut at_truth = u64::MAX;
        for (k, t) in templates.iter().enumerate() {
            if angle_diff(t.yaw_rad, truth.yaw_rad) > acc.max_rad {
                continue;
            }
            for dj in -9..=9 {
                for di in -9..=9 {
                    let p = localizer.dt.corner_of(ti + di, tj + dj);
                    let pose = Pose2 {
                        x: p[0],
                        y: p[1],
                        yaw_rad: t.yaw_rad,
                    };
                    if !acc.accepts(&pose, &truth) {
                        continue;
                    }
                    let c = pose_cost(&localizer.dt, t, ti + di, tj + dj);
                    if di == 0
                        && dj == 0
                        && angle_diff(t.yaw_rad, truth.yaw_rad) < 0.5f64.to_radians() + 1e-9
                    {
                        at_truth = at_truth.min(c);
                    }
                    if near_best.is_none_or(|b| c < b.0) {
                        near_best = Some((c, k, ti + di, tj + dj));
                    }
                }
            }
        }
        let near_ratio = near_best.map_or(f64::NAN, |b| b.0 as f64 / min.max(1) as f64);
        let near_truth = |p: &&localize::candidates::RawPose| {
            let xy = localizer.dt.corner_of(p.i, p.j);
            let pose = Pose2 {
                x: xy[0],
                y: xy[1],
                yaw_rad: templates[p.yaw_index].yaw_rad,
            };
            acc.accepts(&pose, &truth)
        };
        let raw_near = raw.iter().filter(near_truth).count();
        let raw_rank = raw.iter().position(|p| near_truth(&p));
        let sup = suppress(
            &raw,
            &templates,
            &localizer.dt,
            o.search.nms_radius_m,
            o.search.nms_yaw_rad,
        );
        let sup_near = sup.iter().filter(|c| acc.accepts(&c.pose, &truth)).count();
        let sup_close: Vec<String> = sup
            .iter()
            .filter(|c| c.pose.distance_to(&truth) < 8.0)
            .map(|c| {
                format!(
                    "({:.1} m {:.1}° dcm {:.3})",
                    c.pose.distance_to(&truth),
                    angle_diff(c.pose.yaw_rad, truth.yaw_rad).to_degrees(),
                    c.dcm
                )
            })
            .collect();
        let has_streets = !map.streets.segments.is_empty();
        let (kept, counts) = filter(
            sup.clone(),
            |_| (&index, has_streets),
            StreetFilter {
                distance_m: o.search.street_distance_m,
                along_rad: o
                    .vehicle
                    .along_streets(r.sensor.as_ref())
                    .then(|| o.search.along_street_deg.to_radians()),
            },
        );
        let kept_near = kept.iter().filter(|c| acc.accepts(&c.pose, &truth)).count();
        let truth_in_building = index.building_at([truth.x, truth.y]).is_some();
        let truth_street = index
            .nearest_segment([truth.x, truth.y])
            .map_or(f64::NAN, |(_, d)| d);
        let nearest = r.candidates.iter().enumerate().min_by(|a, b| {
            a.1.pose
                .distance_to(&truth)
                .total_cmp(&b.1.pose.distance_to(&truth))
        });
        let top = r.candidates.first();
        if let Some(c) = r.candidates.first() {
            println!("   top1 costs {:?} msg {:?}", c.costs, r.message);
        } else {
            println!("   msg {:?}", r.message);
        }
        println!(
            "{} {}: segs {} ({:.0} m), cells {}, in_set {} | min {} raw {} | near-truth best ratio {:.3} (at truth {:.3}) raw_near {} first rank {:?} | sup {} near {} | filt in_bldg {} far {} kept {} near {} | truth in bldg {} street {:.1} m | top1 {:?} | nearest cand {:?}",
            i, scan.name, segments.len(), seg_len, cells.len(), in_set, min, raw.len(),
            near_ratio, at_truth as f64 / min.max(1) as f64, raw_near, raw_rank, sup.len(), sup_near,
            counts.inside_building, counts.far_from_street, kept.len(), kept_near,
            truth_in_building, truth_street,
            top.map(|c| (format!("{:.1} m", c.pose.distance_to(&truth)), format!("{:.1}°", angle_diff(c.pose.yaw_rad, truth.yaw_rad).to_degrees()))),
            nearest.map(|(k, c)| (k, format!("{:.1} m", c.pose.distance_to(&truth)), format!("{:.1}°", angle_diff(c.pose.yaw_rad, truth.yaw_rad).to_degrees()))),
        );
        println!("   close after NMS: {}", sup_close.join(" "));
        let per_segment = |k: usize, i: i64, j: i64| -> String {
            let t = &templates[k];
            let dt = &localizer.dt;
            let pose = Pose2 {
                x: dt.corner_of(i, j)[0],
                y: dt.corner_of(i, j)[1],
                yaw_rad: t.yaw_rad,
            };
            segments
                .iter()
                .map(|sg| {
                    let one = build_template(std::slice::from_ref(sg), t.yaw_rad, dt, 0);
                    let c = pose_cost(dt, &one, i, j) as f64
                        / dt.units_per_m
                        / one.samples.max(1) as f64;
                    let m = sg.transformed(&pose);
                    format!(
                        "[{:.1} m @({:.0},{:.0}) {:.2}]",
                        sg.length(),
                        m.a[0],
                        m.a[1],
                        c
                    )
                })
                .collect::<Vec<_>>()
                .join(" ")
        };
        if let Some((_, k, i, j)) = near_best {
            println!("   near-best per segment: {}", per_segment(k, i, j));
        }
        if let Some(p) = raw.first() {
            println!(
                "   minimum per segment:   {}",
                per_segment(p.yaw_index, p.i, p.j)
            );
        }
        if let Ok(out) = std::env::var("DIAG_SVG") {
            let half = 80.0;
            let map_xy = |p: [f64; 2]| [p[0] - truth.x + half, half - (p[1] - truth.y)];
            let mut svg = format!("<svg xmlns='http://www.w3.org/2000/svg' width='800' height='800' viewBox='0 0 {} {}'><rect width='100%' height='100%' fill='white'/>", 2.0 * half, 2.0 * half);
            let line = |svg: &mut String, a: [f64; 2], b: [f64; 2], style: &str| {
                let (a, b) = (map_xy(a), map_xy(b));
                svg.push_str(&format!(
                    "<line x1='{:.2}' y1='{:.2}' x2='{:.2}' y2='{:.2}' style='{style}'/>",
                    a[0], a[1], b[0], b[1]
                ));
            };
            for e in &localizer.edges {
                if (e.a[0] - truth.x).abs() < half * 1.5 && (e.a[1] - truth.y).abs() < half * 1.5 {
                    line(&mut svg, e.a, e.b, "stroke:#bbb;stroke-width:0.4");
                }
            }
            for e in localizer.visible_from([truth.x, truth.y]) {
                line(&mut svg, e.a, e.b, "stroke:#000;stroke-width:0.5");
            }
            for c in &cells {
                let p = map_xy(truth.apply(c.xy));
                svg.push_str(&format!(
                    "<circle cx='{:.2}' cy='{:.2}' r='0.12' fill='#2a7'/>",
                    p[0], p[1]
                ));
            }
            for sg in &segments {
                let m = sg.transformed(&truth);
                line(
                    &mut svg,
                    m.a,
                    m.b,
                    "stroke:#d00;stroke-width:0.5;stroke-opacity:0.8",
                );
            }
            svg.push_str("</svg>");
            std::fs::write(format!("{out}/{i:03}.svg"), svg)?;
        }
    }
    Ok(())
}
