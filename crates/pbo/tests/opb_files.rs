//! `.opb` files as users write them: regressions of issue 16 (a quadratic-time tokenizer
//! and a header that made the reader allocate one name per declared variable).

use pbo::instances::denoising_grid;
use pbo::opb::{parse_opb, write_opb, OpbError};
use pbo::qssr::{solve, QssrOptions};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// Issue 16: a 512 × 512 denoising grid written as one objective line (262 144 variables,
/// ≈ 24 MB) did not parse in 10 minutes, because every token's column was recounted from
/// the start of its line. The file must read back as the same function and solve to the
/// max-flow optimum (the grid is submodular, so QPBO labels every variable).
#[test]
fn issue16_grid_objective_on_one_line_reads_and_solves() {
    let inst = denoising_grid(512, 512, 7);
    let problem = inst.to_opb();
    let text = write_opb(&problem);
    let objective_lines = text.lines().filter(|l| !l.starts_with('*')).count();
    assert_eq!(objective_lines, 1, "the objective must be one line");
    assert!(text.len() > 10_000_000, "{} bytes", text.len());

    let back = parse_opb(&text, "grid.opb").expect("the written grid parses");
    assert_eq!(back.names.len(), inst.num_vars);
    assert_eq!(back.poly.num_terms(), problem.poly.num_terms());
    let mut rng = ChaCha8Rng::seed_from_u64(1);
    for _ in 0..3 {
        let x: Vec<bool> = (0..inst.num_vars).map(|_| rng.gen_bool(0.5)).collect();
        assert_eq!(back.poly.evaluate(&x), inst.energy(&x) as f64);
    }

    let result = solve(&back.poly, &QssrOptions::default());
    let mut g = inst.to_graph::<i64>().expect("Potts grid is a cut");
    let optimum = g.maxflow(false);
    assert_eq!(inst.energy(&result.assignment), optimum);
}

/// Issue 16: a 60-byte file whose header declares 42 949 672 964 variables hung the solver
/// (a name was created for every declared variable before the objective was read). The
/// reader keeps only the variables the objective mentions when the header declares more
/// than the file could.
#[test]
fn issue16_huge_variable_header_keeps_only_mentioned_variables() {
    let text = "* #variable= 42949672964 #constraint= 0\nmin: +1 x1 -2 x42949672964 ;\n";
    assert!(text.len() <= 70);
    let p = parse_opb(text, "huge.opb").expect("parses");
    assert_eq!(p.names, ["x1", "x42949672964"]);
    assert_eq!(p.declared, Some(42_949_672_964));
    assert_eq!(p.poly.num_vars(), 2);
    let r = solve(&p.poly, &QssrOptions::default());
    assert_eq!(r.assignment, [false, true]);

    // Variables are ordered by their declared number, whatever order they appear in.
    let p = parse_opb(
        "* #variable= 99999999999\nmin: +1 x900 x3 -1 ~x77 +2 x3 ;",
        "huge2.opb",
    )
    .expect("parses");
    assert_eq!(p.names, ["x3", "x77", "x900"]);
    for mask in 0..8u32 {
        let x: Vec<bool> = (0..3).map(|i| mask >> i & 1 == 1).collect();
        let (x3, x77, x900) = (x[0] as u8 as f64, x[1] as u8 as f64, x[2] as u8 as f64);
        let expected = x900 * x3 - (1.0 - x77) + 2.0 * x3;
        assert_eq!(p.poly.evaluate(&x), expected);
    }

    // Names beyond the header, or not of the form xk, are still errors.
    let err = parse_opb("* #variable= 99999999999\nmin: +1 x100000000000 ;", "h3")
        .expect_err("beyond the header");
    assert!(
        matches!(
            err,
            OpbError::UnknownVariable {
                line: 2,
                col: 9,
                ..
            }
        ),
        "{err}"
    );
    let err = parse_opb("* #variable= 99999999999\nmin: +1 y1 ;", "h4").expect_err("not xk");
    assert!(matches!(err, OpbError::UnknownVariable { .. }), "{err}");
    let err = parse_opb("* #variable= 99999999999\nmin: +1 x01 ;", "h5").expect_err("x01");
    assert!(matches!(err, OpbError::UnknownVariable { .. }), "{err}");
}

/// Columns are character columns, counted once per character, also after multi-byte text.
#[test]
fn columns_count_characters_on_long_lines() {
    let mut text = String::from("min: +1 büro");
    for k in 1..=1000 {
        text.push_str(&format!(" +1 x{k}"));
    }
    text.push_str(" +1 x$ ;");
    let err = parse_opb(&text, "cols.opb").expect_err("x$ is not a literal");
    // "min: +1 büro" is 12 characters (13 bytes), each " +1 xk" is 5 + digits(k).
    let before: usize = 12
        + (1..=1000)
            .map(|k: usize| 5 + k.to_string().len())
            .sum::<usize>();
    let expected_col = before + " +1 ".len() + 1;
    match err {
        OpbError::Syntax { line: 1, col, .. } => assert_eq!(col, expected_col),
        other => panic!("unexpected error {other}"),
    }
}
