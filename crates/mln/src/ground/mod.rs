//! Grounding: an MLN program, its evidence and its queries → ground formulas over unknown
//! atoms, simplified by evidence (thesis §3.2.3), as a pseudo-Boolean cost function (PBMLN).
//!
//! **Conventions** (scripts compare on them):
//! - The unknown atoms (the variables) are the atoms of *open* predicates not fixed by
//!   evidence. Open predicates are the query predicates and, in programs that mark closed
//!   predicates with Tuffy's `*`, every predicate without `*` (Tuffy/RockIt read them
//!   open-world). All other predicates are closed world: an atom not in the evidence is false.
//!   When the query lists ground atoms of a predicate explicitly (the "canopy" of ER and
//!   KB3), only those atoms are unknown and every other atom of it is false.
//! - One ground formula is one factor with the formula's weight w: it contributes
//!   −w·[F true] to the cost (eq. 3.1), with \[F\] = Π_clauses (1 − Π_{l∈C} l̄) in the literals
//!   of its CNF (thesis, after §3.2.3). Groundings with equal arguments are kept unless the
//!   formula says `x != y`. Hard formulas get a weight larger than the sum of all soft
//!   weights and are reported separately.
//! - Groundings decided by evidence alone are dropped from the cost but counted in
//!   `violated_weight`: Σ over all groundings of w where w > 0 and F is false, plus |w| where
//!   w < 0 and F is true.
//!
//! Each clause is grounded by a join: a negative literal over a closed predicate can only
//! leave the clause unsatisfied where the atom is true, so its true evidence tuples (indexed
//! by argument position) generate the bindings; other variables range over their domains;
//! each binding is pruned as soon as a literal is true by evidence. Formulas ground in
//! parallel (rayon).

mod cnf;
mod expand;
mod join;
mod lazy;

use crate::parse::{Atom, EvidenceAtom, Program, Term, Weight};
use cnf::for_each_atom;
pub use expand::expand_per_constant;
use join::{ground_formula, AtomMap, Constants, FormulaGroundings, World};
use pbo::polynomial::{Literal, Polynomial};
use rayon::prelude::*;
use rustc_hash::{FxHashMap, FxHashSet};
use thiserror::Error;

/// Why a program could not be grounded.
#[derive(Debug, Error)]
pub enum GroundError {
    /// A variable is used at argument positions of different types.
    #[error("{path}:{line}: variable `{var}` is used both as {first} and as {second}")]
    TypeClash {
        /// Program file.
        path: String,
        /// Line of the formula.
        line: usize,
        /// The variable.
        var: String,
        /// One type.
        first: String,
        /// The other type.
        second: String,
    },
    /// A type with no constants (nothing declared, nothing in evidence or formulas).
    #[error("{path}:{line}: type `{type_name}` of variable `{var}` has an empty domain: declare its constants or give evidence that mentions them")]
    EmptyDomain {
        /// Program file.
        path: String,
        /// Line of the formula.
        line: usize,
        /// The variable.
        var: String,
        /// Its type.
        type_name: String,
    },
    /// A variable whose type cannot be inferred (only in equalities).
    #[error("{path}:{line}: cannot infer the type of variable `{var}`: it must appear as an argument of some atom")]
    UntypedVariable {
        /// Program file.
        path: String,
        /// Line of the formula.
        line: usize,
        /// The variable.
        var: String,
    },
    /// Evidence mentions a constant not in the declared domain of a closed type.
    #[error(
        "{path}:{line}: constant `{constant}` is not in the declared domain of type `{type_name}`"
    )]
    UnknownConstant {
        /// Evidence file.
        path: String,
        /// Line.
        line: usize,
        /// The constant.
        constant: String,
        /// The declared type.
        type_name: String,
    },
    /// A formula with Alchemy's `+x` reached grounding unexpanded.
    #[error("{path}:{line}: the formula has per-constant variables (`+`): expand them first (mln::ground::expand_per_constant)")]
    PerConstantUnexpanded {
        /// Program file.
        path: String,
        /// Line of the formula.
        line: usize,
    },
    /// Alchemy's `+x` would write out too many formulas.
    #[error("{path}:{line}: the per-constant variables (`+`) of the program expand into {count} formulas by this one, more than the {limit} supported")]
    TooManyPerConstant {
        /// Program file.
        path: String,
        /// Line of the formula.
        line: usize,
        /// Formulas the expansion would write.
        count: u64,
        /// The limit.
        limit: usize,
    },
    /// Grounding would exceed the configured size limit.
    #[error("formula at {path}:{line} has more than {limit} groundings (at about 100 bytes each, {} or more); raise the cap (`--max-groundings N`, GroundOptions::max_groundings) if the memory is there", memory_text(*limit as f64 * 100.0))]
    TooLarge {
        /// Program file.
        path: String,
        /// Line of the formula.
        line: usize,
        /// The limit.
        limit: usize,
    },
}

/// Bytes as a short text: `2.0 GB`, `95 MB`, `3 kB`.
fn memory_text(bytes: f64) -> String {
    if bytes >= 1e9 {
        format!("{:.1} GB", bytes / 1e9)
    } else if bytes >= 1e6 {
        format!("{:.0} MB", bytes / 1e6)
    } else {
        format!("{:.0} kB", (bytes / 1e3).max(1.0))
    }
}

/// Options of [`ground`].
#[derive(Debug, Clone)]
pub struct GroundOptions {
    /// Refuse formulas with more enumerated groundings than this (default 20 million: each
    /// kept grounding costs some 100 bytes, and the largest benchmark, KB, has 0.5 million;
    /// PR's formulas over two open predicates would enumerate billions and exhaust memory).
    pub max_groundings: usize,
    /// Ground lazily for MAP inference: open predicates that no formula could profit from
    /// making true are grounded closed-world (a per-predicate active closure); MAP-exact, not for
    /// marginals or learning.
    pub lazy: bool,
}

impl Default for GroundOptions {
    fn default() -> Self {
        GroundOptions {
            max_groundings: 20_000_000,
            lazy: false,
        }
    }
}

impl GroundOptions {
    /// The defaults of MAP inference: lazy.
    pub fn map() -> Self {
        GroundOptions {
            lazy: true,
            ..GroundOptions::default()
        }
    }
}

/// A ground atom: predicate index and constant ids (see [`GroundProblem::constants`]).
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub struct GroundAtom {
    /// Index into the program's predicates.
    pub predicate: usize,
    /// Constant ids.
    pub args: Box<[u32]>,
}

/// One ground formula that still contains unknown atoms: CNF clauses over atom variables.
#[derive(Debug, Clone)]
pub struct GroundFactor {
    /// The formula's weight (hard formulas carry [`GroundProblem::hard_weight`]).
    pub weight: f64,
    /// Whether it comes from a hard formula.
    pub hard: bool,
    /// Index of the program formula it grounds (into `Program::formulas`).
    pub formula: usize,
    /// Clauses (disjunctions of literals over atom variables) whose conjunction is the formula.
    pub clauses: Vec<Vec<Literal>>,
}

impl GroundFactor {
    /// Whether the ground formula holds under an assignment of the atom variables.
    pub fn is_true(&self, x: &[bool]) -> bool {
        self.clauses
            .iter()
            .all(|c| c.iter().any(|l| l.eval(x[l.var() as usize])))
    }
}

/// The ground MAP problem.
#[derive(Debug, Clone)]
pub struct GroundProblem {
    /// Interned constants (id → name).
    pub constants: Vec<String>,
    /// The unknown atoms; atom i is polynomial variable i.
    pub atoms: Vec<GroundAtom>,
    /// Ground formulas still containing unknown atoms.
    pub factors: Vec<GroundFactor>,
    /// The cost to minimise: Σ −w·\[F\] over `factors` (soft and hard).
    pub cost: Polynomial,
    /// The weight given to hard formulas.
    pub hard_weight: f64,
    /// `violated_weight` of the groundings decided by evidence alone.
    pub constant_violated_weight: f64,
    /// Hard groundings violated by evidence alone.
    pub constant_hard_violations: usize,
    /// Open predicates grounded lazily: their atoms outside the evidence are false
    /// ([`GroundOptions::lazy`]).
    pub inactive_predicates: Vec<usize>,
}

/// Cost measures of an assignment (see the module documentation).
#[derive(Debug, Clone, PartialEq)]
pub struct Scores {
    /// −Σ w·\[F\] over the soft factors with unknown atoms (hard ones excluded).
    pub cost: f64,
    /// Σ w over false positive-weight groundings plus Σ |w| over true negative-weight ones,
    /// all groundings (soft), evidence-decided ones included.
    pub violated_weight: f64,
    /// Violated hard groundings (evidence-decided ones included).
    pub hard_violations: usize,
}

impl GroundProblem {
    /// Number of factors of degree ≥ 3 in the cost polynomial's sense (≥ 3 distinct atoms).
    pub fn higher_order_factors(&self) -> usize {
        self.factors
            .iter()
            .filter(|f| {
                let mut vars: Vec<u32> = f.clauses.iter().flatten().map(|l| l.var()).collect();
                vars.sort_unstable();
                vars.dedup();
                vars.len() >= 3
            })
            .count()
    }

    /// The scores of an assignment of the unknown atoms.
    pub fn score(&self, x: &[bool]) -> Scores {
        let mut s = Scores {
            cost: 0.0,
            violated_weight: self.constant_violated_weight,
            hard_violations: self.constant_hard_violations,
        };
        for f in &self.factors {
            let t = f.is_true(x);
            if f.hard {
                s.hard_violations += usize::from(!t);
                continue;
            }
            if t {
                s.cost -= f.weight;
            }
            if (f.weight > 0.0 && !t) || (f.weight < 0.0 && t) {
                s.violated_weight += f.weight.abs();
            }
        }
        s
    }

    /// A readable name of atom variable `i`, like `Smokes(Anna)`.
    pub fn atom_name(&self, program: &Program, i: usize) -> String {
        let a = &self.atoms[i];
        let args: Vec<&str> = a
            .args
            .iter()
            .map(|&c| self.constants[c as usize].as_str())
            .collect();
        format!(
            "{}({})",
            program.predicates[a.predicate].name,
            args.join(",")
        )
    }

    /// The same ground problem with the soft factors of formula i weighted by `weights[i]`
    /// (hard factors keep [`GroundProblem::hard_weight`], raised if the new soft weights
    /// need it); the cost polynomial is rebuilt. The evidence-decided part
    /// (`constant_violated_weight`) is left as grounded. Used by weight learning, which
    /// grounds once with unit weights.
    pub fn with_formula_weights(&self, weights: &[f64]) -> GroundProblem {
        let weight_of = |f: &GroundFactor| weights.get(f.formula).copied().unwrap_or(f.weight);
        let soft_total: f64 = self
            .factors
            .iter()
            .filter(|f| !f.hard)
            .map(|f| weight_of(f).abs())
            .sum();
        let hard_weight = self.hard_weight.max((soft_total + 1.0) * 1.0e3);
        let factors: Vec<GroundFactor> = self
            .factors
            .iter()
            .filter_map(|f| {
                let weight = if f.hard { hard_weight } else { weight_of(f) };
                (weight != 0.0).then(|| GroundFactor {
                    weight,
                    ..f.clone()
                })
            })
            .collect();
        GroundProblem {
            constants: self.constants.clone(),
            atoms: self.atoms.clone(),
            cost: cost_polynomial(self.atoms.len(), &factors),
            factors,
            hard_weight,
            constant_violated_weight: self.constant_violated_weight,
            constant_hard_violations: self.constant_hard_violations,
            inactive_predicates: self.inactive_predicates.clone(),
        }
    }

    /// Per formula of the program (`formulas` of them), the number of its soft ground
    /// factors that hold under `x` (n_i(x) of the MLN's log-linear form, less the
    /// groundings decided by evidence, which do not depend on `x`).
    pub fn true_counts(&self, formulas: usize, x: &[bool]) -> Vec<f64> {
        let mut n = vec![0.0; formulas];
        for f in self.factors.iter().filter(|f| !f.hard) {
            if let Some(c) = n.get_mut(f.formula) {
                *c += f64::from(u8::from(f.is_true(x)));
            }
        }
        n
    }
}

/// Grounds a program with evidence and query atoms into a MAP problem.
pub fn ground(
    program: &Program,
    evidence: &[EvidenceAtom],
    evidence_path: &str,
    query: &[Atom],
    options: &GroundOptions,
) -> Result<GroundProblem, GroundError> {
    if let Some(f) = program.formulas.iter().find(|f| !f.per_constant.is_empty()) {
        return Err(GroundError::PerConstantUnexpanded {
            path: program.file_of(f).to_owned(),
            line: f.line,
        });
    }
    let np = program.predicates.len();
    let mut consts = Constants::default();
    // Domains: declared constants, then constants seen in evidence, formulas and queries.
    let mut domain_sets: FxHashMap<String, (Vec<u32>, FxHashSet<u32>)> = FxHashMap::default();
    let declared: FxHashSet<&str> = program.types.iter().map(|t| t.name.as_str()).collect();
    for t in &program.types {
        let entry = domain_sets.entry(t.name.clone()).or_default();
        for c in &t.constants {
            let id = consts.id(c);
            if entry.1.insert(id) {
                entry.0.push(id);
            }
        }
    }
    let add_const =
        |type_name: &str, id: u32, domains: &mut FxHashMap<String, (Vec<u32>, FxHashSet<u32>)>| {
            let entry = domains.entry(type_name.to_owned()).or_default();
            if entry.1.insert(id) {
                entry.0.push(id);
            }
        };
    let mut evidence_map: FxHashMap<(usize, Box<[u32]>), bool> = FxHashMap::default();
    for ev in evidence {
        let pred = &program.predicates[ev.predicate];
        let mut args = Vec::with_capacity(ev.args.len());
        for (c, t) in ev.args.iter().zip(&pred.arg_types) {
            let id = consts.id(c);
            if declared.contains(t.as_str())
                && !domain_sets
                    .get(t.as_str())
                    .is_some_and(|d| d.1.contains(&id))
            {
                return Err(GroundError::UnknownConstant {
                    path: evidence_path.to_owned(),
                    line: ev.line,
                    constant: c.to_string(),
                    type_name: t.to_string(),
                });
            }
            add_const(t, id, &mut domain_sets);
            args.push(id);
        }
        evidence_map.insert((ev.predicate, args.into_boxed_slice()), ev.value);
    }
    let note_atom_constants =
        |atom: &Atom,
         consts: &mut Constants,
         domains: &mut FxHashMap<String, (Vec<u32>, FxHashSet<u32>)>| {
            for (t, ty) in atom
                .args
                .iter()
                .zip(&program.predicates[atom.predicate].arg_types)
            {
                if let Term::Const(c) = t {
                    let id = consts.id(c);
                    add_const(ty, id, domains);
                }
            }
        };
    for f in &program.formulas {
        for_each_atom(&f.formula, &mut |a| {
            note_atom_constants(a, &mut consts, &mut domain_sets)
        });
    }
    for a in query {
        note_atom_constants(a, &mut consts, &mut domain_sets);
    }

    // Open predicates and canopies.
    let tuffy_style = program.predicates.iter().any(|p| p.closed_world);
    let mut open: Vec<bool> = program
        .predicates
        .iter()
        .map(|p| tuffy_style && !p.closed_world)
        .collect();
    let mut canopy: Vec<Option<AtomMap<()>>> = vec![None; np];
    let mut listed_all: Vec<bool> = vec![false; np];
    for a in query {
        open[a.predicate] = true;
        let ground_args: Option<Vec<u32>> = a
            .args
            .iter()
            .map(|t| match t {
                Term::Const(c) => Some(consts.id(c)),
                Term::Var(_) => None,
            })
            .collect();
        match ground_args {
            Some(args) => {
                canopy[a.predicate]
                    .get_or_insert_with(AtomMap::default)
                    .insert(args.into_boxed_slice(), ());
            }
            None => listed_all[a.predicate] = true,
        }
    }
    for (p, all) in listed_all.iter().enumerate() {
        if *all {
            canopy[p] = None;
        }
    }

    let mut true_facts: Vec<Vec<Box<[u32]>>> = vec![Vec::new(); np];
    for ((p, args), &v) in &evidence_map {
        if v {
            true_facts[*p].push(args.clone());
        }
    }
    let mut inactive = Vec::new();
    if options.lazy {
        let has_true: Vec<bool> = true_facts.iter().map(|f| !f.is_empty()).collect();
        let active = lazy::active_predicates(program, &open, &has_true);
        for p in 0..np {
            if open[p] && !active[p] {
                open[p] = false;
                inactive.push(p);
            }
        }
    }
    for facts in &mut true_facts {
        facts.sort_unstable();
    }
    let fact_index: Vec<Vec<FxHashMap<u32, Vec<u32>>>> = true_facts
        .iter()
        .enumerate()
        .map(|(p, facts)| {
            let arity = program.predicates[p].arg_types.len();
            let mut idx: Vec<FxHashMap<u32, Vec<u32>>> = vec![FxHashMap::default(); arity];
            for (i, f) in facts.iter().enumerate() {
                for (pos, &c) in f.iter().enumerate() {
                    idx[pos].entry(c).or_default().push(i as u32);
                }
            }
            idx
        })
        .collect();
    let domains: FxHashMap<String, Vec<u32>> =
        domain_sets.into_iter().map(|(k, v)| (k, v.0)).collect();
    let mut evidence_by_pred: Vec<AtomMap<bool>> = vec![AtomMap::default(); np];
    for ((p, args), v) in evidence_map {
        evidence_by_pred[p].insert(args, v);
    }
    let world = World {
        program,
        evidence: evidence_by_pred,
        true_facts,
        fact_index,
        open,
        canopy,
        domains,
        const_ids: std::mem::take(&mut consts.ids),
    };

    let soft_total: f64 = program
        .formulas
        .iter()
        .map(|f| match f.weight {
            Weight::Soft(w) => w.abs(),
            Weight::Hard => 0.0,
        })
        .sum();
    let hard_weight = (soft_total + 1.0).max(1.0) * 1.0e3;

    // Ground every formula in parallel.
    let per_formula: Vec<Result<FormulaGroundings, GroundError>> = program
        .formulas
        .par_iter()
        .map(|f| ground_formula(&world, f, options))
        .collect();

    // Intern atoms in formula order (deterministic), build factors and the polynomial.
    // Per predicate: constant ids → atom variable (packed keys, see `AtomMap`).
    let mut atom_ids: Vec<AtomMap<u32>> = vec![AtomMap::default(); np];
    let mut atoms: Vec<GroundAtom> = Vec::new();
    let mut factors = Vec::new();
    let mut constant_violated_weight = 0.0;
    let mut constant_hard_violations = 0;
    for (formula_index, (formula, result)) in program.formulas.iter().zip(per_formula).enumerate() {
        let g = result?;
        let (weight, hard) = match formula.weight {
            Weight::Soft(w) => (w, false),
            Weight::Hard => (hard_weight, true),
        };
        if hard {
            constant_hard_violations += g.decided_false;
        } else if weight > 0.0 {
            constant_violated_weight += weight * g.decided_false as f64;
        } else {
            constant_violated_weight += -weight * g.decided_true;
        }
        if weight == 0.0 {
            continue;
        }
        for clauses in g.factors {
            let clauses: Vec<Vec<Literal>> = clauses
                .into_iter()
                .map(|c| {
                    c.into_iter()
                        .map(|(pred, args, positive)| {
                            let id = match atom_ids[pred].get(&args) {
                                Some(&id) => id,
                                None => {
                                    let id = atoms.len() as u32;
                                    atom_ids[pred].insert_slice(&args, id);
                                    atoms.push(GroundAtom {
                                        predicate: pred,
                                        args,
                                    });
                                    id
                                }
                            };
                            Literal::new(id, positive)
                        })
                        .collect()
                })
                .collect();
            factors.push(GroundFactor {
                weight,
                hard,
                formula: formula_index,
                clauses,
            });
        }
    }
    let cost = cost_polynomial(atoms.len(), &factors);
    Ok(GroundProblem {
        constants: consts.names,
        atoms,
        factors,
        cost,
        hard_weight,
        constant_violated_weight,
        constant_hard_violations,
        inactive_predicates: inactive,
    })
}

/// Σ −w·[F] over the factors as one simplified polynomial in `n` atoms.
fn cost_polynomial(n: usize, factors: &[GroundFactor]) -> Polynomial {
    let mut cost = Polynomial::new(n);
    for f in factors {
        add_factor_polynomial(&mut cost, f);
    }
    cost.simplify(1e-12);
    cost
}

/// Adds −w·Π_C (1 − Π_{l∈C} l̄) to the cost.
fn add_factor_polynomial(cost: &mut Polynomial, f: &GroundFactor) {
    if let [clause] = f.clauses.as_slice() {
        // −w·(1 − Π l̄) = −w + w·Π l̄ (most factors are single clauses).
        let negs: Vec<Literal> = clause.iter().map(|l| l.complement()).collect();
        cost.add_constant(-f.weight);
        cost.add_term(f.weight, &negs);
        return;
    }
    // Expand the product over clauses: each clause contributes 1 or −Π l̄.
    let mut terms: Vec<(f64, Vec<Literal>)> = vec![(1.0, Vec::new())];
    for clause in &f.clauses {
        let negs: Vec<Literal> = clause.iter().map(|l| l.complement()).collect();
        let mut next = Vec::with_capacity(terms.len() * 2);
        for (a, lits) in &terms {
            next.push((*a, lits.clone()));
            let mut l2 = lits.clone();
            l2.extend_from_slice(&negs);
            next.push((-a, l2));
        }
        terms = next;
    }
    for (a, lits) in terms {
        cost.add_term(-f.weight * a, &lits);
    }
}
