//! Alchemy's per-constant weights (`+x`): one formula per constant of the variable's type.

use super::cnf::{for_each_atom, free_variables};
use super::GroundError;
use crate::parse::{Atom, EvidenceAtom, Formula, Program, Term};
use rustc_hash::{FxHashMap, FxHashSet};

/// Most formulas the `+` formulas of a program may expand into, all together.
const MAX_PER_CONSTANT: usize = 1_000_000;

/// The program with every formula that has `+` variables replaced by one formula per
/// combination of their constants (the type's declared constants, then those in evidence,
/// formulas and queries, in that order), each keeping the written weight.
pub fn expand_per_constant(
    program: Program,
    evidence: &[EvidenceAtom],
    query: &[Atom],
) -> Result<Program, GroundError> {
    if program.formulas.iter().all(|f| f.per_constant.is_empty()) {
        return Ok(program);
    }
    let constants = type_constants(&program, evidence, query);
    let mut written: u64 = 0;
    let mut formulas = Vec::with_capacity(program.formulas.len());
    for f in &program.formulas {
        if f.per_constant.is_empty() {
            formulas.push(f.clone());
            continue;
        }
        let path = program.file_of(f);
        let (names, types) = free_variables(&f.formula, &program, path, f.line)?;
        let mut choices: Vec<(&str, &[String])> = Vec::new();
        let mut count: u64 = 1;
        for v in &f.per_constant {
            let Some(i) = names.iter().position(|n| n == v) else {
                return Err(GroundError::UntypedVariable {
                    path: path.to_owned(),
                    line: f.line,
                    var: v.clone(),
                });
            };
            let domain = constants
                .get(types[i].as_str())
                .map_or(&[][..], Vec::as_slice);
            if domain.is_empty() {
                return Err(GroundError::EmptyDomain {
                    path: path.to_owned(),
                    line: f.line,
                    var: v.clone(),
                    type_name: types[i].clone(),
                });
            }
            count = count.saturating_mul(domain.len() as u64);
            choices.push((v, domain));
        }
        written = written.saturating_add(count);
        if written > MAX_PER_CONSTANT as u64 {
            return Err(GroundError::TooManyPerConstant {
                path: path.to_owned(),
                line: f.line,
                count: written,
                limit: MAX_PER_CONSTANT,
            });
        }
        // Odometer over the combinations, the first variable slowest.
        let mut pick = vec![0usize; choices.len()];
        'combinations: loop {
            let mut g = f.clone();
            for ((var, domain), &k) in choices.iter().zip(&pick) {
                substitute(&mut g.formula, var, &domain[k]);
            }
            g.per_constant.clear();
            formulas.push(g);
            let mut d = choices.len();
            loop {
                if d == 0 {
                    break 'combinations;
                }
                d -= 1;
                pick[d] += 1;
                if pick[d] < choices[d].1.len() {
                    continue 'combinations;
                }
                pick[d] = 0;
            }
        }
    }
    Ok(Program {
        formulas,
        ..program
    })
}

/// Each type's constants in first-seen order: declared, evidence, formulas, queries.
fn type_constants<'p>(
    program: &'p Program,
    evidence: &'p [EvidenceAtom],
    query: &'p [Atom],
) -> FxHashMap<&'p str, Vec<String>> {
    let mut out: FxHashMap<&str, (Vec<String>, FxHashSet<&str>)> = FxHashMap::default();
    let mut add = |ty: &'p str, c: &'p str| {
        let e = out.entry(ty).or_default();
        if e.1.insert(c) {
            e.0.push(c.to_owned());
        }
    };
    for t in &program.types {
        for c in &t.constants {
            add(&t.name, c);
        }
    }
    for ev in evidence {
        for (c, ty) in ev
            .args
            .iter()
            .zip(&program.predicates[ev.predicate].arg_types)
        {
            add(ty, c);
        }
    }
    let mut atom_constants = |a: &'p Atom| {
        for (t, ty) in a
            .args
            .iter()
            .zip(&program.predicates[a.predicate].arg_types)
        {
            if let Term::Const(c) = t {
                add(ty, c);
            }
        }
    };
    for f in &program.formulas {
        for_each_atom(&f.formula, &mut atom_constants);
    }
    for a in query {
        atom_constants(a);
    }
    out.into_iter().map(|(k, v)| (k, v.0)).collect()
}

/// Replaces the free occurrences of variable `var` by constant `c`.
fn substitute(f: &mut Formula, var: &str, c: &str) {
    let term = |t: &mut Term| {
        if matches!(t, Term::Var(v) if v == var) {
            *t = Term::Const(c.into());
        }
    };
    match f {
        Formula::Atom(a) => a.args.iter_mut().for_each(term),
        Formula::Equal(pair) => {
            term(&mut pair.0);
            term(&mut pair.1);
        }
        Formula::Not(g) => substitute(g, var, c),
        Formula::And(v) | Formula::Or(v) => v.iter_mut().for_each(|g| substitute(g, var, c)),
        Formula::Implies(a, b) | Formula::Iff(a, b) => {
            substitute(a, var, c);
            substitute(b, var, c);
        }
        Formula::Exists(vs, g) | Formula::Forall(vs, g) => {
            if !vs.iter().any(|v| v == var) {
                substitute(g, var, c);
            }
        }
    }
}
