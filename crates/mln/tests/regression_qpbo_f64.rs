//! Issue 7 regression: on −F&S with 100 persons in the multinomial form, QPBO<f64> on the
//! ISH quadratization labelled every node, and QSSR claimed the optimum 79 190 with bound
//! 79 190 while ASM + tabu search finds 39 850.5. QPBO took x = 0 from "x in the source
//! tree or x̄ in the sink tree", mixing two different minimum cuts of a non-symmetric flow;
//! it now reads one cut (the sink tree against the rest) as Kolmogorov's QPBO does.

#![allow(clippy::unwrap_used, clippy::expect_used)]

use mln::generate::{friends_smokers, FriendsSmokersOptions};
use mln::ground::{ground, GroundOptions};
use mln::infer::{map_inference, InferOptions, Representation};
use mln::parse::{parse_evidence, parse_program, parse_query};
use pbo::quadratize::Quadratizer;

#[test]
fn issue_7_qssr_bound_never_exceeds_a_found_cost_on_neg_fs_100() {
    let g = friends_smokers(
        &FriendsSmokersOptions {
            persons: 100,
            negate: true,
            ..FriendsSmokersOptions::default()
        },
        0,
    );
    let program = parse_program(&g.program, "neg-fs.mln").unwrap();
    let evidence = parse_evidence(&g.evidence, "neg-fs.db", &program).unwrap();
    let query = parse_query(&g.query, "query.db", &program).unwrap();
    let p = ground(
        &program,
        &evidence,
        "neg-fs.db",
        &query,
        &GroundOptions::default(),
    )
    .unwrap();
    let asm = map_inference(&p, &InferOptions::default());
    let ish = map_inference(
        &p,
        &InferOptions {
            quadratizer: Quadratizer::Ish,
            representation: Representation::Multinomial,
            ..InferOptions::default()
        },
    );
    let bound = ish.lower_bound.unwrap();
    assert!(
        bound <= asm.scores.cost + 1e-6,
        "ISH bound {bound} above the cost {} found with ASM",
        asm.scores.cost
    );
}
