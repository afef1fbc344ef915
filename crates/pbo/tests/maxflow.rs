//! Property tests of Boykov–Kolmogorov max-flow against an Edmonds–Karp reference.

use pbo::maxflow::{Capacity, Graph, Segment};
use proptest::prelude::*;
use std::collections::VecDeque;

/// A random s-t network: per-node terminal weights (signed) and edges with parallels,
/// reverse pairs and zero capacities.
#[derive(Debug, Clone)]
struct Net {
    n: usize,
    tweights: Vec<(usize, i32, i32)>,
    edges: Vec<(usize, usize, i32, i32)>,
}

fn net_strategy() -> impl Strategy<Value = Net> {
    (2usize..9).prop_flat_map(|n| {
        (
            Just(n),
            prop::collection::vec((0..n, -5i32..12, -5i32..12), 0..12),
            prop::collection::vec((0..n, 0..n, 0i32..10, 0i32..10), 0..24),
        )
            .prop_map(|(n, tweights, edges)| Net {
                n,
                tweights,
                edges: edges.into_iter().filter(|e| e.0 != e.1).collect(),
            })
    })
}

/// Edmonds–Karp on a dense matrix; returns the max-flow value including the constant that
/// signed terminal weights move out (min(source, sink) per node).
fn reference_maxflow(
    n: usize,
    source: &[f64],
    sink: &[f64],
    edges: &[(usize, usize, f64, f64)],
) -> f64 {
    let (s, t) = (n, n + 1);
    let size = n + 2;
    let mut cap = vec![vec![0.0f64; size]; size];
    let mut constant = 0.0;
    for i in 0..n {
        let m = source[i].min(sink[i]);
        constant += m;
        cap[s][i] += source[i] - m;
        cap[i][t] += sink[i] - m;
    }
    for &(i, j, c, r) in edges {
        cap[i][j] += c;
        cap[j][i] += r;
    }
    let mut flow = 0.0;
    loop {
        let mut prev = vec![usize::MAX; size];
        prev[s] = s;
        let mut queue = VecDeque::from([s]);
        while let Some(u) = queue.pop_front() {
            for v in 0..size {
                if prev[v] == usize::MAX && cap[u][v] > 1e-12 {
                    prev[v] = u;
                    queue.push_back(v);
                }
            }
        }
        if prev[t] == usize::MAX {
            break;
        }
        let mut b = f64::INFINITY;
        let mut v = t;
        while v != s {
            b = b.min(cap[prev[v]][v]);
            v = prev[v];
        }
        let mut v = t;
        while v != s {
            cap[prev[v]][v] -= b;
            cap[v][prev[v]] += b;
            v = prev[v];
        }
        flow += b;
    }
    flow + constant
}

fn close(a: f64, b: f64) -> bool {
    (a - b).abs() <= 1e-9 * (1.0 + a.abs().max(b.abs()))
}

/// Builds the graph in type T (capacities scaled by `scale` before conversion).
fn build<T: Capacity>(net: &Net, conv: &dyn Fn(i32) -> T) -> Graph<T> {
    let mut g = Graph::<T>::new(net.n, net.edges.len());
    for &(i, s, t) in &net.tweights {
        g.add_tweights(i, conv(s), conv(t));
    }
    for &(i, j, c, r) in &net.edges {
        g.add_edge(i, j, conv(c), conv(r));
    }
    g
}

fn terminal_sums(net: &Net, factor: f64) -> (Vec<f64>, Vec<f64>) {
    let mut source = vec![0.0; net.n];
    let mut sink = vec![0.0; net.n];
    for &(i, s, t) in &net.tweights {
        source[i] += f64::from(s) * factor;
        sink[i] += f64::from(t) * factor;
    }
    (source, sink)
}

/// Checks value against the reference and that the returned cut has that capacity.
fn check<T: Capacity>(
    net: &Net,
    factor: f64,
    conv: &dyn Fn(i32) -> T,
) -> Result<(), TestCaseError> {
    let mut g = build(net, conv);
    let flow = g.maxflow(false).to_f64();
    let (source, sink) = terminal_sums(net, factor);
    let edges: Vec<(usize, usize, f64, f64)> = net
        .edges
        .iter()
        .map(|&(i, j, c, r)| (i, j, f64::from(c) * factor, f64::from(r) * factor))
        .collect();
    let reference = reference_maxflow(net.n, &source, &sink, &edges);
    prop_assert!(
        close(flow, reference),
        "flow {} reference {}",
        flow,
        reference
    );
    // Capacity of the returned cut, constants included.
    let mut cut = 0.0;
    for i in 0..net.n {
        let m = source[i].min(sink[i]);
        cut += m;
        cut += match g.segment(i) {
            Segment::Source => sink[i] - m,
            Segment::Sink => source[i] - m,
        };
    }
    for &(i, j, c, r) in &edges {
        match (g.segment(i), g.segment(j)) {
            (Segment::Source, Segment::Sink) => cut += c,
            (Segment::Sink, Segment::Source) => cut += r,
            _ => {}
        }
    }
    prop_assert!(close(cut, flow), "cut {} flow {}", cut, flow);
    // The source tree is closed under residual arcs: tree nodes are on the source side.
    for i in 0..net.n {
        if g.tree(i) == Some(Segment::Sink) {
            prop_assert_eq!(g.segment(i), Segment::Sink);
        }
    }
    // The trees are exactly the residual reachability sets (the same for every maximum
    // flow, so QPBO's labels do not depend on the order in which paths are augmented).
    let (from_source, to_sink) = residual_reachability(&g, net.n);
    for i in 0..net.n {
        prop_assert_eq!(
            g.tree(i) == Some(Segment::Source),
            from_source[i],
            "node {}",
            i
        );
        prop_assert_eq!(g.tree(i) == Some(Segment::Sink), to_sink[i], "node {}", i);
    }
    Ok(())
}

/// Nodes reachable from the source and nodes reaching the sink in the residual graph of
/// `g` after a solve, by fixpoint iteration (brute force).
fn residual_reachability<T: Capacity>(g: &Graph<T>, n: usize) -> (Vec<bool>, Vec<bool>) {
    let eps = g.tolerance();
    let zero = T::default();
    let mut arcs = Vec::new();
    for i in 0..n {
        g.for_each_residual_arc(i, |j, _| arcs.push((i, j)));
    }
    let mut from_source: Vec<bool> = (0..n).map(|i| g.tr_residual(i) > eps).collect();
    let mut to_sink: Vec<bool> = (0..n).map(|i| g.tr_residual(i) < zero - eps).collect();
    let mut changed = true;
    while changed {
        changed = false;
        for &(i, j) in &arcs {
            if from_source[i] && !from_source[j] {
                from_source[j] = true;
                changed = true;
            }
            if to_sink[j] && !to_sink[i] {
                to_sink[i] = true;
                changed = true;
            }
        }
    }
    (from_source, to_sink)
}

/// Changes applied after a first solve: signed t-weights, capacity increases, new edges.
#[derive(Debug, Clone)]
struct Changes {
    tweights: Vec<(usize, i32, i32)>,
    grow: Vec<(usize, i32, i32)>,
}

fn changes_strategy() -> impl Strategy<Value = Changes> {
    (
        prop::collection::vec((0usize..9, -6i32..8, -6i32..8), 0..6),
        prop::collection::vec((0usize..24, 0i32..6, 0i32..6), 0..6),
    )
        .prop_map(|(tweights, grow)| Changes { tweights, grow })
}

fn check_reuse<T: Capacity>(
    net: &Net,
    ch: &Changes,
    conv: &dyn Fn(i32) -> T,
) -> Result<(), TestCaseError> {
    let mut g = build(net, conv);
    g.maxflow(false);
    let mut fresh_net = net.clone();
    for &(i, s, t) in &ch.tweights {
        let i = i % net.n;
        g.add_tweights(i, conv(s), conv(t));
        g.mark_node(i);
        fresh_net.tweights.push((i, s, t));
    }
    if !net.edges.is_empty() {
        for &(e, d, rd) in &ch.grow {
            let e = e % net.edges.len();
            g.add_edge_capacity(e, conv(d), conv(rd));
            let (i, j, _, _) = net.edges[e];
            g.mark_node(i);
            g.mark_node(j);
            fresh_net.edges[e].2 += d;
            fresh_net.edges[e].3 += rd;
        }
    }
    let reused = g.maxflow(true).to_f64();
    let fresh = build(&fresh_net, conv).maxflow(false).to_f64();
    prop_assert!(close(reused, fresh), "reused {} fresh {}", reused, fresh);
    Ok(())
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(1000))]

    #[test]
    fn maxflow_i32_equals_edmonds_karp(net in net_strategy()) {
        check::<i32>(&net, 1.0, &|v| v)?;
    }

    #[test]
    fn maxflow_i64_equals_edmonds_karp(net in net_strategy()) {
        check::<i64>(&net, 1.0, &|v| i64::from(v))?;
    }

    #[test]
    fn maxflow_f64_equals_edmonds_karp(net in net_strategy()) {
        check::<f64>(&net, 0.35, &|v| f64::from(v) * 0.35)?;
    }

    #[test]
    fn tree_reuse_equals_fresh_solve_i32(net in net_strategy(), ch in changes_strategy()) {
        check_reuse::<i32>(&net, &ch, &|v| v)?;
    }

    #[test]
    fn tree_reuse_equals_fresh_solve_f64(net in net_strategy(), ch in changes_strategy()) {
        check_reuse::<f64>(&net, &ch, &|v| f64::from(v) * 1.5)?;
    }
}

#[test]
fn edges_added_after_a_solve_are_included() {
    let mut g = Graph::<i32>::new(3, 2);
    g.add_tweights(0, 5, 0);
    g.add_tweights(2, 0, 5);
    g.add_edge(0, 1, 4, 0);
    assert_eq!(g.maxflow(false), 0);
    g.add_edge(1, 2, 3, 0);
    g.mark_node(1);
    g.mark_node(2);
    assert_eq!(g.maxflow(true), 3);
}
