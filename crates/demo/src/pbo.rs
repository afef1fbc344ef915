//! Demo stages of pbo: binary image denoising with QPBO, higher-order functions with QSSR.

use crate::report::{encode_png_rgb, Html};
use crate::{DemoArgs, StageOutput};
use pbo::polynomial::{Literal, Polynomial};
use pbo::qpbo::{Label, Qpbo};
use pbo::qssr::{solve, QssrOptions};
use pbo::quadratize::Quadratizer;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::Serialize;
use std::collections::BTreeMap;
use std::time::Instant;

/// The denoising stage's summary entry (`pbo_denoise` in `summary.json`).
#[derive(Debug, Clone, Serialize)]
pub struct DenoiseSummary {
    /// Pixels (variables).
    pub pixels: usize,
    /// Energy of the minimiser.
    pub energy: i32,
    /// QPBO's lower bound.
    pub lower_bound: i32,
    /// Share of pixels QPBO labelled.
    pub labelled_fraction: f64,
    /// Wrong pixels in the noisy image.
    pub wrong_pixels_noisy: usize,
    /// Wrong pixels after denoising.
    pub wrong_pixels_denoised: usize,
    /// Seconds building the graph.
    pub seconds_build: f64,
    /// Seconds solving.
    pub seconds_solve: f64,
}

/// One quadratizer's row of the higher-order stage.
#[derive(Debug, Clone, Serialize)]
pub struct MethodRow {
    /// Share labelled by the first QPBO.
    pub labelled_first_round: f64,
    /// Share labelled after QSSR.
    pub labelled_fraction: f64,
    /// QSSR rounds.
    pub rounds: usize,
    /// Energy found.
    pub energy: f64,
    /// Lower bound.
    pub lower_bound: f64,
    /// Seconds.
    pub seconds: f64,
}

/// The higher-order stage's summary entry (`pbo_higher_order` in `summary.json`).
#[derive(Debug, Clone, Serialize)]
pub struct HigherOrderSummary {
    /// Variables of the function.
    pub variables: usize,
    /// Terms.
    pub terms: usize,
    /// Terms of degree three.
    pub higher_order_terms: usize,
    /// Per quadratizer (and `+probe`).
    pub methods: BTreeMap<String, MethodRow>,
}

/// A seeded binary image of discs and bars, and a copy with a share of pixels flipped.
pub fn synthetic_image(side: usize, noise: f64, seed: u64) -> (Vec<bool>, Vec<bool>) {
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

/// Colour of an "on" pixel in the demo's binary images.
pub const IMAGE_ON: [u8; 3] = [30, 30, 40];
/// Colour of an "off" pixel.
pub const IMAGE_OFF: [u8; 3] = [240, 236, 226];

/// A black-and-white image as a PNG file.
pub fn image_png(side: usize, pixels: &[bool]) -> anyhow::Result<Vec<u8>> {
    let rgb: Vec<u8> = pixels
        .iter()
        .flat_map(|&p| if p { IMAGE_ON } else { IMAGE_OFF })
        .collect();
    encode_png_rgb(side as u32, side as u32, &rgb)
}

/// The demo stage of pbo's QPBO: binary image denoising on a 4-connected grid.
pub fn denoise_stage(args: &DemoArgs) -> anyhow::Result<StageOutput> {
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
        ("denoise-clean.png", image_png(side, &clean)?),
        ("denoise-noisy.png", image_png(side, &noisy)?),
        ("denoise-qpbo.png", image_png(side, &labels)?),
    ];
    let figures = pngs
        .iter()
        .map(|(name, png)| Html::png_img(png, name, 256))
        .collect();
    Ok(StageOutput {
        key: "pbo_denoise",
        summary: serde_json::to_value(DenoiseSummary {
            pixels: side * side,
            energy,
            lower_bound: q.lower_bound(),
            labelled_fraction: labelled as f64 / (side * side) as f64,
            wrong_pixels_noisy: errors_before,
            wrong_pixels_denoised: errors_after,
            seconds_build: build_s,
            seconds_solve: solve_s,
        })?,
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

/// The demo stage of pbo's QSSR: a random cubic function, per quadratizer, with and without probing.
pub fn higher_order_stage(args: &DemoArgs) -> anyhow::Result<StageOutput> {
    let f = random_higher_order(2000, 5000, args.seed);
    let mut rows = Vec::new();
    let mut per_method = BTreeMap::new();
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
                MethodRow {
                    labelled_first_round: first as f64 / f.num_vars() as f64,
                    labelled_fraction: r.labelled_fraction,
                    rounds: r.rounds.len(),
                    energy: r.energy,
                    lower_bound: r.lower_bound,
                    seconds: secs,
                },
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
        summary: serde_json::to_value(HigherOrderSummary {
            variables: f.num_vars(),
            terms: f.num_terms(),
            higher_order_terms: f.num_higher_order_terms(),
            methods: per_method,
        })?,
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
