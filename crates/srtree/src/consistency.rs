//! Consistency of the relations by a Markov logic network (thesis §3.3.2), MAP by `mln`.
//!
//! The knowledge base over objects `a, b, c` of one scene:
//!
//! ```text
//! On(a,b) => !On(b,a).            LeftOf(a,b) => !LeftOf(b,a).     Behind(a,b) => !Behind(b,a).
//! On(a,b) => !LeftOf(b,a).        On(a,b) => !LeftOf(a,b).
//! On(a,b) => !Behind(b,a).        On(a,b) => !Behind(a,b).
//! LeftOf(a,b) <=> RightOf(b,a).   Behind(a,b) <=> InFrontOf(b,a).
//! w_T  P(a,b) ^ P(b,c) => P(a,c)          for P in On, LeftOf, Behind
//! w_E  PSvm(a,b) <=> P(a,b)               for P in On, LeftOf, Behind
//! ```
//!
//! Antisymmetry and the exclusivity of On hold by the relations' definitions, so they are
//! hard (ending in `.`), as are the RightOf/InFrontOf complements; the transitivity and the
//! classifier-evidence formulas are soft, with one weight per predicate learnt
//! discriminatively by the voted perceptron (Singla & Domingos, "Discriminative training of
//! Markov logic networks", AAAI 2005): per epoch, over all training scenes, `w_i += η (n_i(y)
//! − n_i(MAP_w))` with `n_i` the number of true groundings of formula i, and the average of
//! the epochs' weights is returned. `PSvm` atoms are closed-world evidence.
//!
//! The relations of a subject that is a ground surface are false by the annotation
//! protocol, so only atoms with a non-ground subject are unknown (explicit query atoms).

use crate::error::{Result, SrtreeError};
use crate::graph::Relation;
use mln::ground::{ground, GroundOptions};
use mln::infer::{map_inference, InferOptions};
use mln::parse::{parse_evidence, parse_program, parse_query};
use mln::walksat::{max_walk_sat, Factor, WalkSatOptions};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// Truth values of the three base relations for every ordered pair of a scene's objects.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct Assignment {
    /// Number of objects.
    pub n: usize,
    /// `bits[a·n + b]`: [`Relation::bit`] of each base relation that holds for (a, b).
    pub bits: Vec<u8>,
}

impl Assignment {
    /// All false.
    pub fn empty(n: usize) -> Assignment {
        Assignment {
            n,
            bits: vec![0; n * n],
        }
    }

    /// Whether `r(a, b)` holds.
    pub fn get(&self, r: Relation, a: usize, b: usize) -> bool {
        self.bits[a * self.n + b] & r.bit() != 0
    }

    /// Sets `r(a, b)`.
    pub fn set(&mut self, r: Relation, a: usize, b: usize, value: bool) {
        let bits = &mut self.bits[a * self.n + b];
        if value {
            *bits |= r.bit();
        } else {
            *bits &= !r.bit();
        }
    }
}

/// One scene for the MLN: which objects may be subjects, and the classifier's output.
#[derive(Debug, Clone)]
pub struct MlnScene {
    /// Per object: may it be the subject of a relation (not a ground surface)?
    pub subject: Vec<bool>,
    /// The classifier's decisions.
    pub svm: Assignment,
}

/// The soft weights: transitivity and evidence per base relation (On, LeftOf, Behind).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct MlnWeights {
    /// `P(a,b) ^ P(b,c) => P(a,c)`.
    pub transitivity: [f64; 3],
    /// `PSvm(a,b) <=> P(a,b)`.
    pub evidence: [f64; 3],
}

impl Default for MlnWeights {
    fn default() -> Self {
        MlnWeights {
            transitivity: [1.0; 3],
            evidence: [2.0; 3],
        }
    }
}

/// The knowledge base as MLN text for objects `O0 … O{n−1}`.
pub fn program_text(n: usize, w: &MlnWeights) -> String {
    let consts: Vec<String> = (0..n).map(|i| format!("O{i}")).collect();
    let mut s = format!("obj = {{ {} }}\n", consts.join(", "));
    for p in ["On", "LeftOf", "Behind", "RightOf", "InFrontOf"] {
        s += &format!("{p}(obj, obj)\n");
    }
    for p in ["On", "LeftOf", "Behind"] {
        s += &format!("*{p}Svm(obj, obj)\n");
    }
    for p in ["On", "LeftOf", "Behind"] {
        s += &format!("{p}(a,b) => !{p}(b,a).\n");
    }
    for q in ["LeftOf", "Behind"] {
        s += &format!("On(a,b) => !{q}(b,a).\nOn(a,b) => !{q}(a,b).\n");
    }
    s += "LeftOf(a,b) <=> RightOf(b,a).\nBehind(a,b) <=> InFrontOf(b,a).\n";
    for (k, p) in ["On", "LeftOf", "Behind"].iter().enumerate() {
        s += &format!("{:.6} {p}(a,b) ^ {p}(b,c) => {p}(a,c)\n", w.transitivity[k]);
        s += &format!("{:.6} {p}Svm(a,b) <=> {p}(a,b)\n", w.evidence[k]);
    }
    s
}

/// MAP relations of one scene under the knowledge base.
pub fn map_relations(
    scene: &MlnScene,
    w: &MlnWeights,
    options: &InferOptions,
) -> Result<Assignment> {
    let n = scene.subject.len();
    let mut out = Assignment::empty(n);
    if n < 2 || !scene.subject.iter().any(|&s| s) {
        return Ok(out);
    }
    let err = |e: &dyn std::fmt::Display| SrtreeError::Mln(e.to_string());
    let program = parse_program(&program_text(n, w), "relations.mln").map_err(|e| err(&e))?;
    let mut evidence = String::new();
    let mut query = String::new();
    for a in 0..n {
        for b in 0..n {
            if a == b || !scene.subject[a] {
                continue;
            }
            for r in Relation::BASE {
                if scene.svm.get(r, a, b) {
                    evidence += &format!("{}Svm(O{a},O{b})\n", r.name());
                }
                query += &format!("{}(O{a},O{b})\n", r.name());
            }
            query += &format!("RightOf(O{b},O{a})\nInFrontOf(O{b},O{a})\n");
        }
    }
    let ev = parse_evidence(&evidence, "relations.db", &program).map_err(|e| err(&e))?;
    let q = parse_query(&query, "relations.query", &program).map_err(|e| err(&e))?;
    let problem = ground(&program, &ev, "relations.db", &q, &GroundOptions::default())
        .map_err(|e| err(&e))?;
    let result = map_inference(&problem, options);
    // A second search started from the classifier's decisions (complements filled in):
    // MaxWalkSAT on the ground formulas; the better of the two answers is kept.
    let idx = |c: u32| -> Option<usize> {
        problem
            .constants
            .get(c as usize)?
            .strip_prefix('O')?
            .parse()
            .ok()
    };
    let start: Vec<bool> = problem
        .atoms
        .iter()
        .map(|atom| {
            let name = &program.predicates[atom.predicate].name;
            let (Some(a), Some(b)) = (
                atom.args.first().and_then(|&c| idx(c)),
                atom.args.get(1).and_then(|&c| idx(c)),
            ) else {
                return false;
            };
            match Relation::from_name(name) {
                Some(Relation::RightOf) => scene.svm.get(Relation::LeftOf, b, a),
                Some(Relation::InFrontOf) => scene.svm.get(Relation::Behind, b, a),
                Some(r) => scene.svm.get(r, a, b),
                None => false,
            }
        })
        .collect();
    let factors: Vec<Factor> = problem
        .factors
        .iter()
        .map(|f| Factor {
            weight: f.weight,
            clauses: f.clauses.clone(),
        })
        .collect();
    let (walk, _) = max_walk_sat(
        &factors,
        problem.atoms.len(),
        Some(&start),
        &WalkSatOptions {
            max_flips: 20 * problem.atoms.len().max(100),
            chains: 1,
            ..options.walksat.clone()
        },
    );
    let key = |x: &[bool]| {
        let s = problem.score(x);
        (s.hard_violations, s.cost)
    };
    let (k1, k2) = (key(&result.assignment), key(&walk));
    let best = if k2.0 < k1.0 || (k2.0 == k1.0 && k2.1 < k1.1) {
        &walk
    } else {
        &result.assignment
    };
    for (i, atom) in problem.atoms.iter().enumerate() {
        if !best[i] {
            continue;
        }
        let name = &program.predicates[atom.predicate].name;
        let Some(r) = Relation::from_name(name) else {
            continue;
        };
        if !Relation::BASE.contains(&r) {
            continue;
        }
        if let (Some(a), Some(b)) = (
            atom.args.first().and_then(|&c| idx(c)),
            atom.args.get(1).and_then(|&c| idx(c)),
        ) {
            if a < n && b < n {
                out.set(r, a, b, true);
            }
        }
    }
    Ok(out)
}

/// True groundings of the soft formulas (transitivity ×3, evidence ×3) over distinct
/// objects; constant offsets relative to `mln`'s grounding cancel in the perceptron.
pub fn soft_counts(x: &Assignment, scene: &MlnScene) -> [f64; 6] {
    let n = x.n;
    let mut c = [0.0; 6];
    for (k, r) in Relation::BASE.into_iter().enumerate() {
        let mut trans = 0usize;
        let mut agree = 0usize;
        for a in 0..n {
            for b in 0..n {
                if a == b {
                    continue;
                }
                if scene.subject[a] && x.get(r, a, b) == scene.svm.get(r, a, b) {
                    agree += 1;
                }
                let ab = x.get(r, a, b);
                for cc in 0..n {
                    if cc == a || cc == b {
                        continue;
                    }
                    if !(ab && x.get(r, b, cc)) || x.get(r, a, cc) {
                        trans += 1;
                    }
                }
            }
        }
        c[k] = trans as f64;
        c[3 + k] = agree as f64;
    }
    c
}

/// Violations of the hard rules (antisymmetry and exclusivity of On) in an assignment.
pub fn hard_violations(x: &Assignment) -> usize {
    let n = x.n;
    let mut v = 0;
    for a in 0..n {
        for b in 0..n {
            if a == b {
                continue;
            }
            for r in Relation::BASE {
                v += usize::from(x.get(r, a, b) && x.get(r, b, a));
            }
            if x.get(Relation::On, a, b) {
                for q in [Relation::LeftOf, Relation::Behind] {
                    v += usize::from(x.get(q, b, a)) + usize::from(x.get(q, a, b));
                }
            }
        }
    }
    v
}

/// Options of [`learn_weights`].
#[derive(Debug, Clone)]
pub struct LearnOptions {
    /// Perceptron epochs.
    pub epochs: usize,
    /// Step size per unit of count difference per scene.
    pub learning_rate: f64,
    /// MAP inference settings.
    pub infer: InferOptions,
}

impl Default for LearnOptions {
    fn default() -> Self {
        LearnOptions {
            epochs: 5,
            learning_rate: 0.01,
            infer: InferOptions {
                tabu_moves: 5000,
                ..InferOptions::default()
            },
        }
    }
}

/// Starting weights from counts in the training scenes: each soft formula's log-odds of
/// holding where it is not trivially true (evidence: the classifier agrees with the label;
/// transitivity: the conclusion holds where both premises do), with add-one smoothing.
pub fn initial_weights(scenes: &[(MlnScene, Assignment)]) -> MlnWeights {
    let mut held = [0.0f64; 6];
    let mut broken = [0.0f64; 6];
    for (s, y) in scenes {
        let n = y.n;
        for (k, r) in Relation::BASE.into_iter().enumerate() {
            for a in 0..n {
                for b in 0..n {
                    if a == b || !s.subject[a] {
                        continue;
                    }
                    if y.get(r, a, b) == s.svm.get(r, a, b) {
                        held[3 + k] += 1.0;
                    } else {
                        broken[3 + k] += 1.0;
                    }
                    if !y.get(r, a, b) {
                        continue;
                    }
                    for c in 0..n {
                        if c != a && c != b && y.get(r, b, c) {
                            if y.get(r, a, c) {
                                held[k] += 1.0;
                            } else {
                                broken[k] += 1.0;
                            }
                        }
                    }
                }
            }
        }
    }
    let w = |k: usize| (((held[k] + 1.0) / (broken[k] + 1.0)).ln()).max(0.0);
    MlnWeights {
        transitivity: [w(0), w(1), w(2)],
        evidence: [w(3), w(4), w(5)],
    }
}

/// Voted-perceptron weight learning on training scenes with their (annotated) relations.
pub fn learn_weights(
    scenes: &[(MlnScene, Assignment)],
    start: &MlnWeights,
    options: &LearnOptions,
) -> Result<MlnWeights> {
    let mut w = start.clone();
    let mut sum = [0.0; 6];
    let epochs = options.epochs.max(1);
    let truth_counts: Vec<[f64; 6]> = scenes.iter().map(|(s, y)| soft_counts(y, s)).collect();
    for _ in 0..epochs {
        let maps: Vec<Result<[f64; 6]>> = scenes
            .par_iter()
            .map(|(s, _)| Ok(soft_counts(&map_relations(s, &w, &options.infer)?, s)))
            .collect();
        let mut grad = [0.0; 6];
        for (t, m) in truth_counts.iter().zip(maps) {
            let m = m?;
            for k in 0..6 {
                grad[k] += t[k] - m[k];
            }
        }
        let scale = options.learning_rate / scenes.len().max(1) as f64;
        for k in 0..3 {
            w.transitivity[k] = (w.transitivity[k] + scale * grad[k]).max(0.0);
            w.evidence[k] = (w.evidence[k] + scale * grad[3 + k]).max(0.0);
        }
        for k in 0..3 {
            sum[k] += w.transitivity[k];
            sum[3 + k] += w.evidence[k];
        }
    }
    let e = epochs as f64;
    Ok(MlnWeights {
        transitivity: [sum[0] / e, sum[1] / e, sum[2] / e],
        evidence: [sum[3] / e, sum[4] / e, sum[5] / e],
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scene(n: usize) -> MlnScene {
        MlnScene {
            subject: vec![true; n],
            svm: Assignment::empty(n),
        }
    }

    #[test]
    fn map_repairs_antisymmetry_and_exclusivity() {
        let mut s = scene(3);
        // The classifier says both LeftOf(0,1) and LeftOf(1,0), and On(0,2) with LeftOf(0,2).
        s.svm.set(Relation::LeftOf, 0, 1, true);
        s.svm.set(Relation::LeftOf, 1, 0, true);
        s.svm.set(Relation::On, 0, 2, true);
        s.svm.set(Relation::LeftOf, 0, 2, true);
        assert_eq!(hard_violations(&s.svm), 3);
        let x = map_relations(&s, &MlnWeights::default(), &InferOptions::default()).unwrap();
        assert_eq!(hard_violations(&x), 0);
        assert!(x.get(Relation::LeftOf, 0, 1) ^ x.get(Relation::LeftOf, 1, 0));
        // Agreeing with the classifier where it is consistent.
        let mut t = scene(3);
        t.svm.set(Relation::Behind, 2, 1, true);
        let y = map_relations(&t, &MlnWeights::default(), &InferOptions::default()).unwrap();
        assert_eq!(y, t.svm);
    }

    #[test]
    fn map_equals_brute_force_on_two_objects() {
        // Two objects: 6 base atoms; enumerate all 64 assignments under the same weights.
        let w = MlnWeights {
            transitivity: [0.5, 0.7, 0.3],
            evidence: [1.0, 0.8, 1.3],
        };
        for pattern in 0..64u32 {
            let mut s = scene(2);
            for (bit, (r, a, b)) in [
                (Relation::On, 0, 1),
                (Relation::On, 1, 0),
                (Relation::LeftOf, 0, 1),
                (Relation::LeftOf, 1, 0),
                (Relation::Behind, 0, 1),
                (Relation::Behind, 1, 0),
            ]
            .into_iter()
            .enumerate()
            {
                s.svm.set(r, a, b, pattern >> bit & 1 == 1);
            }
            let score = |x: &Assignment| {
                let c = soft_counts(x, &s);
                (0..3)
                    .map(|k| w.transitivity[k] * c[k] + w.evidence[k] * c[3 + k])
                    .sum::<f64>()
            };
            let mut best = f64::NEG_INFINITY;
            for q in 0..64u32 {
                let mut x = Assignment::empty(2);
                for (bit, (r, a, b)) in [
                    (Relation::On, 0, 1),
                    (Relation::On, 1, 0),
                    (Relation::LeftOf, 0, 1),
                    (Relation::LeftOf, 1, 0),
                    (Relation::Behind, 0, 1),
                    (Relation::Behind, 1, 0),
                ]
                .into_iter()
                .enumerate()
                {
                    x.set(r, a, b, q >> bit & 1 == 1);
                }
                if hard_violations(&x) == 0 {
                    best = best.max(score(&x));
                }
            }
            let got = map_relations(&s, &w, &InferOptions::default()).unwrap();
            assert_eq!(hard_violations(&got), 0);
            assert!((score(&got) - best).abs() < 1e-9, "pattern {pattern:#b}");
        }
    }

    #[test]
    fn perceptron_raises_the_weight_of_reliable_evidence() {
        // The classifier is right except for antisymmetric double predictions.
        let mut scenes = Vec::new();
        for k in 0..4 {
            let mut s = scene(3);
            let mut y = Assignment::empty(3);
            y.set(Relation::LeftOf, 0, 1, true);
            y.set(Relation::LeftOf, 1, 2, true);
            y.set(Relation::LeftOf, 0, 2, true);
            s.svm = y.clone();
            if k % 2 == 0 {
                s.svm.set(Relation::LeftOf, 2, 0, true);
            }
            scenes.push((s, y));
        }
        let start = MlnWeights {
            transitivity: [0.0; 3],
            evidence: [0.0; 3],
        };
        let w = learn_weights(&scenes, &start, &LearnOptions::default()).unwrap();
        assert!(w.evidence[1] > 0.0, "{w:?}");
    }
}
