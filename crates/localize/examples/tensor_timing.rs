//! Times the distance-transform tensor and its lower-bound pyramid on a 2 km × 2 km window of
//! a real OSM extract (issue 6 target: ≤ 5 s on 2 cores; thesis: 35–155 s).
//!
//! `cargo run --release -p localize --example tensor_timing -- [MAP] [SIDE_M]`
//! (default `../shared/data/osm/monaco.osm.pbf`, 2000 m around the densest 1 km² cell).

use geodata::osm::OsmMap;
use localize::chamfer::{
    bounding_box, map_edges, BoundPyramid, ChamferOptions, DtTensor, IntegralDt,
};
use std::collections::HashMap;
use std::time::Instant;

/// CPU seconds (user + system) of this process so far, from `/proc/self/stat` (0 elsewhere).
fn cpu_s() -> f64 {
    let stat = std::fs::read_to_string("/proc/self/stat").unwrap_or_default();
    // Fields after the command name's closing parenthesis: utime and stime are the 12th and
    // 13th, in clock ticks (100 per second on Linux).
    let rest = stat.rsplit_once(')').map_or("", |(_, r)| r);
    let f: Vec<f64> = rest
        .split_whitespace()
        .map(|x| x.parse().unwrap_or(0.0))
        .collect();
    (f.get(11).copied().unwrap_or(0.0) + f.get(12).copied().unwrap_or(0.0)) / 100.0
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let path = args.next().unwrap_or_else(|| {
        concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../../../shared/data/osm/monaco.osm.pbf"
        )
        .into()
    });
    let side: f64 = args
        .next()
        .map(|s| s.parse())
        .transpose()?
        .unwrap_or(2000.0);
    let map = OsmMap::load(&path)?;
    let all = map_edges(&map);
    // The densest 1 km² cell (most edges) is the window's centre.
    let mut count: HashMap<(i64, i64), usize> = HashMap::new();
    for e in &all {
        *count
            .entry((
                (e.a[0] / 1000.0).floor() as i64,
                (e.a[1] / 1000.0).floor() as i64,
            ))
            .or_default() += 1;
    }
    let Some((&(cx, cy), _)) = count
        .iter()
        .max_by_key(|(k, n)| (**n, std::cmp::Reverse(**k)))
    else {
        return Err("the map has no building outlines".into());
    };
    let centre = [cx as f64 * 1000.0 + 500.0, cy as f64 * 1000.0 + 500.0];
    let h = side / 2.0;
    let edges: Vec<_> = all
        .into_iter()
        .filter(|e| {
            [e.a, e.b]
                .iter()
                .all(|p| (p[0] - centre[0]).abs() <= h && (p[1] - centre[1]).abs() <= h)
        })
        .collect();
    let (min, max) = bounding_box(&edges).ok_or("no edges in the window")?;
    let options = ChamferOptions::default();
    let (t, c) = (Instant::now(), cpu_s());
    let dt = DtTensor::build(&edges, &options)?;
    let (dt_s, dt_cpu) = (t.elapsed().as_secs_f64(), cpu_s() - c);
    let (t, c) = (Instant::now(), cpu_s());
    let pyr = BoundPyramid::build(&dt, 6);
    let (pyr_s, pyr_cpu) = (t.elapsed().as_secs_f64(), cpu_s() - c);
    let t = Instant::now();
    let idt = IntegralDt::build(&dt);
    let idt_s = t.elapsed().as_secs_f64();
    drop(idt);
    // On a shared machine the wall time depends on the load; the process CPU time does not
    // (its ratio to the thread count bounds the wall time on idle cores).
    println!(
        "CPU time (user + system, all threads): tensor {dt_cpu:.2} s, pyramid {pyr_cpu:.2} s; load average {}",
        std::fs::read_to_string("/proc/loadavg").unwrap_or_default().trim()
    );
    println!(
        "{path}: {} edges in {:.0} m × {:.0} m; tensor {}×{}×{} at {} m: {dt_s:.2} s ({:.0} MB), pyramid {pyr_s:.2} s ({:.0} MB), integral DTs {idt_s:.2} s; {} threads; thesis: 35–155 s → {:.0}–{:.0}× faster",
        edges.len(),
        max[0] - min[0],
        max[1] - min[1],
        dt.width,
        dt.height,
        dt.channels,
        dt.grid_m,
        dt.bytes() as f64 / 1e6,
        pyr.bytes() as f64 / 1e6,
        rayon::current_num_threads(),
        35.0 / dt_s,
        155.0 / dt_s
    );
    Ok(())
}
