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

use crate::parse::{Atom, EvidenceAtom, Formula, Program, Term, Weight};
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
    /// Grounding would exceed the configured size limit.
    #[error("formula at {path}:{line} has more than {limit} groundings; raise GroundOptions::max_groundings if this is intended")]
    TooLarge {
        /// Program file.
        path: String,
        /// Line of the formula.
        line: usize,
        /// The limit.
        limit: usize,
    },
}

/// Options of [`ground`].
#[derive(Debug, Clone)]
pub struct GroundOptions {
    /// Refuse formulas with more enumerated groundings than this (default 20 million: each
    /// kept grounding costs some 100 bytes, and the largest benchmark, KB, has 0.5 million;
    /// PR's formulas over two open predicates would enumerate billions and exhaust memory).
    pub max_groundings: usize,
}

impl Default for GroundOptions {
    fn default() -> Self {
        GroundOptions {
            max_groundings: 20_000_000,
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

/// Truth of a ground atom given the evidence.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum State {
    True,
    False,
    Unknown,
}

/// A literal of a formula clause before grounding.
#[derive(Debug, Clone)]
enum ClauseLit {
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

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Arg {
    Var(usize),
    Const(u32),
}

/// Evidence and domains, shared read-only by the parallel grounders.
/// A map keyed by the constant ids of one predicate's ground atoms. Atoms of arity ≤ 2 (almost
/// all in the benchmark sets) are packed into one `u64` key, so a lookup hashes one word
/// instead of a slice; all keys of one map have the predicate's arity, so packing is exact.
#[derive(Clone)]
struct AtomMap<V> {
    packed: FxHashMap<u64, V>,
    long: FxHashMap<Box<[u32]>, V>,
}

impl<V> Default for AtomMap<V> {
    fn default() -> Self {
        AtomMap {
            packed: FxHashMap::default(),
            long: FxHashMap::default(),
        }
    }
}

impl<V> AtomMap<V> {
    fn pack(args: &[u32]) -> Option<u64> {
        match *args {
            [] => Some(0),
            [a] => Some(u64::from(a)),
            [a, b] => Some(u64::from(a) << 32 | u64::from(b)),
            _ => None,
        }
    }

    fn get(&self, args: &[u32]) -> Option<&V> {
        match Self::pack(args) {
            Some(key) => self.packed.get(&key),
            None => self.long.get(args),
        }
    }

    /// Inserts by slice: allocates a key only for atoms of arity > 2.
    fn insert_slice(&mut self, args: &[u32], value: V) {
        match Self::pack(args) {
            Some(key) => {
                self.packed.insert(key, value);
            }
            None => {
                self.long.insert(args.into(), value);
            }
        }
    }

    fn insert(&mut self, args: Box<[u32]>, value: V) {
        match Self::pack(&args) {
            Some(key) => {
                self.packed.insert(key, value);
            }
            None => {
                self.long.insert(args, value);
            }
        }
    }
}

struct World<'a> {
    program: &'a Program,
    /// Per predicate: evidence atoms (constant ids) → truth value.
    evidence: Vec<AtomMap<bool>>,
    /// Per predicate: true facts.
    true_facts: Vec<Vec<Box<[u32]>>>,
    /// Per predicate, per argument position: constant → indices into `true_facts`.
    fact_index: Vec<Vec<FxHashMap<u32, Vec<u32>>>>,
    open: Vec<bool>,
    canopy: Vec<Option<AtomMap<()>>>,
    domains: FxHashMap<String, Vec<u32>>,
    /// Constant name → id (every constant of evidence, formulas and queries).
    const_ids: FxHashMap<String, u32>,
}

impl World<'_> {
    fn state(&self, predicate: usize, args: &[u32]) -> State {
        match self.evidence[predicate].get(args) {
            Some(true) => State::True,
            Some(false) => State::False,
            None if !self.open[predicate] => State::False,
            None => match &self.canopy[predicate] {
                Some(set) if set.get(args).is_none() => State::False,
                _ => State::Unknown,
            },
        }
    }
}

/// Interning of constant names.
#[derive(Default)]
struct Constants {
    names: Vec<String>,
    ids: FxHashMap<String, u32>,
}

impl Constants {
    fn id(&mut self, name: &str) -> u32 {
        if let Some(&i) = self.ids.get(name) {
            return i;
        }
        let i = self.names.len() as u32;
        self.names.push(name.to_owned());
        self.ids.insert(name.to_owned(), i);
        i
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
                && !domain_sets.get(t).is_some_and(|d| d.1.contains(&id))
            {
                return Err(GroundError::UnknownConstant {
                    path: evidence_path.to_owned(),
                    line: ev.line,
                    constant: c.clone(),
                    type_name: t.clone(),
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

/// A literal of a ground clause before atom interning: predicate, constants, polarity.
type GroundLit = (usize, Box<[u32]>, bool);

/// Groundings of one formula.
struct FormulaGroundings {
    /// Each factor: clauses of (predicate, args, positive) over unknown atoms.
    factors: Vec<Vec<Vec<GroundLit>>>,
    /// Groundings decided false by evidence alone.
    decided_false: usize,
    /// Groundings decided true by evidence alone (counted, not enumerated).
    decided_true: f64,
}

fn for_each_atom<'a>(f: &'a Formula, visit: &mut impl FnMut(&'a Atom)) {
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

/// Negation normal form with quantifiers expanded over their domains.
#[derive(Debug, Clone)]
enum Nnf {
    Lit(ClauseLit),
    And(Vec<Nnf>),
    Or(Vec<Nnf>),
}

struct Scope<'a> {
    world: &'a World<'a>,
    var_index: FxHashMap<String, usize>,
    /// Quantified variables bound to constants during expansion.
    bound: FxHashMap<String, u32>,
}

fn to_nnf(f: &Formula, positive: bool, s: &mut Scope<'_>, consts: &FxHashMap<String, u32>) -> Nnf {
    let term = |t: &Term, s: &Scope<'_>| -> Arg {
        match t {
            Term::Var(v) => match s.bound.get(v) {
                Some(&c) => Arg::Const(c),
                None => Arg::Var(s.var_index[v]),
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
        Formula::Equal(a, b) => Nnf::Lit(ClauseLit::Equal {
            a: term(a, s),
            b: term(b, s),
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
    let ty = quantified_type(body, v, s.world.program).unwrap_or_default();
    let domain = s.world.domains.get(&ty).cloned().unwrap_or_default();
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
                found = Some(ty.clone());
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
fn free_variables(
    f: &Formula,
    program: &Program,
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
                        ty: Option<&String>,
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
                    None => types[i] = Some(ty.clone()),
                    Some(t) if t != ty && err.is_none() => {
                        *err = Some((v.to_owned(), t.clone(), ty.clone()));
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
                        note(v, Some(ty), names, types);
                    }
                }
            }
            Formula::Equal(a, b) => {
                for t in [a, b] {
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
            path: program.path.clone(),
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
                    path: program.path.clone(),
                    line,
                    var: n.clone(),
                })
            }
        }
    }
    Ok((names, out_types))
}

fn ground_formula(
    world: &World<'_>,
    wf: &crate::parse::WeightedFormula,
    options: &GroundOptions,
) -> Result<FormulaGroundings, GroundError> {
    let program = world.program;
    let (names, types) = free_variables(&wf.formula, program, wf.line)?;
    let mut domains: Vec<&[u32]> = Vec::with_capacity(types.len());
    for (n, t) in names.iter().zip(&types) {
        match world.domains.get(t) {
            Some(d) if !d.is_empty() => domains.push(d),
            _ => {
                return Err(GroundError::EmptyDomain {
                    path: program.path.clone(),
                    line: wf.line,
                    var: n.clone(),
                    type_name: t.clone(),
                })
            }
        }
    }
    if matches!(wf.weight, Weight::Soft(w) if w == 0.0) {
        // Contributes to neither cost nor violated weight, and creates no atoms.
        return Ok(FormulaGroundings {
            factors: Vec::new(),
            decided_false: 0,
            decided_true: 0.0,
        });
    }
    let mut scope = Scope {
        world,
        var_index: names
            .iter()
            .enumerate()
            .map(|(i, n)| (n.clone(), i))
            .collect(),
        bound: FxHashMap::default(),
    };
    let nnf = to_nnf(&wf.formula, true, &mut scope, &world.const_ids);
    let clauses = cnf(&nnf);
    let total: f64 = domains.iter().map(|d| d.len() as f64).product();

    // Bindings that leave at least one clause unsatisfied by evidence: union over clauses.
    // A single clause enumerates each binding once, in a deterministic order, so it needs
    // neither the union set nor the sort.
    // Bindings flat, `stride` values each (one allocation for all of them).
    let stride = names.len();
    let mut sorted: Vec<u32> = Vec::new();
    let mut num_sorted = 0usize;
    let mut bindings: FxHashSet<Box<[u32]>> = FxHashSet::default();
    let single = clauses.len() == 1;
    for clause in &clauses {
        let mut binding: Vec<Option<u32>> = vec![None; names.len()];
        let clause_vars: Vec<usize> = {
            let mut v: Vec<usize> = clause.iter().flat_map(lit_vars).collect();
            v.sort_unstable();
            v.dedup();
            v
        };
        let mut found: Vec<u32> = Vec::new();
        let mut count = 0usize;
        enumerate_unsatisfied(
            world,
            clause,
            &clause_vars,
            &domains,
            &mut binding,
            (&mut found, &mut count),
            options
                .max_groundings
                .saturating_mul(clause_vars.len().max(1)),
        )
        .map_err(|()| GroundError::TooLarge {
            path: program.path.clone(),
            line: wf.line,
            limit: options.max_groundings,
        })?;
        // Extend over the formula's other variables.
        let others: Vec<usize> = (0..names.len())
            .filter(|v| !clause_vars.contains(v))
            .collect();
        let clause_stride = clause_vars.len();
        let mut full = vec![0u32; names.len()];
        for k in 0..count {
            for (j, &v) in clause_vars.iter().enumerate() {
                full[v] = found[k * clause_stride + j];
            }
            extend_product(&others, &domains, &mut full, 0, &mut |b| {
                if single {
                    sorted.extend_from_slice(b);
                    num_sorted += 1;
                } else {
                    bindings.insert(b.into());
                }
            });
            if num_sorted.max(bindings.len()) > options.max_groundings {
                return Err(GroundError::TooLarge {
                    path: program.path.clone(),
                    line: wf.line,
                    limit: options.max_groundings,
                });
            }
        }
    }
    if !single {
        let mut set: Vec<Box<[u32]>> = bindings.into_iter().collect();
        set.sort_unstable();
        num_sorted = set.len();
        sorted = set.concat();
    }
    let enumerated = num_sorted;
    let mut out = FormulaGroundings {
        factors: Vec::new(),
        decided_false: 0,
        decided_true: total - enumerated as f64,
    };
    // A formula without free variables has one empty binding.
    let bindings_iter: Box<dyn Iterator<Item = &[u32]>> = if stride == 0 {
        Box::new(std::iter::repeat_n(&[][..], num_sorted))
    } else {
        Box::new(sorted.chunks_exact(stride))
    };
    for b in bindings_iter {
        let mut ground_clauses: Vec<Vec<GroundLit>> = Vec::new();
        let mut formula_false = false;
        let mut formula_has_unknown = false;
        for clause in &clauses {
            let mut lits = Vec::new();
            let mut satisfied = false;
            for l in clause {
                match eval_lit(world, l, b) {
                    LitValue::True => {
                        satisfied = true;
                        break;
                    }
                    LitValue::False => {}
                    LitValue::Unknown(pred, args, positive) => lits.push((pred, args, positive)),
                }
            }
            if satisfied {
                continue;
            }
            if lits.is_empty() {
                formula_false = true;
                break;
            }
            lits.sort_unstable();
            lits.dedup();
            formula_has_unknown = true;
            ground_clauses.push(lits);
        }
        if formula_false {
            out.decided_false += 1;
        } else if formula_has_unknown {
            out.factors.push(ground_clauses);
        } else {
            out.decided_true += 1.0;
        }
    }
    Ok(out)
}

enum LitValue {
    True,
    False,
    Unknown(usize, Box<[u32]>, bool),
}

fn resolve(a: Arg, b: &[u32]) -> u32 {
    match a {
        Arg::Var(v) => b[v],
        Arg::Const(c) => c,
    }
}

fn eval_lit(world: &World<'_>, l: &ClauseLit, b: &[u32]) -> LitValue {
    match l {
        ClauseLit::Equal { a, b: c, positive } => {
            if (resolve(*a, b) == resolve(*c, b)) == *positive {
                LitValue::True
            } else {
                LitValue::False
            }
        }
        ClauseLit::Atom {
            predicate,
            args,
            positive,
        } => {
            let mut buf = [0u32; 8];
            let ground_vec: Vec<u32>;
            let ground: &[u32] = if args.len() <= buf.len() {
                for (g, a) in buf.iter_mut().zip(args) {
                    *g = resolve(*a, b);
                }
                &buf[..args.len()]
            } else {
                ground_vec = args.iter().map(|a| resolve(*a, b)).collect();
                &ground_vec
            };
            match world.state(*predicate, ground) {
                State::True => {
                    if *positive {
                        LitValue::True
                    } else {
                        LitValue::False
                    }
                }
                State::False => {
                    if *positive {
                        LitValue::False
                    } else {
                        LitValue::True
                    }
                }
                State::Unknown => LitValue::Unknown(*predicate, ground.into(), *positive),
            }
        }
    }
}

fn lit_vars(l: &ClauseLit) -> Vec<usize> {
    let args: Vec<Arg> = match l {
        ClauseLit::Atom { args, .. } => args.clone(),
        ClauseLit::Equal { a, b, .. } => vec![*a, *b],
    };
    args.into_iter()
        .filter_map(|a| match a {
            Arg::Var(v) => Some(v),
            Arg::Const(_) => None,
        })
        .collect()
}

fn extend_product(
    vars: &[usize],
    domains: &[&[u32]],
    full: &mut Vec<u32>,
    k: usize,
    emit: &mut impl FnMut(&[u32]),
) {
    if k == vars.len() {
        emit(full);
        return;
    }
    for &c in domains[vars[k]] {
        full[vars[k]] = c;
        extend_product(vars, domains, full, k + 1, emit);
    }
}

/// Whether a literal with all its variables bound is true by evidence.
fn bound_literal_true(world: &World<'_>, l: &ClauseLit, binding: &[Option<u32>]) -> Option<bool> {
    let get = |a: Arg| match a {
        Arg::Var(v) => binding[v],
        Arg::Const(c) => Some(c),
    };
    match l {
        ClauseLit::Equal { a, b, positive } => Some((get(*a)? == get(*b)?) == *positive),
        ClauseLit::Atom {
            predicate,
            args,
            positive,
        } => {
            let mut buf = [0u32; 8];
            let mut heap = Vec::new();
            let ground: &mut [u32] = if args.len() <= buf.len() {
                &mut buf[..args.len()]
            } else {
                heap.resize(args.len(), 0);
                &mut heap
            };
            for (g, a) in ground.iter_mut().zip(args) {
                *g = get(*a)?;
            }
            Some(match world.state(*predicate, ground) {
                State::True => *positive,
                State::False => !*positive,
                State::Unknown => false,
            })
        }
    }
}

/// Backtracking join: all bindings of `vars` under which no literal of the clause is true,
/// appended flat to `found.0` (one value per variable of `vars`, binding after binding) and
/// counted in `found.1` (a clause without variables has one empty binding).
fn enumerate_unsatisfied(
    world: &World<'_>,
    clause: &[ClauseLit],
    vars: &[usize],
    domains: &[&[u32]],
    binding: &mut Vec<Option<u32>>,
    found: (&mut Vec<u32>, &mut usize),
    limit: usize,
) -> Result<(), ()> {
    let (flat, count) = found;
    // Prune: a literal whose variables are all bound and which is true satisfies the clause.
    for l in clause {
        if bound_literal_true(world, l, binding) == Some(true) {
            return Ok(());
        }
    }
    if vars.iter().all(|&v| binding[v].is_some()) {
        flat.extend(vars.iter().map(|&v| binding[v].unwrap_or(0)));
        *count += 1;
        if *count > limit {
            return Err(());
        }
        return Ok(());
    }
    // A generator: a negative literal over a closed predicate with an unbound variable.
    let generator = clause.iter().find_map(|l| match l {
        ClauseLit::Atom {
            predicate,
            args,
            positive: false,
        } if !world.open[*predicate]
            && args
                .iter()
                .any(|a| matches!(a, Arg::Var(v) if binding[*v].is_none())) =>
        {
            Some((*predicate, args))
        }
        _ => None,
    });
    if let Some((predicate, args)) = generator {
        // Candidate facts: use the index on the first bound argument, else all facts.
        let bound_pos = args.iter().enumerate().find_map(|(pos, a)| match a {
            Arg::Const(c) => Some((pos, *c)),
            Arg::Var(v) => binding[*v].map(|c| (pos, c)),
        });
        let facts = &world.true_facts[predicate];
        let candidates: Box<dyn Iterator<Item = &Box<[u32]>>> = match bound_pos {
            Some((pos, c)) => match world.fact_index[predicate][pos].get(&c) {
                Some(ids) => Box::new(ids.iter().map(move |&i| &facts[i as usize])),
                None => Box::new(std::iter::empty()),
            },
            None => Box::new(facts.iter()),
        };
        for fact in candidates {
            let mut newly = Vec::new();
            let mut ok = true;
            for (a, &c) in args.iter().zip(fact.iter()) {
                match a {
                    Arg::Const(k) if *k != c => ok = false,
                    Arg::Var(v) => match binding[*v] {
                        Some(b) if b != c => ok = false,
                        Some(_) => {}
                        None => {
                            binding[*v] = Some(c);
                            newly.push(*v);
                        }
                    },
                    Arg::Const(_) => {}
                }
                if !ok {
                    break;
                }
            }
            if ok {
                enumerate_unsatisfied(
                    world,
                    clause,
                    vars,
                    domains,
                    binding,
                    (&mut *flat, &mut *count),
                    limit,
                )?;
            }
            for v in newly {
                binding[v] = None;
            }
        }
        return Ok(());
    }
    // Otherwise bind the first unbound variable over its domain.
    let Some(&v) = vars.iter().find(|&&v| binding[v].is_none()) else {
        return Ok(());
    };
    for &c in domains[v] {
        binding[v] = Some(c);
        enumerate_unsatisfied(
            world,
            clause,
            vars,
            domains,
            binding,
            (&mut *flat, &mut *count),
            limit,
        )?;
    }
    binding[v] = None;
    Ok(())
}
