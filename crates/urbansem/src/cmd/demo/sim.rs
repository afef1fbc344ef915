//! Demo stage of the simulator: scans of the embedded default city.

use super::{DemoArgs, StageOutput};
use anyhow::Context;
use geosim::scene::{MapErrorOptions, Scene, SceneOptions};
use geosim::sensor::{scan_with, ScanFrame, SensorOptions};
use std::time::Instant;

/// The demo's simulator stage: scans on the embedded default city, a map and a scan top view.
pub(super) fn stage(args: &DemoArgs) -> anyhow::Result<StageOutput> {
    use crate::report::{encode_png_rgb, Html};
    use geodata::classes::Class;
    use geodata::svg::Svg;
    use serde_json::json;

    let map = geosim::city::default_city_map().context("generating the embedded default city")?;
    let options = SceneOptions {
        map_error: MapErrorOptions::osm_like(),
        ..SceneOptions::default()
    };
    let scene = Scene::build(&map, &options, args.seed).context("building the scene")?;
    let poses = scene
        .sample_sidewalk_poses(6, args.seed)
        .context("placing scanner poses")?;
    let sensor = SensorOptions::default();
    let started = Instant::now();
    let mut clouds = Vec::new();
    let mut rays = 0;
    for (i, pose) in poses.iter().enumerate() {
        let (cloud, stats) = scan_with(
            &scene,
            pose,
            &sensor,
            args.seed + i as u64,
            ScanFrame::World,
        )
        .context("scanning")?;
        rays += stats.rays;
        clouds.push(cloud);
    }
    let cast_seconds = started.elapsed().as_secs_f64();
    let mut histogram = [0usize; Class::COUNT];
    for cloud in &clouds {
        for (k, n) in cloud.class_histogram().iter().enumerate() {
            histogram[k] += n;
        }
    }
    let points: usize = histogram.iter().sum();

    // The figures show the scan that sees most building points.
    let building_points = |c: &geodata::cloud::PointCloud| {
        c.label.as_deref().map_or(0, |l| {
            l.iter().filter(|&&v| v == Class::Building.id()).count()
        })
    };
    let shown = (0..clouds.len())
        .max_by_key(|&i| (building_points(&clouds[i]), std::cmp::Reverse(i)))
        .unwrap_or(0);
    // Map around that pose: true streets and sidewalks, world buildings, map outlines.
    let centre = [poses[shown].position[0], poses[shown].position[1]];
    let half = 110.0;
    let (min, max) = (
        [centre[0] - half, centre[1] - half],
        [centre[0] + half, centre[1] + half],
    );
    let mut svg = Svg::new(700.0, min, max);
    let ppm = svg.pixels_per_metre();
    for (seg, t) in scene.segments.iter().zip(&scene.truth) {
        if !t.on_ground {
            continue;
        }
        let line = geosim::truth::offset_centre_line(seg, t);
        let sidewalk_px = (t.width_m + 2.0 * if t.drivable { t.sidewalk_m } else { 0.0 }) * ppm;
        svg.polyline(
            &line,
            &format!("stroke:#c8c6c2;stroke-width:{sidewalk_px:.1};stroke-linecap:round"),
        );
    }
    for (seg, t) in scene.segments.iter().zip(&scene.truth) {
        if t.on_ground && t.drivable {
            let line = geosim::truth::offset_centre_line(seg, t);
            svg.polyline(
                &line,
                &format!(
                    "stroke:#5a5a62;stroke-width:{:.1};stroke-linecap:round",
                    t.width_m * ppm
                ),
            );
        }
    }
    for b in &scene.buildings {
        svg.polygon(&b.outer, "fill:#c98c3c;fill-opacity:0.85;stroke:none");
    }
    for b in &map.buildings {
        svg.polygon(
            &b.outer,
            "fill:none;stroke:#d02020;stroke-width:0.8;stroke-dasharray:3,2",
        );
    }
    for o in &scene.objects {
        let [r, g, b] = o.class.color_rgb();
        let (sn, cs) = o.yaw_rad.sin_cos();
        let [hx, hy, _] = o.half_extents;
        let corners: Vec<[f64; 2]> = [[-hx, -hy], [hx, -hy], [hx, hy], [-hx, hy]]
            .iter()
            .map(|q| {
                [
                    o.centre[0] + cs * q[0] - sn * q[1],
                    o.centre[1] + sn * q[0] + cs * q[1],
                ]
            })
            .collect();
        svg.polygon(
            &corners,
            &format!("fill:rgb({r},{g},{b});fill-opacity:0.8;stroke:none"),
        );
    }
    for p in &poses {
        let (s, c) = p.yaw_rad.sin_cos();
        svg.polyline(
            &[
                [p.position[0], p.position[1]],
                [p.position[0] + 8.0 * c, p.position[1] + 8.0 * s],
            ],
            "stroke:#1040c0;stroke-width:2",
        );
        svg.circle([p.position[0], p.position[1]], 4.0, "fill:#1040c0");
    }
    svg.scale_bar(50.0);
    let map_svg = svg.finish();

    // Top view of the first scan, coloured by class (the highest point per pixel wins).
    let side = 640usize;
    let metres_per_px = 80.0 / side as f64;
    let mut top = vec![f64::NEG_INFINITY; side * side];
    let mut rgb = vec![255u8; side * side * 3];
    let cloud = &clouds[shown];
    let labels = cloud.label.as_deref().unwrap_or(&[]);
    for (p, &l) in cloud.positions.iter().zip(labels) {
        let x = ((p[0] - centre[0]) / metres_per_px + side as f64 / 2.0).floor();
        let y = (side as f64 / 2.0 - (p[1] - centre[1]) / metres_per_px).floor();
        if x < 0.0 || y < 0.0 || x >= side as f64 || y >= side as f64 {
            continue;
        }
        let i = y as usize * side + x as usize;
        if p[2] > top[i] {
            top[i] = p[2];
            let c = Class::from_id(l).unwrap_or(Class::Unlabelled).color_rgb();
            rgb[3 * i..3 * i + 3].copy_from_slice(&c);
        }
    }
    let png = encode_png_rgb(side as u32, side as u32, &rgb)?;
    let legend: String = Class::ALL[1..]
        .iter()
        .map(|c| {
            let [r, g, b] = c.color_rgb();
            format!(
                r#"<span style="display:inline-block;width:10px;height:10px;background:rgb({r},{g},{b})"></span> {} "#,
                c.name()
            )
        })
        .collect();
    let rays_per_second = rays as f64 / cast_seconds.max(1e-9);
    let class_counts: serde_json::Map<String, serde_json::Value> = Class::ALL
        .iter()
        .map(|c| (c.name().to_string(), json!(histogram[c.id() as usize])))
        .collect();
    Ok(StageOutput {
        key: "simulator",
        summary: json!({
            "scans": clouds.len(),
            "rays": rays,
            "points": points,
            "cast_seconds": cast_seconds,
            "rays_per_second": rays_per_second,
            "objects": scene.objects.len(),
            "map_error": {
                "removed_buildings": scene.map_error.removed.len(),
                "extra_buildings": scene.map_error.extra,
                "mean_shift_m": scene.map_error.mean_shift_m,
            },
            "points_per_class": class_counts,
        }),
        title: "geodata: simulated laser scans with ground truth",
        text_html: format!(
            "The world built from the map: true street areas (dark: driving area, light: \
             sidewalks; offset and width per segment), buildings as they are in the world \
             (filled) against the map's outlines (dashed red: the OSM map-error model shifted \
             them by {:.2} m on average, removed {} and added {}), and {} clutter objects the map \
             does not have (cars, trees, poles, bicycles, pedestrians, construction fences). \
             Blue: {} scanner poses on sidewalks. {} rays cast in {:.2} s \
             (<b>{:.2} M rays/s</b>), {} labelled points. Right: top view of the scan at the centre of the map \
             (80 m × 80 m), coloured by label: {}",
            scene.map_error.mean_shift_m,
            scene.map_error.removed.len(),
            scene.map_error.extra,
            scene.objects.len(),
            clouds.len(),
            rays,
            cast_seconds,
            rays_per_second / 1e6,
            points,
            legend
        ),
        figures: vec![
            map_svg.clone(),
            Html::png_img(&png, "top view of a simulated scan", side as u32),
        ],
        files: vec![
            ("sim-map.svg", map_svg.into_bytes()),
            ("sim-scan-top.png", png),
        ],
    })
}
