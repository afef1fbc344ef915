//! `urbansem sim bench`: the scan simulator's scene building and ray casting, rays per second
//! (issue target ≥ 1 M rays/s).

use anyhow::Context;
use geodata::osm::OsmMap;
use geosim::scene::{Scene, SceneOptions};
use geosim::sensor::{scan_with, ScanFrame, SensorOptions};
use std::path::Path;
use std::time::Instant;

/// Result of the simulator benchmark.
#[derive(serde::Serialize)]
pub struct SimBench {
    /// The map.
    pub map: String,
    /// Seconds building the scene.
    pub scene_seconds: f64,
    /// Shapes in the scene.
    pub shapes: usize,
    /// Scans cast.
    pub scans: usize,
    /// Rays cast.
    pub rays: usize,
    /// Points returned.
    pub points: usize,
    /// Seconds casting.
    pub cast_seconds: f64,
    /// Rays per second.
    pub rays_per_second: f64,
    /// Worker threads.
    pub threads: usize,
}

/// Times scene building and `scans` default scans from sidewalk poses.
pub fn measure(map: &OsmMap, name: &str, scans: usize, seed: u64) -> anyhow::Result<SimBench> {
    let t = Instant::now();
    let scene = Scene::build(map, &SceneOptions::default(), seed).context("building the scene")?;
    let scene_seconds = t.elapsed().as_secs_f64();
    let poses = scene
        .sample_sidewalk_poses(scans, seed)
        .context("placing scanner poses")?;
    let sensor = SensorOptions::default();
    let t = Instant::now();
    let (mut rays, mut points) = (0, 0);
    for (i, pose) in poses.iter().enumerate() {
        let (_, stats) = scan_with(&scene, pose, &sensor, seed + i as u64, ScanFrame::World)
            .context("scanning")?;
        rays += stats.rays;
        points += stats.points;
    }
    let cast_seconds = t.elapsed().as_secs_f64();
    Ok(SimBench {
        map: name.to_string(),
        scene_seconds,
        shapes: scene.shape_count(),
        scans: poses.len(),
        rays,
        points,
        cast_seconds,
        rays_per_second: rays as f64 / cast_seconds.max(1e-9),
        threads: rayon::current_num_threads(),
    })
}

/// Runs `urbansem sim bench`: scene building and scan simulation on a map (default: the
/// embedded city), rays per second.
pub fn bench_sim(map: Option<&Path>, scans: usize, seed: u64, json: bool) -> anyhow::Result<()> {
    let (map, name) = match map {
        Some(path) => (
            OsmMap::load(path).with_context(|| format!("loading the map {}", path.display()))?,
            path.display().to_string(),
        ),
        None => (
            geosim::city::default_city_map().context("generating the embedded default city")?,
            "embedded default city".to_string(),
        ),
    };
    let b = measure(&map, &name, scans, seed)?;
    if json {
        println!("{}", serde_json::to_string_pretty(&b)?);
    } else {
        println!(
            "{}: scene with {} shapes built in {:.2} s; {} scans, {:.1} M rays, {} points in {:.2} s on {} threads: {:.2} M rays/s (target ≥ 1.0)",
            b.map,
            b.shapes,
            b.scene_seconds,
            b.scans,
            b.rays as f64 / 1e6,
            b.points,
            b.cast_seconds,
            b.threads,
            b.rays_per_second / 1e6
        );
    }
    Ok(())
}
