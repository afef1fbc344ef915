//! Demo stage: the embedded default city.

use crate::{DemoArgs, StageOutput};
use anyhow::Context;
use geodata::svg::Svg;
use serde::Serialize;
use std::time::Instant;

/// The city stage's summary entry (`city` in `summary.json`).
#[derive(Debug, Clone, Serialize)]
pub struct CitySummary {
    /// Buildings (ways and multipolygons).
    pub buildings: usize,
    /// Highway ways.
    pub highway_ways: usize,
    /// Street segments between intersections.
    pub segments: usize,
    /// Intersections.
    pub intersections: usize,
    /// Pairs of neighbouring segments.
    pub neighbour_pairs: usize,
    /// Total street length, metres.
    pub street_length_m: f64,
    /// Latitude and longitude of the local frame's origin.
    pub frame_origin_lat_lon: [f64; 2],
    /// Bounding box: west, south, east, north.
    pub bbox_lonlat: [f64; 4],
    /// Seconds generating the city as OSM XML and parsing it back.
    pub seconds_generate_and_parse: f64,
}

/// The demo stage of the embedded default city: its numbers and a map of buildings and streets.
pub fn stage(_args: &DemoArgs) -> anyhow::Result<StageOutput> {
    let t = Instant::now();
    let map = geosim::city::default_city_map().context("generating the embedded default city")?;
    let generate_s = t.elapsed().as_secs_f64();
    let (mut min, mut max) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
    let points = map
        .buildings
        .iter()
        .flat_map(|b| b.outer.iter())
        .chain(map.highways.iter().flat_map(|h| h.points.iter()));
    for p in points {
        for k in 0..2 {
            min[k] = min[k].min(p[k]);
            max[k] = max[k].max(p[k]);
        }
    }
    if !min[0].is_finite() {
        anyhow::bail!("the embedded default city is empty");
    }
    let margin = 10.0;
    let mut svg = Svg::new(
        900.0,
        [min[0] - margin, min[1] - margin],
        [max[0] + margin, max[1] + margin],
    );
    for b in &map.buildings {
        svg.polygon(
            &b.outer,
            "fill:#c98c3c;fill-opacity:0.85;stroke:#7a5020;stroke-width:0.6",
        );
        for inner in &b.inners {
            svg.polygon(inner, "fill:#f4f1ea;stroke:#7a5020;stroke-width:0.6");
        }
    }
    let ppm = svg.pixels_per_metre();
    let style_of = |highway: &str| match highway {
        "primary" | "trunk" => (9.0, "#e8a03c"),
        "secondary" | "tertiary" => (7.0, "#f2cf5b"),
        "residential" | "unclassified" | "living_street" => (5.5, "#ffffff"),
        "service" => (3.5, "#ffffff"),
        _ => (1.5, "#d86a6a"),
    };
    // Casing first (grey, wider), then the fill colour, so light streets stay visible.
    for casing in [true, false] {
        for h in &map.highways {
            let (width_m, colour) = style_of(&h.highway);
            let width_px = (width_m * ppm).max(1.0);
            let style = if casing {
                format!(
                    "stroke:#8a8a8a;stroke-width:{:.1};stroke-linecap:round;stroke-linejoin:round",
                    width_px + 1.6
                )
            } else {
                format!(
                    "stroke:{colour};stroke-width:{width_px:.1};stroke-linecap:round;stroke-linejoin:round"
                )
            };
            svg.polyline(&h.points, &style);
        }
    }
    for i in &map.streets.intersections {
        svg.circle(i.position, 2.0, "fill:#3050c0");
    }
    svg.scale_bar(100.0);
    let city_svg = svg.finish();
    let street_m: f64 = map.streets.segments.iter().map(|s| s.length_m).sum();
    let (lat0, lon0) = map.frame.origin();
    Ok(StageOutput {
        key: "city",
        summary: serde_json::to_value(CitySummary {
            buildings: map.building_count(),
            highway_ways: map.highways.len(),
            segments: map.streets.segments.len(),
            intersections: map.streets.intersections.len(),
            neighbour_pairs: map.streets.neighbour_pairs.len(),
            street_length_m: street_m,
            frame_origin_lat_lon: [lat0, lon0],
            bbox_lonlat: map.bbox_lonlat,
            seconds_generate_and_parse: generate_s,
        })?,
        title: "The embedded default city (procedural OSM map)",
        text_html: format!(
            "{} buildings, {} highway ways split into {} segments ({:.1} km of street), \
             {} intersections (blue), {} neighbouring segment pairs; generated as OSM XML and \
             parsed back in {:.3} s. Streets are drawn by type (primary orange, secondary yellow, \
             residential and service white, footways red).",
            map.building_count(),
            map.highways.len(),
            map.streets.segments.len(),
            street_m / 1000.0,
            map.streets.intersections.len(),
            map.streets.neighbour_pairs.len(),
            generate_s
        ),
        files: vec![("city.svg", city_svg.clone().into_bytes())],
        figures: vec![city_svg],
    })
}
