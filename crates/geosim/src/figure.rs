//! A picture of a simulated world around a point: the true street areas (driving area dark,
//! sidewalks light), the world's buildings (filled) against the map's outlines (dashed red),
//! the clutter objects in their class colours, and scanner poses.

use crate::scene::{Pose, Scene};
use crate::truth::offset_centre_line;
use geodata::osm::OsmMap;
use geodata::svg::Svg;

/// The world of `scene` within `half_m` of `centre` with `map`'s outlines and `poses`, as SVG.
pub fn scene_svg(
    scene: &Scene,
    map: &OsmMap,
    poses: &[Pose],
    centre: [f64; 2],
    half_m: f64,
) -> String {
    let (min, max) = (
        [centre[0] - half_m, centre[1] - half_m],
        [centre[0] + half_m, centre[1] + half_m],
    );
    let mut svg = Svg::new(700.0, min, max);
    let ppm = svg.pixels_per_metre();
    for (seg, t) in scene.segments.iter().zip(&scene.truth) {
        if !t.on_ground {
            continue;
        }
        let line = offset_centre_line(seg, t);
        let sidewalk_px = (t.width_m + 2.0 * if t.drivable { t.sidewalk_m } else { 0.0 }) * ppm;
        svg.polyline(
            &line,
            &format!("stroke:#c8c6c2;stroke-width:{sidewalk_px:.1};stroke-linecap:round"),
        );
    }
    for (seg, t) in scene.segments.iter().zip(&scene.truth) {
        if t.on_ground && t.drivable {
            let line = offset_centre_line(seg, t);
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
    for p in poses {
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
    svg.finish()
}
