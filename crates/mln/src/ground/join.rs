//! The evidence join that grounds one formula: the evidence and domains shared by the
//! grounders (`World`), and the backtracking join of each clause against them.

use super::cnf::{formula_clauses, free_variables, Arg, ClauseLit};
use super::{GroundError, GroundOptions};
use crate::parse::{Program, Weight};
use rustc_hash::{FxHashMap, FxHashSet};

/// Truth of a ground atom given the evidence.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum State {
    True,
    False,
    Unknown,
}

/// A map keyed by the constant ids of one predicate's ground atoms. Atoms of arity ≤ 2 (almost
/// all in the benchmark sets) are packed into one `u64` key, so a lookup hashes one word
/// instead of a slice; all keys of one map have the predicate's arity, so packing is exact.
#[derive(Clone)]
pub(super) struct AtomMap<V> {
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

    pub(super) fn get(&self, args: &[u32]) -> Option<&V> {
        match Self::pack(args) {
            Some(key) => self.packed.get(&key),
            None => self.long.get(args),
        }
    }

    /// Inserts by slice: allocates a key only for atoms of arity > 2.
    pub(super) fn insert_slice(&mut self, args: &[u32], value: V) {
        match Self::pack(args) {
            Some(key) => {
                self.packed.insert(key, value);
            }
            None => {
                self.long.insert(args.into(), value);
            }
        }
    }

    pub(super) fn insert(&mut self, args: Box<[u32]>, value: V) {
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

/// Evidence and domains, shared read-only by the parallel grounders.
pub(super) struct World<'a> {
    pub(super) program: &'a Program,
    /// Per predicate: evidence atoms (constant ids) → truth value.
    pub(super) evidence: Vec<AtomMap<bool>>,
    /// Per predicate: true facts.
    pub(super) true_facts: Vec<Vec<Box<[u32]>>>,
    /// Per predicate, per argument position: constant → indices into `true_facts`.
    pub(super) fact_index: Vec<Vec<FxHashMap<u32, Vec<u32>>>>,
    /// Per predicate: whether it is open (its atoms outside the evidence are unknown).
    pub(super) open: Vec<bool>,
    /// Per predicate: the query atoms listed explicitly, when only those are unknown.
    pub(super) canopy: Vec<Option<AtomMap<()>>>,
    /// Type name → constant ids.
    pub(super) domains: FxHashMap<String, Vec<u32>>,
    /// Constant name → id (every constant of evidence, formulas and queries).
    pub(super) const_ids: FxHashMap<String, u32>,
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
pub(super) struct Constants {
    pub(super) names: Vec<String>,
    pub(super) ids: FxHashMap<String, u32>,
}

impl Constants {
    pub(super) fn id(&mut self, name: &str) -> u32 {
        if let Some(&i) = self.ids.get(name) {
            return i;
        }
        let i = self.names.len() as u32;
        self.names.push(name.to_owned());
        self.ids.insert(name.to_owned(), i);
        i
    }
}

/// A literal of a ground clause before atom interning: predicate, constants, polarity.
pub(super) type GroundLit = (usize, Box<[u32]>, bool);

/// Groundings of one formula.
pub(super) struct FormulaGroundings {
    /// Each factor: clauses of (predicate, args, positive) over unknown atoms.
    pub(super) factors: Vec<Vec<Vec<GroundLit>>>,
    /// Groundings decided false by evidence alone.
    pub(super) decided_false: usize,
    /// Groundings decided true by evidence alone (counted, not enumerated).
    pub(super) decided_true: f64,
}

/// The groundings of one formula that evidence leaves undecided (as factors over unknown
/// atoms), and the counts of those it decides.
pub(super) fn ground_formula(
    world: &World<'_>,
    wf: &crate::parse::WeightedFormula,
    options: &GroundOptions,
) -> Result<FormulaGroundings, GroundError> {
    let program = world.program;
    let (names, types) = free_variables(&wf.formula, program, program.file_of(wf), wf.line)?;
    let mut domains: Vec<&[u32]> = Vec::with_capacity(types.len());
    for (n, t) in names.iter().zip(&types) {
        match world.domains.get(t) {
            Some(d) if !d.is_empty() => domains.push(d),
            _ => {
                return Err(GroundError::EmptyDomain {
                    path: program.file_of(wf).to_owned(),
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
    let clauses = formula_clauses(
        &wf.formula,
        &names,
        program,
        &world.domains,
        &world.const_ids,
    );
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
            path: program.file_of(wf).to_owned(),
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
                    path: program.file_of(wf).to_owned(),
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
