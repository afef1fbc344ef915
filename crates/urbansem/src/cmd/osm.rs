//! `urbansem osm …`: statistics of OpenStreetMap files.

use anyhow::Context;
use clap::Subcommand;
use geodata::osm::OsmMap;
use std::path::PathBuf;
use std::time::Instant;

/// Subcommands of `urbansem osm`.
#[derive(Subcommand)]
pub enum OsmCommand {
    /// Parse an .osm / .osm.pbf file and print its buildings, highways and street network.
    Info {
        /// The map file (.osm XML or .osm.pbf).
        map: PathBuf,
        /// Print one JSON object instead of a readable summary.
        #[arg(long)]
        json: bool,
    },
}

/// Runs one `urbansem osm` subcommand.
pub fn run(command: OsmCommand) -> anyhow::Result<()> {
    match command {
        OsmCommand::Info { map, json } => info(&map, json),
    }
}

fn info(path: &PathBuf, json: bool) -> anyhow::Result<()> {
    let start = Instant::now();
    let map = OsmMap::load(path).context("loading the map")?;
    let parse_s = start.elapsed().as_secs_f64();
    let s = &map.stats;
    let (origin_lat, origin_lon) = map.frame.origin();
    if json {
        let value = serde_json::json!({
            "file": path.display().to_string(),
            "buildings": map.building_count(),
            "highway_ways": s.highway_ways,
            "segments": map.streets.segments.len(),
            "intersections": map.streets.intersections.len(),
            "bbox": map.bbox_lonlat,
            "building_ways": s.building_ways,
            "building_relations": s.building_relations,
            "building_outlines": map.buildings.len(),
            "neighbour_pairs": map.streets.neighbour_pairs.len(),
            "street_length_m": map.streets.segments.iter().map(|x| x.length_m).sum::<f64>(),
            "nodes": s.nodes,
            "ways": s.ways,
            "relations": s.relations,
            "frame_origin_lat_lon": [origin_lat, origin_lon],
            "stats": s,
            "parse_seconds": parse_s,
        });
        println!("{}", serde_json::to_string_pretty(&value)?);
    } else {
        println!("{}", path.display());
        println!(
            "  elements        {} nodes, {} ways, {} relations",
            s.nodes, s.ways, s.relations
        );
        println!(
            "  bbox            lon {:.5}..{:.5}, lat {:.5}..{:.5}",
            map.bbox_lonlat[0], map.bbox_lonlat[2], map.bbox_lonlat[1], map.bbox_lonlat[3]
        );
        println!("  frame origin    lat {origin_lat:.6}, lon {origin_lon:.6}");
        println!(
            "  buildings       {} ({} closed ways + {} multipolygons) → {} outlines",
            map.building_count(),
            s.building_ways,
            s.building_relations,
            map.buildings.len()
        );
        println!("  highway ways    {}", s.highway_ways);
        println!(
            "  street network  {} segments ({:.1} km), {} intersections, {} neighbour pairs",
            map.streets.segments.len(),
            map.streets.segments.iter().map(|x| x.length_m).sum::<f64>() / 1000.0,
            map.streets.intersections.len(),
            map.streets.neighbour_pairs.len()
        );
        println!(
            "  skipped         buildings: {} missing nodes, {} degenerate, {} relations missing members, {} unclosed; highways: {} missing nodes, {} too short; {} open building ways",
            s.skipped_building_ways_missing_nodes,
            s.skipped_building_ways_degenerate,
            s.skipped_building_relations_missing_members,
            s.skipped_building_relations_unclosed,
            s.skipped_highway_ways_missing_nodes,
            s.skipped_highway_ways_too_short,
            s.open_building_ways
        );
        println!("  parse time      {parse_s:.3} s");
    }
    // The process ends here: freeing every outline and segment one by one would only cost time.
    std::mem::forget(map);
    Ok(())
}
