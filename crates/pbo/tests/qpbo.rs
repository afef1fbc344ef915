//! Property tests of QPBO, probing and improve against brute-force enumeration.

use pbo::maxflow::Capacity;
use pbo::qpbo::{ImproveOptions, Label, ProbeOptions, Qpbo};
use proptest::prelude::*;

/// A random quadratic function: unary and pairwise energies in small integers.
#[derive(Debug, Clone)]
struct Function {
    n: usize,
    constant: i32,
    unary: Vec<(usize, i32, i32)>,
    pairs: Vec<(usize, usize, [i32; 4])>,
}

fn function_strategy(max_vars: usize, submodular: bool) -> impl Strategy<Value = Function> {
    (1usize..=max_vars).prop_flat_map(move |n| {
        (
            Just(n),
            -10i32..10,
            prop::collection::vec((0..n, -8i32..8, -8i32..8), 0..2 * n),
            prop::collection::vec((0..n, 0..n, prop::array::uniform4(-8i32..8)), 0..3 * n),
        )
            .prop_map(move |(n, constant, unary, pairs)| {
                let pairs = pairs
                    .into_iter()
                    .filter(|p| p.0 != p.1)
                    .map(|(i, j, mut e)| {
                        // Make it submodular: raise E01 until E00 + E11 <= E01 + E10.
                        if submodular && e[0] + e[3] > e[1] + e[2] {
                            e[1] += e[0] + e[3] - e[1] - e[2];
                        }
                        (i, j, e)
                    })
                    .collect();
                Function {
                    n,
                    constant,
                    unary,
                    pairs,
                }
            })
    })
}

fn build<T: Capacity>(f: &Function, conv: &dyn Fn(i32) -> T) -> Qpbo<T> {
    let mut q = Qpbo::<T>::new(f.n, f.pairs.len());
    q.add_constant(conv(f.constant));
    for &(i, e0, e1) in &f.unary {
        q.add_unary(i, conv(e0), conv(e1));
    }
    for &(i, j, e) in &f.pairs {
        q.add_pairwise(i, j, conv(e[0]), conv(e[1]), conv(e[2]), conv(e[3]));
    }
    q
}

fn assignment(n: usize, bits: u32) -> Vec<bool> {
    (0..n).map(|k| bits >> k & 1 == 1).collect()
}

const TOL: f64 = 1e-7;

/// All energies (as f64) by enumeration and the minimum.
fn enumerate<T: Capacity>(q: &Qpbo<T>) -> (Vec<f64>, f64) {
    let n = q.num_vars();
    let energies: Vec<f64> = (0..1u32 << n)
        .map(|b| q.energy(&assignment(n, b)).to_f64())
        .collect();
    let min = energies.iter().cloned().fold(f64::INFINITY, f64::min);
    (energies, min)
}

/// Minimum energy over assignments agreeing with `keep`.
fn min_agreeing(energies: &[f64], n: usize, keep: impl Fn(&[bool]) -> bool) -> f64 {
    (0..1u32 << n)
        .filter(|&b| keep(&assignment(n, b)))
        .map(|b| energies[b as usize])
        .fold(f64::INFINITY, f64::min)
}

fn check_qpbo<T: Capacity>(f: &Function, conv: &dyn Fn(i32) -> T) -> Result<(), TestCaseError> {
    let mut q = build(f, conv);
    let (energies, min) = enumerate(&q);
    q.solve();
    let twice = q.twice_lower_bound().to_f64();
    prop_assert!(
        twice <= 2.0 * min + TOL,
        "bound {} > min {}",
        twice / 2.0,
        min
    );
    prop_assert!(q.lower_bound().to_f64() <= min + TOL);
    // Strong persistency: every global minimiser agrees with every label.
    let strong: Vec<Label> = q.labels().to_vec();
    for (b, &e) in energies.iter().enumerate() {
        if e <= min + TOL {
            let x = assignment(f.n, b as u32);
            for (i, l) in strong.iter().enumerate() {
                if let Some(v) = l.value() {
                    prop_assert_eq!(
                        x[i],
                        v,
                        "minimiser {:?} disagrees with strong label of x{}",
                        x,
                        i
                    );
                }
            }
        }
    }
    // Weak persistency: some global minimiser extends all labels jointly.
    q.compute_weak_persistencies();
    let weak: Vec<Label> = q.labels().to_vec();
    for (s, w) in strong.iter().zip(&weak) {
        if s.value().is_some() {
            prop_assert_eq!(s, w);
        }
    }
    let m = min_agreeing(&energies, f.n, |x| {
        weak.iter()
            .zip(x)
            .all(|(l, &xi)| l.value().is_none_or(|v| v == xi))
    });
    prop_assert!(
        (m - min).abs() <= TOL,
        "weak labels {:?}: best extension {} min {}",
        weak,
        m,
        min
    );
    // Autarky: overwriting any assignment with the weak labels never increases energy.
    for b in [0u32, (1 << f.n) - 1, 0x5555_5555 & ((1 << f.n) - 1)] {
        let x = assignment(f.n, b);
        let y: Vec<bool> = x
            .iter()
            .zip(&weak)
            .map(|(&xi, l)| l.value().unwrap_or(xi))
            .collect();
        prop_assert!(q.energy(&y).to_f64() <= q.energy(&x).to_f64() + TOL);
    }
    Ok(())
}

fn check_submodular<T: Capacity>(
    f: &Function,
    conv: &dyn Fn(i32) -> T,
) -> Result<(), TestCaseError> {
    let mut q = build(f, conv);
    let (_, min) = enumerate(&q);
    q.solve();
    prop_assert!((q.twice_lower_bound().to_f64() - 2.0 * min).abs() <= TOL);
    q.compute_weak_persistencies();
    prop_assert_eq!(q.num_labelled(), f.n);
    let x = q.labelling_or_zero();
    prop_assert!((q.energy(&x).to_f64() - min).abs() <= TOL);
    Ok(())
}

fn check_probe<T: Capacity>(
    f: &Function,
    weak: bool,
    conv: &dyn Fn(i32) -> T,
) -> Result<(), TestCaseError> {
    let mut q = build(f, conv);
    let (energies, min) = enumerate(&q);
    let options = ProbeOptions {
        weak_persistencies: weak,
        ..ProbeOptions::default()
    };
    let res = q.probe(&options);
    let consistent = |x: &[bool]| {
        (0..f.n).all(|i| {
            res.fixed[i].is_none_or(|v| x[i] == v)
                && res.equivalent[i].is_none_or(|(j, neg)| x[i] == (x[j] ^ neg))
        })
    };
    let m = min_agreeing(&energies, f.n, consistent);
    prop_assert!(
        (m - min).abs() <= TOL,
        "probe result {:?}: best extension {} min {}",
        res,
        m,
        min
    );
    if !weak {
        for (b, &e) in energies.iter().enumerate() {
            if e <= min + TOL {
                prop_assert!(
                    consistent(&assignment(f.n, b as u32)),
                    "a minimiser violates strong probing"
                );
            }
        }
    }
    prop_assert!(res.best_energy >= min - TOL);
    prop_assert!((q.energy(&res.best_assignment).to_f64() - res.best_energy).abs() <= TOL);
    for (i, fx) in res.fixed.iter().enumerate() {
        if let Some(v) = fx {
            prop_assert_eq!(q.label(i), Label::from_bool(*v));
        }
    }
    Ok(())
}

fn check_improve<T: Capacity>(
    f: &Function,
    start: u32,
    seed: u64,
    conv: &dyn Fn(i32) -> T,
) -> Result<(), TestCaseError> {
    let mut q = build(f, conv);
    let mut x = assignment(f.n, start & ((1u32 << f.n) - 1));
    let before = q.energy(&x).to_f64();
    let options = ImproveOptions {
        rounds: 5,
        seed,
        ..ImproveOptions::default()
    };
    let after = q.improve(&mut x, &options);
    prop_assert!(after.to_f64() <= before + TOL);
    prop_assert_eq!(after.to_f64(), q.energy(&x).to_f64());
    Ok(())
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(300))]

    #[test]
    fn qpbo_persistencies_i32(f in function_strategy(12, false)) {
        check_qpbo::<i32>(&f, &|v| v)?;
    }

    #[test]
    fn qpbo_persistencies_i64(f in function_strategy(12, false)) {
        check_qpbo::<i64>(&f, &|v| i64::from(v) * 1000)?;
    }

    #[test]
    fn qpbo_persistencies_f64(f in function_strategy(12, false)) {
        check_qpbo::<f64>(&f, &|v| f64::from(v) * 0.35)?;
    }

    #[test]
    fn submodular_is_fully_labelled_and_optimal_i32(f in function_strategy(12, true)) {
        check_submodular::<i32>(&f, &|v| v)?;
    }

    #[test]
    fn submodular_is_fully_labelled_and_optimal_f64(f in function_strategy(12, true)) {
        check_submodular::<f64>(&f, &|v| f64::from(v) * 1.5)?;
    }

    #[test]
    fn probing_is_jointly_persistent_i32(f in function_strategy(10, false), weak in any::<bool>()) {
        check_probe::<i32>(&f, weak, &|v| v)?;
    }

    #[test]
    fn probing_is_jointly_persistent_i64(f in function_strategy(10, false), weak in any::<bool>()) {
        check_probe::<i64>(&f, weak, &|v| i64::from(v))?;
    }

    #[test]
    fn probing_is_jointly_persistent_f64(f in function_strategy(10, false), weak in any::<bool>()) {
        check_probe::<f64>(&f, weak, &|v| f64::from(v) * 0.35)?;
    }

    #[test]
    fn improve_never_increases_energy_i32(f in function_strategy(12, false), start in any::<u32>(), seed in any::<u64>()) {
        check_improve::<i32>(&f, start, seed, &|v| v)?;
    }

    #[test]
    fn improve_never_increases_energy_f64(f in function_strategy(12, false), start in any::<u32>(), seed in any::<u64>()) {
        check_improve::<f64>(&f, start, seed, &|v| f64::from(v) * 0.35)?;
    }
}

/// Larger functions (14 variables, dense non-submodular terms) for the persistency check.
#[test]
fn qpbo_persistencies_on_fourteen_variables() {
    use rand::{Rng, SeedableRng};
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(14);
    for _ in 0..20 {
        let n = 14;
        let f = Function {
            n,
            constant: 0,
            unary: (0..n)
                .map(|i| (i, rng.gen_range(-5..5), rng.gen_range(-5..5)))
                .collect(),
            pairs: (0..30)
                .map(|_| {
                    let i = rng.gen_range(0..n);
                    let j = (i + rng.gen_range(1..n)) % n;
                    (i, j, [0, 0, 0, 0].map(|_: i32| rng.gen_range(-8..8)))
                })
                .collect(),
        };
        let r = check_qpbo::<i32>(&f, &|v| v);
        assert!(r.is_ok(), "{r:?}");
    }
}

/// Measures (does not assert) how often improve reaches the optimum from a random start.
#[test]
fn improve_success_rate_is_reported() {
    use rand::{Rng, SeedableRng};
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
    let (mut optimal, mut total) = (0, 0);
    for _ in 0..100 {
        let n = 10;
        let f = Function {
            n,
            constant: 0,
            unary: (0..n)
                .map(|i| (i, rng.gen_range(-5..5), rng.gen_range(-5..5)))
                .collect(),
            pairs: (0..20)
                .map(|_| {
                    let i = rng.gen_range(0..n);
                    let j = (i + rng.gen_range(1..n)) % n;
                    (i, j, [0, 0, 0, 0].map(|_: i32| rng.gen_range(-8..8)))
                })
                .collect(),
        };
        let mut q = build::<i32>(&f, &|v| v);
        let (_, min) = enumerate(&q);
        let mut x: Vec<bool> = (0..n).map(|_| rng.gen_bool(0.5)).collect();
        let e = q.improve(
            &mut x,
            &ImproveOptions {
                rounds: 20,
                seed: 1,
                ..ImproveOptions::default()
            },
        );
        total += 1;
        if f64::from(e) == min {
            optimal += 1;
        }
    }
    eprintln!(
        "improve (20 rounds) reached the optimum on {optimal}/{total} random 10-variable functions"
    );
    assert_eq!(total, 100);
}
