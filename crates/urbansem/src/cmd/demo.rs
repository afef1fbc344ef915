//! `urbansem demo`: every capability that exists so far, on embedded default data, with a
//! report in `demo-out/` (`summary.json`, `index.html` with figures).

use crate::report::{encode_png_rgb, Html, Svg};
use anyhow::Context;
use clap::Args;
use indicatif::{ProgressBar, ProgressStyle};
use pbo::polynomial::{Literal, Polynomial};
use pbo::qpbo::{Label, Qpbo};
use pbo::qssr::{solve, QssrOptions};
use pbo::quadratize::Quadratizer;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde_json::{json, Map, Value};
use std::path::PathBuf;
use std::time::Instant;

/// Options of `urbansem demo`.
#[derive(Args)]
pub struct DemoArgs {
    /// Output folder for summary.json and index.html.
    #[arg(long, default_value = "demo-out")]
    pub out: PathBuf,
    /// Seed of every random step (same seed, same report numbers).
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
}

/// One stage's contribution: its summary entry and its report section.
pub(crate) struct StageOutput {
    /// Key of the stage's entry in `summary.json`.
    pub(crate) key: &'static str,
    /// The stage's entry in `summary.json` (an object; its timings move to `timings.json`).
    pub(crate) summary: Value,
    /// Section title in `index.html`.
    pub(crate) title: &'static str,
    /// Section text (HTML).
    pub(crate) text_html: String,
    /// Inline figures (HTML: `<svg>` or `<img>`).
    pub(crate) figures: Vec<String>,
    /// Figures also written as files into the output folder: (file name, bytes).
    pub(crate) files: Vec<(&'static str, Vec<u8>)>,
}

type Stage = fn(&DemoArgs) -> anyhow::Result<StageOutput>;

/// Runs the demo.
pub fn run(args: DemoArgs) -> anyhow::Result<()> {
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("creating the output folder {}", args.out.display()))?;
    let stages: [(&str, Stage); 9] = [
        ("geodata: embedded default city", stage_city),
        ("geodata: simulated scans", crate::cmd::sim::demo_stage),
        ("pbo: binary image denoising (QPBO)", stage_denoise),
        (
            "pbo: higher-order functions (QSSR per quadratizer)",
            stage_higher_order,
        ),
        ("mln: MAP on the thesis' synthetic problems", stage_mln),
        (
            "streets: widths and offsets",
            crate::cmd::streets::demo_stage,
        ),
        (
            "localize: one scan on the map",
            crate::cmd::localize::demo_stage,
        ),
        (
            "localize: a car-LiDAR drive along its track",
            crate::cmd::localize::demo_track_stage,
        ),
        (
            "srtree: semantic map and spatial relations",
            crate::cmd::srtree::demo_stage,
        ),
    ];
    let bar = ProgressBar::new(stages.len() as u64);
    bar.set_style(
        ProgressStyle::with_template("{bar:30} {pos}/{len} {msg} [{elapsed}]")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    let t0 = Instant::now();
    let mut summary = Map::new();
    let mut timings = Map::new();
    let mut html = Html::default();
    for (name, stage) in stages {
        bar.set_message(name);
        let t = Instant::now();
        let out = stage(&args).with_context(|| format!("demo stage {name:?}"))?;
        let mut entry = out.summary;
        let mut stage_timings = take_timings(&mut entry).unwrap_or_else(|| json!({}));
        if let Value::Object(m) = &mut stage_timings {
            m.insert("seconds".into(), json!(t.elapsed().as_secs_f64()));
        }
        summary.insert(out.key.into(), entry);
        timings.insert(out.key.into(), stage_timings);
        html.section(out.title, &out.text_html, &out.figures);
        for (name, bytes) in &out.files {
            let path = args.out.join(name);
            geodata::fsio::write_atomic(&path, bytes)
                .with_context(|| format!("writing {}", path.display()))?;
        }
        bar.inc(1);
    }
    bar.finish_and_clear();
    summary.insert("seed".into(), json!(args.seed));
    timings.insert("seconds_total".into(), json!(t0.elapsed().as_secs_f64()));
    let summary_path = args.out.join("summary.json");
    geodata::fsio::write_atomic(
        &summary_path,
        serde_json::to_string_pretty(&Value::Object(summary))? + "\n",
    )
    .with_context(|| format!("writing {}", summary_path.display()))?;
    // Timings change from run to run; they live apart so that every other file is the same
    // bytes for the same seed.
    let timings_path = args.out.join("timings.json");
    geodata::fsio::write_atomic(
        &timings_path,
        serde_json::to_string_pretty(&Value::Object(timings))? + "\n",
    )
    .with_context(|| format!("writing {}", timings_path.display()))?;
    let html_path = args.out.join("index.html");
    geodata::fsio::write_atomic(&html_path, html.finish("urbansem demo"))
        .with_context(|| format!("writing {}", html_path.display()))?;
    println!(
        "demo finished in {:.1} s: {} and {}",
        t0.elapsed().as_secs_f64(),
        summary_path.display(),
        html_path.display()
    );
    Ok(())
}

/// Whether a summary key holds a timing (seconds, or a rate per second).
fn is_timing_key(key: &str) -> bool {
    key.contains("second") || key.ends_with("_s") || key.ends_with("_per_s")
}

/// Moves every timing out of `value` into the returned value, keeping the nesting (arrays
/// keep their length, with `null` where an element had none); `None` when there was none.
fn take_timings(value: &mut Value) -> Option<Value> {
    match value {
        Value::Object(m) => {
            let mut taken = Map::new();
            let keys: Vec<String> = m.keys().cloned().collect();
            for key in keys {
                if is_timing_key(&key) {
                    if let Some(v) = m.remove(&key) {
                        taken.insert(key, v);
                    }
                } else if let Some(sub) = m.get_mut(&key).and_then(take_timings) {
                    taken.insert(key, sub);
                }
            }
            (!taken.is_empty()).then_some(Value::Object(taken))
        }
        Value::Array(items) => {
            let taken: Vec<Value> = items
                .iter_mut()
                .map(|v| take_timings(v).unwrap_or(Value::Null))
                .collect();
            taken
                .iter()
                .any(|v| !v.is_null())
                .then_some(Value::Array(taken))
        }
        _ => None,
    }
}

fn stage_city(_args: &DemoArgs) -> anyhow::Result<StageOutput> {
    let t = Instant::now();
    let map = geodata::city::default_city_map().context("generating the embedded default city")?;
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
        summary: json!({
            "buildings": map.building_count(),
            "highway_ways": map.highways.len(),
            "segments": map.streets.segments.len(),
            "intersections": map.streets.intersections.len(),
            "neighbour_pairs": map.streets.neighbour_pairs.len(),
            "street_length_m": street_m,
            "frame_origin_lat_lon": [lat0, lon0],
            "bbox_lonlat": map.bbox_lonlat,
            "seconds_generate_and_parse": generate_s,
        }),
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

/// A seeded binary image of discs and bars, and a copy with a share of pixels flipped.
fn synthetic_image(side: usize, noise: f64, seed: u64) -> (Vec<bool>, Vec<bool>) {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut clean = vec![false; side * side];
    let s = side as f64;
    for _ in 0..8 {
        let (cx, cy, r) = (
            rng.gen_range(0.0..s),
            rng.gen_range(0.0..s),
            rng.gen_range(0.05..0.2) * s,
        );
        for y in 0..side {
            for x in 0..side {
                let (dx, dy) = (x as f64 - cx, y as f64 - cy);
                if dx * dx + dy * dy < r * r {
                    clean[y * side + x] = !clean[y * side + x];
                }
            }
        }
    }
    let noisy = clean
        .iter()
        .map(|&p| if rng.gen_bool(noise) { !p } else { p })
        .collect();
    (clean, noisy)
}

fn image_png(side: usize, pixels: &[bool]) -> Vec<u8> {
    let rgb: Vec<u8> = pixels
        .iter()
        .flat_map(|&p| if p { [30, 30, 40] } else { [240, 236, 226] })
        .collect();
    encode_png_rgb(side as u32, side as u32, &rgb)
}

fn stage_denoise(args: &DemoArgs) -> anyhow::Result<StageOutput> {
    let side = 256;
    let (clean, noisy) = synthetic_image(side, 0.15, args.seed);
    let (unary, smooth) = (10, 8);
    let t = Instant::now();
    let mut q = Qpbo::<i32>::new(side * side, 2 * side * side);
    for (i, &p) in noisy.iter().enumerate() {
        // Cost of disagreeing with the observation.
        if p {
            q.add_unary(i, unary, 0);
        } else {
            q.add_unary(i, 0, unary);
        }
    }
    for y in 0..side {
        for x in 0..side {
            let i = y * side + x;
            if x + 1 < side {
                q.add_pairwise(i, i + 1, 0, smooth, smooth, 0);
            }
            if y + 1 < side {
                q.add_pairwise(i, i + side, 0, smooth, smooth, 0);
            }
        }
    }
    let build_s = t.elapsed().as_secs_f64();
    let t = Instant::now();
    q.solve();
    q.compute_weak_persistencies();
    let solve_s = t.elapsed().as_secs_f64();
    let labels: Vec<bool> = (0..side * side).map(|i| q.label(i) == Label::One).collect();
    let labelled = (0..side * side)
        .filter(|&i| q.label(i) != Label::Unlabelled)
        .count();
    let energy = q.energy(&labels);
    let errors_before = clean.iter().zip(&noisy).filter(|(a, b)| a != b).count();
    let errors_after = clean.iter().zip(&labels).filter(|(a, b)| a != b).count();
    let pngs = [
        ("denoise-clean.png", image_png(side, &clean)),
        ("denoise-noisy.png", image_png(side, &noisy)),
        ("denoise-qpbo.png", image_png(side, &labels)),
    ];
    let figures = pngs
        .iter()
        .map(|(name, png)| Html::png_img(png, name, 256))
        .collect();
    Ok(StageOutput {
        key: "pbo_denoise",
        summary: json!({
            "pixels": side * side,
            "energy": energy,
            "lower_bound": q.lower_bound(),
            "labelled_fraction": labelled as f64 / (side * side) as f64,
            "wrong_pixels_noisy": errors_before,
            "wrong_pixels_denoised": errors_after,
            "seconds_build": build_s,
            "seconds_solve": solve_s,
        }),
        title: "Binary denoising by QPBO (submodular: solved exactly)",
        text_html: format!(
            "A {side}×{side} image, 15 % of its pixels flipped, denoised on a 4-connected grid \
             (unary {unary}, Potts {smooth}). Energy {energy} = lower bound {}, {:.1} % labelled, \
             wrong pixels {errors_before} → {errors_after}; build {:.3} s, solve {:.3} s. \
             Left to right: clean, noisy, minimiser.",
            q.lower_bound(),
            100.0 * labelled as f64 / (side * side) as f64,
            build_s,
            solve_s
        ),
        figures,
        files: pngs.into_iter().collect(),
    })
}

/// A seeded random cubic polynomial with mixed signs, like a small ground MLN.
fn random_higher_order(vars: u32, terms: usize, seed: u64) -> Polynomial {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut f = Polynomial::new(vars as usize);
    for _ in 0..terms {
        let degree = rng.gen_range(1..=3);
        let lits: Vec<Literal> = (0..degree)
            .map(|_| Literal::new(rng.gen_range(0..vars), rng.gen_bool(0.7)))
            .collect();
        let w: f64 = rng.gen_range(-2.0..1.0);
        f.add_term((w * 100.0).round() / 100.0, &lits);
    }
    f
}

fn stage_higher_order(args: &DemoArgs) -> anyhow::Result<StageOutput> {
    let f = random_higher_order(2000, 5000, args.seed);
    let mut rows = Vec::new();
    let mut per_method = Map::new();
    for quadratizer in Quadratizer::ALL {
        for probe in [false, true] {
            let t = Instant::now();
            let r = solve(
                &f,
                &QssrOptions {
                    quadratizer,
                    probe,
                    improve_rounds: 20,
                    seed: args.seed,
                    ..QssrOptions::default()
                },
            );
            let secs = t.elapsed().as_secs_f64();
            let first = r.rounds.first().map_or(0, |x| x.fixed_by_qpbo);
            let name = format!(
                "{}{}",
                quadratizer.name(),
                if probe { "+probe" } else { "" }
            );
            rows.push(vec![
                name.clone(),
                format!("{:.1} %", 100.0 * first as f64 / f.num_vars() as f64),
                format!("{:.1} %", 100.0 * r.labelled_fraction),
                r.rounds.len().to_string(),
                format!("{:.2}", r.energy),
                format!("{:.2}", r.lower_bound),
                format!("{secs:.3}"),
            ]);
            per_method.insert(
                name,
                json!({
                    "labelled_first_round": first as f64 / f.num_vars() as f64,
                    "labelled_fraction": r.labelled_fraction,
                    "rounds": r.rounds.len(),
                    "energy": r.energy,
                    "lower_bound": r.lower_bound,
                    "seconds": secs,
                }),
            );
        }
    }
    let table = Html::table(
        &[
            "method",
            "labelled (QPBO)",
            "labelled (QSSR)",
            "rounds",
            "energy",
            "bound",
            "seconds",
        ],
        &rows,
    );
    Ok(StageOutput {
        key: "pbo_higher_order",
        summary: json!({
            "variables": f.num_vars(),
            "terms": f.num_terms(),
            "higher_order_terms": f.num_higher_order_terms(),
            "methods": per_method,
        }),
        title: "Higher-order minimisation: quadratize → QPBO → fix → repeat (QSSR)",
        text_html: format!(
            "A seeded random function of {} variables and {} terms ({} cubic), of mixed signs. \
             Per quadratization: variables labelled persistently by the first QPBO and after \
             QSSR (with and without probing), then 20 rounds of QPBO-I on the rest.",
            f.num_vars(),
            f.num_terms(),
            f.num_higher_order_terms()
        ),
        figures: vec![table],
        files: Vec::new(),
    })
}

/// Grounds a generated MLN problem.
fn ground_generated(
    g: &mln::generate::GeneratedMln,
    name: &str,
) -> anyhow::Result<(mln::parse::Program, mln::ground::GroundProblem)> {
    use mln::parse::{parse_evidence, parse_program, parse_query};
    let program = parse_program(&g.program, name)?;
    let evidence = parse_evidence(&g.evidence, name, &program)?;
    let query = parse_query(&g.query, name, &program)?;
    let problem = mln::ground::ground(
        &program,
        &evidence,
        name,
        &query,
        &mln::ground::GroundOptions::default(),
    )?;
    Ok((program, problem))
}

fn stage_mln(args: &DemoArgs) -> anyhow::Result<StageOutput> {
    use mln::generate::{friends_smokers, image_denoising, FriendsSmokersOptions};
    use mln::infer::{map_inference, InferOptions, Method};
    let side = 90;
    let problems = [
        ("ID 90×90", image_denoising(side, args.seed)),
        (
            "F&S 200",
            friends_smokers(&FriendsSmokersOptions::default(), args.seed),
        ),
        (
            "−F&S 200",
            friends_smokers(
                &FriendsSmokersOptions {
                    negate: true,
                    ..FriendsSmokersOptions::default()
                },
                args.seed,
            ),
        ),
    ];
    let mut rows = Vec::new();
    let mut per_problem = Map::new();
    let mut figures = Vec::new();
    let mut files = Vec::new();
    for (name, generated) in &problems {
        let t = Instant::now();
        let (program, problem) = ground_generated(generated, name)?;
        let ground_s = t.elapsed().as_secs_f64();
        let mut methods = Map::new();
        for method in [
            Method::Qpbo,
            Method::MaxWalkSat,
            Method::MaxWalkSatMonomials,
        ] {
            let mut o = InferOptions {
                method,
                ..InferOptions::default()
            };
            o.walksat.seed = args.seed;
            o.walksat.max_flips = 200_000;
            let t = Instant::now();
            let r = map_inference(&problem, &o);
            let secs = t.elapsed().as_secs_f64();
            rows.push(vec![
                name.to_string(),
                method.name().to_owned(),
                problem.atoms.len().to_string(),
                problem.factors.len().to_string(),
                format!("{:.2}", r.scores.cost),
                r.lower_bound.map_or("–".into(), |b| format!("{b:.2}")),
                if method == Method::Qpbo {
                    format!("{:.1} %", 100.0 * r.persistent_fraction)
                } else {
                    "–".into()
                },
                format!("{:.3}", ground_s + secs),
            ]);
            methods.insert(
                method.name().into(),
                json!({"cost": r.scores.cost, "lower_bound": r.lower_bound,
                       "persistent_fraction": r.persistent_fraction, "seconds": secs}),
            );
            if method == Method::Qpbo && name.starts_with("ID") {
                // Observed image and MAP image side by side.
                let mut observed = vec![false; side * side];
                let mut map_on = vec![false; side * side];
                let pixel = |atom_args: &[u32]| -> Option<usize> {
                    let c = problem.constants.get(*atom_args.first()? as usize)?;
                    let (x, y) = c.strip_prefix('X')?.split_once('_')?;
                    Some(y.parse::<usize>().ok()? * side + x.parse::<usize>().ok()?)
                };
                for line in generated.evidence.lines() {
                    if let Some(rest) = line.strip_prefix("Observed(") {
                        let c = rest.trim_end_matches(')');
                        if let Some((x, y)) = c.strip_prefix('X').and_then(|c| c.split_once('_')) {
                            if let (Ok(x), Ok(y)) = (x.parse::<usize>(), y.parse::<usize>()) {
                                observed[y * side + x] = true;
                            }
                        }
                    }
                }
                for (i, a) in problem.atoms.iter().enumerate() {
                    if program.predicates[a.predicate].name == "On" {
                        if let Some(k) = pixel(&a.args) {
                            map_on[k] = r.assignment[i];
                        }
                    }
                }
                let (p1, p2) = (image_png(side, &observed), image_png(side, &map_on));
                figures.push(Html::png_img(&p1, "ID: observed random image", 270));
                figures.push(Html::png_img(&p2, "ID: MAP state of On(p)", 270));
                files.push(("mln-id-observed.png", p1));
                files.push(("mln-id-map.png", p2));
            }
        }
        per_problem.insert(
            name.to_string(),
            json!({"ground_atoms": problem.atoms.len(), "ground_factors": problem.factors.len(),
                   "higher_order_factors": problem.higher_order_factors(),
                   "seconds_ground": ground_s, "methods": methods}),
        );
    }
    figures.insert(
        0,
        Html::table(
            &[
                "problem",
                "method",
                "atoms",
                "factors",
                "cost",
                "bound",
                "persistent",
                "seconds",
            ],
            &rows,
        ),
    );
    Ok(StageOutput {
        key: "mln",
        summary: Value::Object(per_problem),
        title: "Markov logic: MAP by QSSR (ASM, auto representation) and MaxWalkSAT",
        text_html: "The thesis' synthetic problems generated with the demo seed: image denoising \
                    (ID, 90×90 random image, triple smoothing rules) and Friends & Smokers with 200 \
                    persons (Table 3.1 weights) and with negated weights. QSSR proves its answer \
                    optimal where the bound meets the cost. Below: the observed image and the MAP \
                    state of ID."
            .to_owned(),
        figures,
        files,
    })
}
