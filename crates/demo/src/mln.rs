//! Demo stage of mln: MAP inference on the thesis' synthetic problems.

use crate::pbo::{image_png, IMAGE_OFF, IMAGE_ON};
use crate::report::Html;
use crate::{DemoArgs, StageOutput};
use serde::Serialize;
use std::collections::BTreeMap;
use std::time::Instant;

/// One inference method's result on one problem.
#[derive(Debug, Clone, Serialize)]
pub struct MethodResult {
    /// Cost of the MAP state found.
    pub cost: f64,
    /// Lower bound, where the method has one.
    pub lower_bound: Option<f64>,
    /// Share of atoms fixed persistently (QPBO).
    pub persistent_fraction: f64,
    /// Seconds of inference.
    pub seconds: f64,
}

/// One problem of the MLN stage (the stage's summary maps problem names to these).
#[derive(Debug, Clone, Serialize)]
pub struct ProblemSummary {
    /// Ground atoms.
    pub ground_atoms: usize,
    /// Ground factors.
    pub ground_factors: usize,
    /// Factors of degree above two.
    pub higher_order_factors: usize,
    /// Seconds grounding.
    pub seconds_ground: f64,
    /// Per method name.
    pub methods: BTreeMap<String, MethodResult>,
    /// MC-SAT marginals (image denoising only).
    pub marginal: Option<MarginalSummary>,
}

/// MC-SAT's run on one problem.
#[derive(Debug, Clone, Serialize)]
pub struct MarginalSummary {
    /// Chains run in parallel.
    pub chains: usize,
    /// Counted samples per chain.
    pub samples: usize,
    /// The largest difference between two chains' estimates of one atom.
    pub max_chain_spread: f64,
    /// Its mean over atoms.
    pub mean_chain_spread: f64,
    /// Mean probability of the atoms whose MAP value is true, and of those false.
    pub mean_probability_map_true: f64,
    /// The same for the atoms whose MAP value is false.
    pub mean_probability_map_false: f64,
    /// Seconds sampling.
    pub seconds: f64,
}

/// A probability image: each pixel between the "off" (0) and "on" (1) colour of
/// [`image_png`].
fn probability_png(side: usize, p: &[f64]) -> anyhow::Result<Vec<u8>> {
    let rgb: Vec<u8> = p
        .iter()
        .flat_map(|&q| {
            let q = q.clamp(0.0, 1.0);
            [0, 1, 2].map(|c| {
                let (off, on) = (f64::from(IMAGE_OFF[c]), f64::from(IMAGE_ON[c]));
                (off + q * (on - off)).round() as u8
            })
        })
        .collect();
    crate::report::encode_png_rgb(side as u32, side as u32, &rgb)
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

/// The demo stage of mln: MAP inference on the thesis' synthetic problems, by QSSR and MaxWalkSAT.
pub fn stage(args: &DemoArgs) -> anyhow::Result<StageOutput> {
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
    let mut per_problem = BTreeMap::new();
    let mut marginal = None;
    let mut figures = Vec::new();
    let mut files = Vec::new();
    for (name, generated) in &problems {
        let t = Instant::now();
        let (program, problem) = ground_generated(generated, name)?;
        let ground_s = t.elapsed().as_secs_f64();
        let mut methods = BTreeMap::new();
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
                MethodResult {
                    cost: r.scores.cost,
                    lower_bound: r.lower_bound,
                    persistent_fraction: r.persistent_fraction,
                    seconds: secs,
                },
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
                let (p1, p2) = (image_png(side, &observed)?, image_png(side, &map_on)?);
                figures.push(Html::png_img(&p1, "ID: observed random image", 270));
                figures.push(Html::png_img(&p2, "ID: MAP state of On(p)", 270));
                files.push(("mln-id-observed.png", p1));
                files.push(("mln-id-map.png", p2));
                // The probability of every pixel (MC-SAT), beside the single MAP state.
                let options = mln::marginal::McSatOptions {
                    samples: 500,
                    burn_in: 100,
                    seed: args.seed,
                    ..mln::marginal::McSatOptions::default()
                };
                let t = Instant::now();
                let m = mln::marginal::mc_sat(&problem, &options)?;
                let secs = t.elapsed().as_secs_f64();
                let mut prob = vec![0.0; side * side];
                let (mut on, mut off) = ((0.0, 0usize), (0.0, 0usize));
                for (i, a) in problem.atoms.iter().enumerate() {
                    if program.predicates[a.predicate].name == "On" {
                        if let Some(k) = pixel(&a.args) {
                            prob[k] = m.probabilities[i];
                            let bucket = if r.assignment[i] { &mut on } else { &mut off };
                            bucket.0 += m.probabilities[i];
                            bucket.1 += 1;
                        }
                    }
                }
                let p3 = probability_png(side, &prob)?;
                figures.push(Html::png_img(
                    &p3,
                    "ID: P(On(p)) by MC-SAT (1 000 samples)",
                    270,
                ));
                files.push(("mln-id-marginals.png", p3));
                rows.push(vec![
                    name.to_string(),
                    "mc-sat (marginals)".to_owned(),
                    problem.atoms.len().to_string(),
                    problem.factors.len().to_string(),
                    "–".into(),
                    "–".into(),
                    format!("spread {:.3}", m.max_chain_spread),
                    format!("{:.3}", ground_s + secs),
                ]);
                marginal = Some(MarginalSummary {
                    chains: m.chains,
                    samples: m.samples,
                    max_chain_spread: m.max_chain_spread,
                    mean_chain_spread: m.mean_chain_spread,
                    mean_probability_map_true: on.0 / on.1.max(1) as f64,
                    mean_probability_map_false: off.0 / off.1.max(1) as f64,
                    seconds: secs,
                });
            }
        }
        per_problem.insert(
            name.to_string(),
            ProblemSummary {
                ground_atoms: problem.atoms.len(),
                ground_factors: problem.factors.len(),
                higher_order_factors: problem.higher_order_factors(),
                seconds_ground: ground_s,
                methods,
                marginal: marginal.take(),
            },
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
        summary: serde_json::to_value(per_problem)?,
        title: "Markov logic: MAP by QSSR (ASM, auto representation) and MaxWalkSAT, marginals by MC-SAT",
        text_html: "The thesis' synthetic problems generated with the demo seed: image denoising \
                    (ID, 90×90 random image, triple smoothing rules) and Friends & Smokers with 200 \
                    persons (Table 3.1 weights) and with negated weights. QSSR proves its answer \
                    optimal where the bound meets the cost. Below: the observed image, the MAP \
                    state of ID, and the probability of every pixel by MC-SAT (2 chains × 500 \
                    samples; grey where the MAP state is uncertain)."
            .to_owned(),
        figures,
        files,
    })
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::expect_used)]
    use super::*;

    #[test]
    fn demo_stage_shows_map_and_marginals_that_agree() {
        let args = DemoArgs {
            out: std::env::temp_dir().join(format!("urbansem-mln-demo-{}", std::process::id())),
            seed: 1,
        };
        let stage = stage(&args).unwrap();
        assert_eq!(stage.key, "mln");
        let m = &stage.summary["ID 90×90"]["marginal"];
        // Two chains agree, and pixels the MAP state turns on are the likelier ones.
        assert!(m["max_chain_spread"].as_f64().unwrap() < 0.2, "{m}");
        assert!(
            m["mean_probability_map_true"].as_f64().unwrap()
                > m["mean_probability_map_false"].as_f64().unwrap() + 0.2,
            "{m}"
        );
        assert!(stage
            .files
            .iter()
            .any(|(name, png)| *name == "mln-id-marginals.png" && png.starts_with(b"\x89PNG")));
    }
}
