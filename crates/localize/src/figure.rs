//! Pictures of localization results in the map's frame: one scan's result (map outlines,
//! the edges visible from the chosen pose, the scan's walls at it, the candidates, the truth)
//! and a track (the drive, every scan's candidates and chosen pose).

use crate::pipeline::{Localization, Localizer};
use crate::Accuracy;
use crate::{Pose2, Segment};
use geodata::osm::OsmMap;
use geodata::svg::Svg;

/// A figure of one result: map outlines (grey), edges visible from the chosen pose (black),
/// scan segments at the chosen pose (red), candidates (blue; the best larger), truth (green).
pub fn result_svg(
    localizer: &Localizer<'_>,
    result: &Localization,
    truth: Option<Pose2>,
    half_m: f64,
) -> String {
    let centre = result
        .candidates
        .first()
        .map(|c| [c.pose.x, c.pose.y])
        .or(truth.map(|t| [t.x, t.y]))
        .unwrap_or([0.0, 0.0]);
    let (min, max) = (
        [centre[0] - half_m, centre[1] - half_m],
        [centre[0] + half_m, centre[1] + half_m],
    );
    let mut svg = Svg::new(600.0, min, max);
    for b in &localizer.map.buildings {
        if b.outer
            .iter()
            .any(|p| p[0] > min[0] && p[0] < max[0] && p[1] > min[1] && p[1] < max[1])
        {
            svg.polygon(&b.outer, "fill:#e6e0d4;stroke:#9a9a9a;stroke-width:1");
        }
    }
    for s in &localizer.map.streets.segments {
        svg.polyline(&[s.a, s.b], "stroke:#ffffff;stroke-width:2");
    }
    if let Some(best) = result.candidates.first() {
        for v in localizer.visible_from([best.pose.x, best.pose.y]) {
            svg.polyline(&[v.a, v.b], "stroke:#222;stroke-width:2");
        }
        for s in &result.segments {
            let m: Segment = s.transformed(&best.pose);
            svg.polyline(
                &[m.a, m.b],
                "stroke:#d62728;stroke-width:2.5;stroke-opacity:0.85",
            );
        }
    }
    for c in result.candidates.iter().skip(1).take(200) {
        svg.circle([c.pose.x, c.pose.y], 3.0, "fill:#6baed6;fill-opacity:0.7");
    }
    if let Some(t) = truth {
        svg.circle([t.x, t.y], 6.0, "fill:none;stroke:#2ca02c;stroke-width:2.5");
    }
    if let Some(best) = result.candidates.first() {
        svg.circle([best.pose.x, best.pose.y], 5.0, "fill:#1f4e9c");
        let tip = best.pose.apply([8.0, 0.0]);
        svg.polyline(
            &[[best.pose.x, best.pose.y], tip],
            "stroke:#1f4e9c;stroke-width:2",
        );
    }
    svg.scale_bar(20.0);
    svg.finish()
}

/// The track figure: the map around the drive, the true track, every scan's candidates and
/// chosen pose.
pub fn track_svg(
    map: &OsmMap,
    truths: &[Pose2],
    results: &[Localization],
    accuracy: &Accuracy,
    window: usize,
) -> String {
    let mut min = [f64::INFINITY; 2];
    let mut max = [f64::NEG_INFINITY; 2];
    for t in truths {
        for k in 0..2 {
            let v = [t.x, t.y][k];
            min[k] = min[k].min(v);
            max[k] = max[k].max(v);
        }
    }
    let half = ((max[0] - min[0]).max(max[1] - min[1]) / 2.0 + 60.0).max(80.0);
    let centre = [(min[0] + max[0]) / 2.0, (min[1] + max[1]) / 2.0];
    let (min, max) = (
        [centre[0] - half, centre[1] - half],
        [centre[0] + half, centre[1] + half],
    );
    let inside = |p: &[f64; 2]| p[0] > min[0] && p[0] < max[0] && p[1] > min[1] && p[1] < max[1];
    let mut svg = Svg::new(640.0, min, max);
    for b in &map.buildings {
        if b.outer.iter().any(inside) {
            svg.polygon(&b.outer, "fill:#e6e0d4;stroke:#9a9a9a;stroke-width:1");
        }
    }
    for s in &map.streets.segments {
        if inside(&s.a) || inside(&s.b) {
            svg.polyline(&[s.a, s.b], "stroke:#bbbbbb;stroke-width:1.5");
        }
    }
    let track: Vec<[f64; 2]> = truths.iter().map(|t| [t.x, t.y]).collect();
    svg.polyline(
        &track,
        "fill:none;stroke:#2ca02c;stroke-width:3;stroke-opacity:0.8",
    );
    for r in results {
        for c in r.candidates.iter().skip(1).take(9) {
            svg.circle([c.pose.x, c.pose.y], 2.5, "fill:#6baed6;fill-opacity:0.7");
        }
    }
    for (i, (r, t)) in results.iter().zip(truths).enumerate() {
        let Some(best) = r.candidates.first() else {
            continue;
        };
        let p = [best.pose.x, best.pose.y];
        svg.polyline(&[p, [t.x, t.y]], "stroke:#555;stroke-width:0.8");
        let colour = if accuracy.accepts(&best.pose, t) {
            "#1f4e9c"
        } else {
            "#d62728"
        };
        svg.circle(p, 4.0, &format!("fill:{colour}"));
        svg.polyline(
            &[p, best.pose.apply([8.0, 0.0])],
            &format!("stroke:{colour};stroke-width:2"),
        );
        if i + 1 < window {
            svg.circle(p, 7.0, &format!("fill:none;stroke:{colour};stroke-width:1"));
        }
    }
    svg.scale_bar(50.0);
    svg.finish()
}
