//! Demo stage of the simulator: scans of the embedded default city.

use crate::{DemoArgs, StageOutput};
use anyhow::Context;
use geosim::scene::{MapErrorOptions, Scene, SceneOptions};
use geosim::sensor::{scan_with, ScanFrame, SensorOptions};
use serde::Serialize;
use std::collections::BTreeMap;
use std::time::Instant;

/// What the OSM map-error model did to the map.
#[derive(Debug, Clone, Serialize)]
pub struct MapErrorSummary {
    /// Map buildings removed from the world.
    pub removed_buildings: usize,
    /// World buildings the map does not have.
    pub extra_buildings: usize,
    /// Mean displacement of the map's outlines, metres.
    pub mean_shift_m: f64,
}

/// The simulator stage's summary entry (`simulator` in `summary.json`).
#[derive(Debug, Clone, Serialize)]
pub struct SimSummary {
    /// Scans simulated.
    pub scans: usize,
    /// Rays cast.
    pub rays: usize,
    /// Labelled points.
    pub points: usize,
    /// Seconds ray casting.
    pub cast_seconds: f64,
    /// Rays per second.
    pub rays_per_second: f64,
    /// Clutter objects in the world.
    pub objects: usize,
    /// The map-error model's changes.
    pub map_error: MapErrorSummary,
    /// Points per class name.
    pub points_per_class: BTreeMap<String, usize>,
}

/// The demo's simulator stage: scans on the embedded default city, a map and a scan top view.
pub fn stage(args: &DemoArgs) -> anyhow::Result<StageOutput> {
    use crate::report::{encode_png_rgb, Html};
    use geodata::classes::Class;
    use geodata::topview::TopView;

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
    let map_svg = geosim::figure::scene_svg(&scene, &map, &poses, centre, 110.0);

    // Top view of the first scan, coloured by class (the highest point per pixel wins).
    let side = 640usize;
    let mut view = TopView::new(centre, 80.0 / side as f64, side, [255; 3]);
    let cloud = &clouds[shown];
    let labels = cloud.label.as_deref().unwrap_or(&[]);
    for (p, &l) in cloud.positions.iter().zip(labels) {
        view.plot(
            *p,
            Class::from_id(l).unwrap_or(Class::Unlabelled).color_rgb(),
        );
    }
    let png = encode_png_rgb(side as u32, side as u32, view.rgb())?;
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
    let class_counts: BTreeMap<String, usize> = Class::ALL
        .iter()
        .map(|c| (c.name().to_string(), histogram[c.id() as usize]))
        .collect();
    Ok(StageOutput {
        key: "simulator",
        summary: serde_json::to_value(SimSummary {
            scans: clouds.len(),
            rays,
            points,
            cast_seconds,
            rays_per_second,
            objects: scene.objects.len(),
            map_error: MapErrorSummary {
                removed_buildings: scene.map_error.removed.len(),
                extra_buildings: scene.map_error.extra,
                mean_shift_m: scene.map_error.mean_shift_m,
            },
            points_per_class: class_counts,
        })?,
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
