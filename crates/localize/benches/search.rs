//! Criterion bench of the candidate search on the embedded default city (`geosim::city`,
//! seed 1) and a scan made of the map edges visible from a known pose on a street: the FDCM
//! branch and bound against exhaustive search (on a 20 m × 20 m window of poses, where
//! exhaustive search is affordable, and extrapolated per pose cell to the whole map) and
//! against the geometric-hashing baseline (Cham et al. 2010) over the whole map.
//! After criterion's report it prints the ratios, measured side by side in one run.
//!
//! `cargo bench -p localize --bench search`

// criterion_group! generates an undocumented public function; the inputs are built here from
// a fixed seed, so a failure to build them is a bug of the bench itself.
#![allow(missing_docs, clippy::expect_used)]
use criterion::{criterion_group, Criterion};
use geodata::osm::OsmMap;
use localize::candidates::{build_template, exhaustive_search, search, Domain, Masks, Template};
use localize::hashing::{CornerIndex, HashingOptions};
use localize::pipeline::{LocalizeOptions, Localizer};
use localize::{Pose2, Segment};
use std::time::Instant;

/// The prepared map, the scan's segments and everything the searches take.
struct Fixture<'m> {
    localizer: Localizer<'m>,
    segments: Vec<Segment>,
    templates: Vec<Template>,
    window: Domain,
    hashing: CornerIndex,
}

/// The scan: map edges of at least 2.5 m visible from the middle of the street segment
/// nearest the map's centre, heading 2 rad, in the sensor frame.
fn fixture(map: &OsmMap) -> Fixture<'_> {
    let localizer = Localizer::new(map, LocalizeOptions::default()).expect("map prepared");
    let (lo, hi) = localize::chamfer::bounding_box(&localizer.edges).expect("buildings");
    let centre = [(lo[0] + hi[0]) / 2.0, (lo[1] + hi[1]) / 2.0];
    let mid =
        |s: &geodata::osm::model::StreetSegment| [(s.a[0] + s.b[0]) / 2.0, (s.a[1] + s.b[1]) / 2.0];
    let dist = |p: [f64; 2]| (p[0] - centre[0]).hypot(p[1] - centre[1]);
    let p = map
        .streets
        .segments
        .iter()
        .map(mid)
        .min_by(|a, b| dist(*a).total_cmp(&dist(*b)))
        .expect("streets");
    let truth = Pose2 {
        x: p[0],
        y: p[1],
        yaw_rad: 2.0,
    };
    let (s, c) = truth.yaw_rad.sin_cos();
    let to_scan = |p: [f64; 2]| {
        let (dx, dy) = (p[0] - truth.x, p[1] - truth.y);
        [c * dx + s * dy, -s * dx + c * dy]
    };
    let segments: Vec<Segment> = localizer
        .visible_from(p)
        .iter()
        .filter(|v| v.length() >= 2.5)
        .map(|v| Segment::new(to_scan(v.a), to_scan(v.b)))
        .collect();
    let n = (360.0 / localizer.options.search.yaw_step_deg).round() as usize;
    let templates = (0..n)
        .map(|k| {
            let yaw = k as f64 * std::f64::consts::TAU / n as f64;
            build_template(&segments, yaw, &localizer.dt, localizer.pyramid.top())
        })
        .collect();
    // A 20 m × 20 m window of poses around the truth.
    let window = Domain::from_box(
        &localizer.dt,
        [truth.x - 10.0, truth.y - 10.0],
        [truth.x + 10.0, truth.y + 10.0],
    );
    let hashing = CornerIndex::new(map, &HashingOptions::default());
    Fixture {
        localizer,
        segments,
        templates,
        window,
        hashing,
    }
}

impl Fixture<'_> {
    fn branch_and_bound(&self, domain: Domain) -> usize {
        let l = &self.localizer;
        let (raw, _) = search(
            &l.dt,
            &l.pyramid,
            &self.templates,
            domain,
            Masks::feasible(l.feasible.as_ref()),
            l.options.search.keep_factor,
        );
        raw.len()
    }

    fn exhaustive(&self, domain: Domain) -> usize {
        let l = &self.localizer;
        exhaustive_search(
            &l.dt,
            &self.templates,
            domain,
            Masks::feasible(l.feasible.as_ref()),
            l.options.search.keep_factor,
        )
        .len()
    }

    fn hashing(&self) -> usize {
        self.hashing.localize(&self.segments).len()
    }
}

fn the_map() -> OsmMap {
    geosim::city::default_city_map().expect("the embedded city")
}

fn bench_search(c: &mut Criterion) {
    let map = the_map();
    let f = fixture(&map);
    let whole = f.localizer.domain;
    let mut group = c.benchmark_group("localize_search");
    group.sample_size(10);
    group.bench_function("fdcm_branch_and_bound/whole_map", |b| {
        b.iter(|| f.branch_and_bound(whole))
    });
    group.bench_function("fdcm_branch_and_bound/window_20m", |b| {
        b.iter(|| f.branch_and_bound(f.window))
    });
    group.bench_function("exhaustive/window_20m", |b| {
        b.iter(|| f.exhaustive(f.window))
    });
    group.bench_function("hashing/whole_map", |b| b.iter(|| f.hashing()));
    group.finish();
}

/// Median seconds of `reps` runs.
fn median_s(reps: usize, mut f: impl FnMut()) -> f64 {
    let mut v: Vec<f64> = (0..reps)
        .map(|_| {
            let t = Instant::now();
            f();
            t.elapsed().as_secs_f64()
        })
        .collect();
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// Side-by-side medians and their ratios.
fn print_ratios() {
    let map = the_map();
    let f = fixture(&map);
    let whole = f.localizer.domain;
    let bb_map = median_s(5, || {
        f.branch_and_bound(whole);
    });
    let bb_win = median_s(5, || {
        f.branch_and_bound(f.window);
    });
    let ex_win = median_s(3, || {
        f.exhaustive(f.window);
    });
    let hash = median_s(5, || {
        f.hashing();
    });
    let ex_map = ex_win * whole.cells() as f64 / f.window.cells() as f64;
    let l = &f.localizer;
    let same = search(
        &l.dt,
        &l.pyramid,
        &f.templates,
        f.window,
        Masks::feasible(l.feasible.as_ref()),
        l.options.search.keep_factor,
    )
    .0 == exhaustive_search(
        &l.dt,
        &f.templates,
        f.window,
        Masks::feasible(l.feasible.as_ref()),
        l.options.search.keep_factor,
    );
    let grid = l.dt.grid_m;
    println!(
        "localize search on the embedded default city, {} scan segments, {} yaws, {:.2} km² of poses:",
        f.segments.len(),
        f.templates.len(),
        whole.cells() as f64 * grid * grid / 1e6
    );
    println!(
        "  20 m window: branch and bound {bb_win:.4} s, exhaustive {ex_win:.3} s: ratio exhaustive / B&B {:.0}× (same poses: {same})",
        ex_win / bb_win
    );
    println!(
        "  whole map:   branch and bound {bb_map:.4} s, exhaustive extrapolated per pose cell {ex_map:.0} s: ratio {:.0}×",
        ex_map / bb_map
    );
    println!(
        "  whole map:   geometric hashing {hash:.4} s: ratio B&B / hashing {:.2}",
        bb_map / hash
    );
}

criterion_group!(benches, bench_search);

fn main() {
    benches();
    Criterion::default().configure_from_args().final_summary();
    print_ratios();
}
