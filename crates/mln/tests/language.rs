//! Alchemy's `!` (exactly-one arguments), `+` (per-constant weights), `*` (both signs) and
//! `#include`: each equals the formulas it stands for, written out by hand; the formula
//! printer reads back as the formula on every shared program.

#![allow(clippy::unwrap_used, clippy::expect_used)]

use mln::ground::{expand_per_constant, ground, GroundOptions, GroundProblem};
use mln::infer::{map_inference, InferOptions};
use mln::marginal::exact_marginals;
use mln::parse::{
    parse_evidence, parse_program, parse_query_predicates, read_program, Origin, Program, Weight,
};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// Grounds program text with evidence text and query predicates (`+` expanded).
fn problem(program: &str, evidence: &str, query: &str) -> (Program, GroundProblem) {
    let p = parse_program(program, "t.mln").unwrap_or_else(|e| panic!("{e}"));
    let e = parse_evidence(evidence, "t.db", &p).unwrap();
    let q = parse_query_predicates(query, &p).unwrap();
    let p = expand_per_constant(p, &e, &q).unwrap();
    let g = ground(&p, &e, "t.db", &q, &GroundOptions::default()).unwrap();
    (p, g)
}

/// Exact marginal per atom name.
fn marginals(program: &str, evidence: &str, query: &str) -> BTreeMap<String, f64> {
    let (p, g) = problem(program, evidence, query);
    let m = exact_marginals(&g).unwrap();
    (0..g.atoms.len())
        .map(|i| (g.atom_name(&p, i), m[i]))
        .collect()
}

fn assert_same(a: &BTreeMap<String, f64>, b: &BTreeMap<String, f64>) {
    assert_eq!(a.keys().collect::<Vec<_>>(), b.keys().collect::<Vec<_>>());
    for (k, x) in a {
        assert!((x - b[k]).abs() < 1e-9, "{k}: {x} vs {}", b[k]);
    }
}

const POSITIONS: &str = "pos = { Prof, Student, Staff }\nSenior(person)\nYoung(person)\n";
const POSITION_RULES: &str =
    "1.2 Senior(x) => HasPos(x, Prof)\n0.7 Young(x) => HasPos(x, Student)\n-0.4 HasPos(x, Staff)\n";
const PEOPLE: &str = "Senior(Ann)\nYoung(Ann)\nYoung(Bob)\n!Senior(Cid)\n";

#[test]
fn block_argument_is_the_exactly_one_constraint_written_out() {
    let with_bang = format!("{POSITIONS}HasPos(person, pos!)\n{POSITION_RULES}");
    let by_hand = format!(
        "{POSITIONS}HasPos(person, pos)\n{POSITION_RULES}EXIST p HasPos(x, p).\n!HasPos(x, p) v !HasPos(x, q) v p = q.\n"
    );
    let a = marginals(&with_bang, PEOPLE, "HasPos");
    assert_same(&a, &marginals(&by_hand, PEOPLE, "HasPos"));
    // Exactly one position per person: the marginals of a block sum to one.
    for person in ["Ann", "Bob", "Cid"] {
        let sum: f64 = a
            .iter()
            .filter(|(k, _)| k.starts_with(&format!("HasPos({person},")))
            .map(|(_, v)| v)
            .sum();
        assert!((sum - 1.0).abs() < 1e-9, "{person}: {sum}");
    }
    // And the MAP state has one position each.
    let (p, g) = problem(&with_bang, PEOPLE, "HasPos");
    let map = map_inference(&g, &InferOptions::default());
    assert_eq!(map.scores.hard_violations, 0);
    assert_eq!(map.assignment.iter().filter(|&&v| v).count(), 3);
    assert_eq!(
        p.formulas
            .iter()
            .filter(|f| f.origin == Origin::Block)
            .count(),
        2
    );
}

#[test]
fn two_block_arguments_form_one_block() {
    let program =
        "a = { A1, A2 }\nb = { B1, B2 }\nS(k, a!, b!)\n0.5 S(x, A1, y)\n-0.3 S(x, y, B2)\n";
    // K1's block is decided by evidence: its other three atoms are false.
    let m = marginals(program, "S(K1, A2, B2)\n", "S");
    assert_eq!(m.len(), 3);
    assert!(m.values().all(|&v| v < 1e-12), "{m:?}");
    let free = "k = { K2 }\na = { A1, A2 }\nb = { B1, B2 }\nS(k, a!, b!)\n0.5 S(x, A1, y)\n";
    let m = marginals(free, "", "S");
    assert_eq!(m.len(), 4);
    assert!((m.values().sum::<f64>() - 1.0).abs() < 1e-9, "{m:?}");
}

#[test]
fn per_constant_variables_write_one_formula_per_constant() {
    let plus = format!("{POSITIONS}HasPos(person, pos!)\n0.9 Senior(x) => HasPos(x, +p)\n");
    let by_hand = format!(
        "{POSITIONS}HasPos(person, pos!)\n0.9 Senior(x) => HasPos(x, Prof)\n0.9 Senior(x) => HasPos(x, Student)\n0.9 Senior(x) => HasPos(x, Staff)\n"
    );
    assert_same(
        &marginals(&plus, PEOPLE, "HasPos"),
        &marginals(&by_hand, PEOPLE, "HasPos"),
    );
    let (p, _) = problem(&plus, PEOPLE, "HasPos");
    let expanded: Vec<_> = p
        .formulas
        .iter()
        .filter(|f| f.origin == Origin::Expanded)
        .collect();
    assert_eq!(expanded.len(), 3);
    assert!(expanded.iter().all(|f| f.per_constant.is_empty()));
    // Two `+` variables: every combination (constants from the evidence too).
    let two = "R(a, b)\n1 R(+x, +y)\n";
    let (p, _) = problem(two, "R(A, B)\nR(C, D)\n", "R");
    assert_eq!(p.formulas.len(), 4);
    // A variable marked twice, not next to each other, is still one variable.
    let again = "R(a, b)\nS(a)\n1 R(+x, +y) ^ S(+x)\n";
    let (p, _) = problem(again, "R(A, B)\nR(C, D)\n", "R,S");
    assert_eq!(p.formulas.len(), 4);
    // Unexpanded, grounding refuses rather than ignoring the `+`.
    let raw = parse_program(two, "t.mln").unwrap();
    let err = ground(&raw, &[], "t.db", &[], &GroundOptions::default()).unwrap_err();
    assert!(err.to_string().contains("per-constant"), "{err}");
}

#[test]
fn starred_atoms_expand_into_every_sign_combination() {
    let star = "Student(person)\nProfessor(person)\n0.3 *Student(x) ^ *Professor(x)\n";
    let (p, _) = problem(star, "Student(Ann)\n", "Professor");
    let texts: Vec<String> = p
        .formulas
        .iter()
        .map(|f| p.formula_text(&f.formula))
        .collect();
    assert_eq!(
        texts,
        [
            "Student(x) ^ Professor(x)",
            "!Student(x) ^ Professor(x)",
            "Student(x) ^ !Professor(x)",
            "!Student(x) ^ !Professor(x)"
        ]
    );
    assert!(p.formulas.iter().all(|f| f.weight == Weight::Soft(0.3)));
    // A lone `*P(x)` line still reads as a (repeated) closed-world declaration: an error.
    let e = parse_program("P(t)\n*P(t)\n", "t.mln").unwrap_err();
    assert!(e.to_string().contains("already declared"), "{e}");
}

#[test]
fn constructs_out_of_place_are_errors_naming_file_line_and_construct() {
    let program = parse_program("P(t)\nQ(t, u!)\n", "t.mln").unwrap();
    let e = parse_evidence("P(A)\nP(+A)\n", "t.db", &program).unwrap_err();
    assert!(
        e.to_string().starts_with("t.db:2:") && e.to_string().contains("`+`"),
        "{e}"
    );
    let e = parse_program("P(t)\n1 P(+)\n", "t.mln").unwrap_err();
    assert!(e.to_string().starts_with("t.mln:2:"), "{e}");
    let e = parse_program("P(t)\n#include \"x.mln\"\n", "t.mln").unwrap_err();
    assert!(
        e.to_string().starts_with("t.mln:2:") && e.to_string().contains("#include"),
        "{e}"
    );
    let e = parse_program("P(t)\n#include x.mln\n", "t.mln").unwrap_err();
    assert!(e.to_string().contains("quoted file name"), "{e}");
    // Constructs of Alchemy and Tuffy that are not read: named, never dropped.
    for (text, construct) in [
        ("P(t)\nQ(t)\nP(x) :- Q(x).\n", "datalog"),
        ("P(t)\n[x > 1] P(x)\n", "bracketed"),
        ("P(t)\nt mother(t)\n", "function declarations"),
        ("P(t)\n1 P(mother(x))\n", "functions"),
        ("P(t)\n1 P(x) ^ greaterThan(x, x)\n", "internal predicate"),
    ] {
        let e = parse_program(text, "t.mln").unwrap_err().to_string();
        assert!(e.starts_with("t.mln:") && e.contains(construct), "{e}");
    }
}

fn temp_dir(name: &str) -> PathBuf {
    let d = Path::new(env!("CARGO_TARGET_TMPDIR")).join(name);
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

#[test]
fn include_reads_relative_files_and_names_them_in_errors() {
    let d = temp_dir("mln_include");
    std::fs::create_dir_all(d.join("rules")).unwrap();
    std::fs::write(
        d.join("main.mln"),
        "Smokes(person)\n#include \"rules/cancer.mln\"\n2 Smokes(x)\n",
    )
    .unwrap();
    std::fs::write(
        d.join("rules/cancer.mln"),
        "Cancer(person)\n\n1.5 Smokes(x) => Cancer(x)\n",
    )
    .unwrap();
    let p = read_program(&d.join("main.mln")).unwrap();
    assert_eq!(p.predicates.len(), 2);
    assert_eq!(p.formulas.len(), 2);
    assert_eq!(p.sources.len(), 2);
    assert_eq!(p.formulas[0].source, 1);
    assert_eq!(p.formulas[0].line, 3);
    assert_eq!(p.sources[1].included_at, Some((0, 2)));
    // An error inside the included file names it.
    std::fs::write(
        d.join("rules/cancer.mln"),
        "Cancer(person)\n1.5 Smokes(x) =>\n",
    )
    .unwrap();
    let e = read_program(&d.join("main.mln")).unwrap_err().to_string();
    assert!(e.contains("cancer.mln:2:"), "{e}");
    // A missing file, and a file that includes itself.
    std::fs::remove_file(d.join("rules/cancer.mln")).unwrap();
    let e = read_program(&d.join("main.mln")).unwrap_err().to_string();
    assert!(
        e.contains("main.mln:2:") && e.contains("cannot read"),
        "{e}"
    );
    std::fs::write(d.join("loop.mln"), "#include \"loop.mln\"\n").unwrap();
    let e = read_program(&d.join("loop.mln")).unwrap_err().to_string();
    assert!(e.contains("nested deeper"), "{e}");
    // Files that each include the next twice: 2^12 reads; the total is capped.
    for i in 0..12 {
        std::fs::write(
            d.join(format!("twice{i}.mln")),
            format!(
                "#include \"twice{0}.mln\"\n#include \"twice{0}.mln\"\n",
                i + 1
            ),
        )
        .unwrap();
    }
    std::fs::write(d.join("twice12.mln"), "P(t)\n").unwrap();
    let e = read_program(&d.join("twice0.mln")).unwrap_err().to_string();
    assert!(e.contains("files included in all"), "{e}");
}

#[test]
fn learnt_program_writes_expanded_and_included_formulas_back() {
    let d = temp_dir("mln_learn_expand");
    std::fs::write(
        d.join("p.mln"),
        "pos = { Prof, Student, Staff }\nHasPos(person, pos!)\nSenior(person)\n#include \"r.mln\"\n",
    )
    .unwrap();
    std::fs::write(
        d.join("r.mln"),
        "0 Senior(x) => HasPos(x, +p)\n0 *Senior(x) ^ *HasPos(x, Staff)\n",
    )
    .unwrap();
    std::fs::write(
        d.join("t.db"),
        "Senior(Ann)\n!Senior(Bob)\nHasPos(Ann, Prof)\nHasPos(Bob, Staff)\n",
    )
    .unwrap();
    let files = mln::files::ProblemFiles {
        program: d.join("p.mln"),
        evidence: vec![d.join("t.db")],
        query: mln::files::QuerySource::Predicates("HasPos".into()),
    };
    let learnt = mln::files::learn_program(&files, &mln::learn::LearnOptions::default()).unwrap();
    // The written program has no `+`, `*` or #include left, and reads back to the same
    // formulas with the learnt weights.
    assert!(!learnt.text.contains('+') && !learnt.text.contains("#include"));
    let back = parse_program(&learnt.text, "learnt.mln").unwrap();
    let p = read_program(&d.join("p.mln")).unwrap();
    let e = mln::parse::read_evidence(&d.join("t.db"), &p).unwrap();
    let q = parse_query_predicates("HasPos", &p).unwrap();
    let expanded = expand_per_constant(p, &e, &q).unwrap();
    assert_eq!(back.formulas.len(), expanded.formulas.len());
    for ((a, b), w) in back
        .formulas
        .iter()
        .zip(&expanded.formulas)
        .zip(&learnt.learnt.weights)
    {
        assert_eq!(a.formula, b.formula);
        if let (Weight::Soft(x), Some(w)) = (a.weight, w) {
            assert!((x - w).abs() < 1e-6, "{x} vs {w}");
        }
    }
}

fn shared_programs(dir: &Path, out: &mut Vec<PathBuf>) {
    for e in std::fs::read_dir(dir).unwrap() {
        let p = e.unwrap().path();
        if p.is_dir() {
            shared_programs(&p, out);
        } else if p.extension().is_some_and(|x| x == "mln") {
            out.push(p);
        }
    }
}

#[test]
fn every_shared_program_parses_and_its_formulas_print_back_as_they_read() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../shared/data/mln");
    let mut files = Vec::new();
    shared_programs(&root, &mut files);
    files.sort();
    assert!(files.len() >= 15, "{files:?}");
    let mut formulas = 0;
    for f in &files {
        let p = read_program(f).unwrap_or_else(|e| panic!("{e}"));
        let mut text = String::new();
        for pred in &p.predicates {
            text += &format!("{}({})\n", pred.name, pred.arg_types.join(", "));
        }
        for wf in &p.formulas {
            let body = p.formula_text(&wf.formula);
            text += &match wf.weight {
                Weight::Hard => format!("{body}.\n"),
                Weight::Soft(w) => format!("{w} {body}\n"),
            };
        }
        let back = parse_program(&text, "printed.mln").unwrap_or_else(|e| panic!("{e}\n{text}"));
        assert_eq!(back.formulas.len(), p.formulas.len(), "{}", f.display());
        for (a, b) in back.formulas.iter().zip(&p.formulas) {
            assert_eq!(a.formula, b.formula, "{}", f.display());
            assert_eq!(a.weight, b.weight, "{}", f.display());
        }
        formulas += p.formulas.len();
    }
    assert!(formulas > 1000, "{formulas}");
}
