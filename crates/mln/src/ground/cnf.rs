//! Formula → clauses: negation normal form, quantifiers expanded over their domains, CNF by
//! distribution, and the free variables of a formula with their types.

use super::GroundError;
use crate::parse::{Atom, Formula, Program, Term};
use rustc_hash::FxHashMap;

/// A literal of a formula clause before grounding.
#[derive(Debug, Clone)]
pub(super) enum ClauseLit {
    Atom {
        predicate: usize,
        args: Vec<Arg>,
        positive: bool,
    },
    Equal {
        a: Arg,
        b: Arg,
        positive: bool,
    },
}

/// An argument of a clause literal: a free variable (by index) or a constant id.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Arg {
    Var(usize),
    Const(u32),
}

/// Calls `visit` on every atom of a formula, left to right.
pub(super) fn for_each_atom<'a>(f: &'a Formula, visit: &mut impl FnMut(&'a Atom)) {
    match f {
        Formula::Atom(a) => visit(a),
        Formula::Equal(..) => {}
        Formula::Not(g) | Formula::Exists(_, g) | Formula::Forall(_, g) => for_each_atom(g, visit),
        Formula::And(v) | Formula::Or(v) => v.iter().for_each(|g| for_each_atom(g, visit)),
        Formula::Implies(a, b) | Formula::Iff(a, b) => {
            for_each_atom(a, visit);
            for_each_atom(b, visit);
        }
    }
}

/// The CNF clauses of a formula: free variable `free_vars[i]` becomes `Arg::Var(i)`,
/// quantified variables are expanded over `domains` (type name → constant ids) and constants
/// become their ids in `const_ids`.
pub(super) fn formula_clauses(
    formula: &Formula,
    free_vars: &[String],
    program: &Program,
    domains: &FxHashMap<String, Vec<u32>>,
    const_ids: &FxHashMap<String, u32>,
) -> Vec<Vec<ClauseLit>> {
    let mut scope = Scope {
        program,
        domains,
        var_index: free_vars
            .iter()
            .enumerate()
            .map(|(i, n)| (n.clone(), i))
            .collect(),
        bound: FxHashMap::default(),
    };
    let nnf = to_nnf(formula, true, &mut scope, const_ids);
    cnf(&nnf)
}

/// Negation normal form with quantifiers expanded over their domains.
#[derive(Debug, Clone)]
enum Nnf {
    Lit(ClauseLit),
    And(Vec<Nnf>),
    Or(Vec<Nnf>),
}

struct Scope<'a> {
    program: &'a Program,
    /// Type name → constant ids.
    domains: &'a FxHashMap<String, Vec<u32>>,
    var_index: FxHashMap<String, usize>,
    /// Quantified variables bound to constants during expansion.
    bound: FxHashMap<String, u32>,
}

fn to_nnf(f: &Formula, positive: bool, s: &mut Scope<'_>, consts: &FxHashMap<String, u32>) -> Nnf {
    let term = |t: &Term, s: &Scope<'_>| -> Arg {
        match t {
            Term::Var(v) => match s.bound.get(v.as_str()) {
                Some(&c) => Arg::Const(c),
                None => Arg::Var(s.var_index[v.as_str()]),
            },
            Term::Const(c) => Arg::Const(consts[c.as_str()]),
        }
    };
    match f {
        Formula::Atom(a) => Nnf::Lit(ClauseLit::Atom {
            predicate: a.predicate,
            args: a.args.iter().map(|t| term(t, s)).collect(),
            positive,
        }),
        Formula::Equal(pair) => Nnf::Lit(ClauseLit::Equal {
            a: term(&pair.0, s),
            b: term(&pair.1, s),
            positive,
        }),
        Formula::Not(g) => to_nnf(g, !positive, s, consts),
        Formula::And(v) | Formula::Or(v) => {
            let parts = v.iter().map(|g| to_nnf(g, positive, s, consts)).collect();
            if matches!(f, Formula::And(_)) == positive {
                Nnf::And(parts)
            } else {
                Nnf::Or(parts)
            }
        }
        Formula::Implies(a, b) => {
            let na = to_nnf(a, !positive, s, consts);
            let nb = to_nnf(b, positive, s, consts);
            if positive {
                Nnf::Or(vec![na, nb])
            } else {
                Nnf::And(vec![na, nb])
            }
        }
        Formula::Iff(a, b) => {
            // a <=> b ≡ (!a v b) ^ (a v !b);  !(a <=> b) ≡ (a v b) ^ (!a v !b)
            let (pa, na) = (to_nnf(a, true, s, consts), to_nnf(a, false, s, consts));
            let (pb, nb) = (to_nnf(b, true, s, consts), to_nnf(b, false, s, consts));
            if positive {
                Nnf::And(vec![Nnf::Or(vec![na, pb]), Nnf::Or(vec![pa, nb])])
            } else {
                Nnf::And(vec![Nnf::Or(vec![pa, pb]), Nnf::Or(vec![na, nb])])
            }
        }
        Formula::Exists(vars, g) | Formula::Forall(vars, g) => {
            let exists = matches!(f, Formula::Exists(..)) == positive;
            let mut parts = Vec::new();
            expand_quantifier(vars, 0, g, positive, s, consts, &mut parts);
            if exists {
                Nnf::Or(parts)
            } else {
                Nnf::And(parts)
            }
        }
    }
}

fn expand_quantifier(
    vars: &[String],
    k: usize,
    body: &Formula,
    positive: bool,
    s: &mut Scope<'_>,
    consts: &FxHashMap<String, u32>,
    out: &mut Vec<Nnf>,
) {
    if k == vars.len() {
        out.push(to_nnf(body, positive, s, consts));
        return;
    }
    let v = &vars[k];
    let ty = quantified_type(body, v, s.program).unwrap_or_default();
    let domain = s.domains.get(&ty).cloned().unwrap_or_default();
    let saved = s.bound.get(v).copied();
    for c in domain {
        s.bound.insert(v.clone(), c);
        expand_quantifier(vars, k + 1, body, positive, s, consts, out);
    }
    match saved {
        Some(c) => s.bound.insert(v.clone(), c),
        None => s.bound.remove(v),
    };
}

fn quantified_type(f: &Formula, var: &str, program: &Program) -> Option<String> {
    let mut found = None;
    for_each_atom(f, &mut |a| {
        for (t, ty) in a
            .args
            .iter()
            .zip(&program.predicates[a.predicate].arg_types)
        {
            if matches!(t, Term::Var(v) if v == var) && found.is_none() {
                found = Some(ty.to_string());
            }
        }
    });
    found
}

/// CNF of an NNF by distribution: a list of clauses.
fn cnf(n: &Nnf) -> Vec<Vec<ClauseLit>> {
    match n {
        Nnf::Lit(l) => vec![vec![l.clone()]],
        Nnf::And(parts) => parts.iter().flat_map(cnf).collect(),
        Nnf::Or(parts) => {
            let mut acc: Vec<Vec<ClauseLit>> = vec![Vec::new()];
            for p in parts {
                let pc = cnf(p);
                let mut next = Vec::with_capacity(acc.len() * pc.len());
                for a in &acc {
                    for c in &pc {
                        let mut m = a.clone();
                        m.extend(c.iter().cloned());
                        next.push(m);
                    }
                }
                acc = next;
            }
            acc
        }
    }
}

/// Free (non-quantified) variables of a formula with their types.
pub(super) fn free_variables(
    f: &Formula,
    program: &Program,
    path: &str,
    line: usize,
) -> Result<(Vec<String>, Vec<String>), GroundError> {
    let mut names: Vec<String> = Vec::new();
    let mut types: Vec<Option<String>> = Vec::new();
    let mut err = None;
    fn walk(
        f: &Formula,
        bound: &mut Vec<String>,
        program: &Program,
        names: &mut Vec<String>,
        types: &mut Vec<Option<String>>,
        err: &mut Option<(String, String, String)>,
    ) {
        let mut note = |v: &str,
                        ty: Option<&str>,
                        names: &mut Vec<String>,
                        types: &mut Vec<Option<String>>| {
            if bound.iter().any(|b| b == v) {
                return;
            }
            let i = match names.iter().position(|n| n == v) {
                Some(i) => i,
                None => {
                    names.push(v.to_owned());
                    types.push(None);
                    names.len() - 1
                }
            };
            if let Some(ty) = ty {
                match &types[i] {
                    None => types[i] = Some(ty.to_owned()),
                    Some(t) if t != ty && err.is_none() => {
                        *err = Some((v.to_owned(), t.clone(), ty.to_owned()));
                    }
                    _ => {}
                }
            }
        };
        match f {
            Formula::Atom(a) => {
                for (t, ty) in a
                    .args
                    .iter()
                    .zip(&program.predicates[a.predicate].arg_types)
                {
                    if let Term::Var(v) = t {
                        note(v, Some(ty.as_str()), names, types);
                    }
                }
            }
            Formula::Equal(pair) => {
                for t in [&pair.0, &pair.1] {
                    if let Term::Var(v) = t {
                        note(v, None, names, types);
                    }
                }
            }
            Formula::Not(g) => walk(g, bound, program, names, types, err),
            Formula::Exists(vs, g) | Formula::Forall(vs, g) => {
                let n = bound.len();
                bound.extend(vs.iter().cloned());
                walk(g, bound, program, names, types, err);
                bound.truncate(n);
            }
            Formula::And(v) | Formula::Or(v) => {
                for g in v {
                    walk(g, bound, program, names, types, err);
                }
            }
            Formula::Implies(a, b) | Formula::Iff(a, b) => {
                walk(a, bound, program, names, types, err);
                walk(b, bound, program, names, types, err);
            }
        }
    }
    walk(
        f,
        &mut Vec::new(),
        program,
        &mut names,
        &mut types,
        &mut err,
    );
    if let Some((var, first, second)) = err {
        return Err(GroundError::TypeClash {
            path: path.to_owned(),
            line,
            var,
            first,
            second,
        });
    }
    let mut out_types = Vec::with_capacity(types.len());
    for (n, t) in names.iter().zip(types) {
        match t {
            Some(t) => out_types.push(t),
            None => {
                return Err(GroundError::UntypedVariable {
                    path: path.to_owned(),
                    line,
                    var: n.clone(),
                })
            }
        }
    }
    Ok((names, out_types))
}
