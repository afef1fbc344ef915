//! Boykov–Kolmogorov max-flow / min-cut with search trees, orphan adoption and tree reuse.
//!
//! Implements Y. Boykov and V. Kolmogorov, "An experimental comparison of min-cut/max-flow
//! algorithms for energy minimization in vision", PAMI 26(9), 2004,
//! doi:10.1109/TPAMI.2004.60, with the distance/timestamp heuristics of their reference
//! implementation and the tree reuse of Kohli & Torr (dynamic graph cuts, ICCV 2005).
//! A fresh solve first saturates, in one cache-friendly sweep, every path source → i → j →
//! sink of a single arc (most of the augmenting paths on vision grids), then grows the trees.
//!
//! The graph is kept as a compact arc array (CSR: the arcs of node `i` are
//! `first[i]..first[i + 1]`, `u32` indices, every arc knows its sister), built once at the
//! first call to [`Graph::maxflow`]. Terminal links are stored per node as one signed
//! residual `tr_cap` (> 0: residual from the source, < 0: residual to the sink).
//! Worst case O(m·n²·|C|); on vision grids it is close to linear in practice.
//!
//! ```
//! use pbo::maxflow::{Graph, Segment};
//! let mut g = Graph::<i32>::new(2, 1);
//! g.add_tweights(0, 5, 0);
//! g.add_tweights(1, 0, 4);
//! g.add_edge(0, 1, 3, 0);
//! assert_eq!(g.maxflow(false), 3);
//! assert_eq!(g.segment(0), Segment::Source);
//! assert_eq!(g.segment(1), Segment::Sink);
//! ```

use std::collections::VecDeque;
use std::fmt::Debug;
use std::ops::{Add, AddAssign, Neg, Sub, SubAssign};

/// Numbers usable as capacities and energies: `i32`, `i64` and `f64`.
pub trait Capacity:
    Copy
    + PartialOrd
    + Add<Output = Self>
    + Sub<Output = Self>
    + Neg<Output = Self>
    + AddAssign
    + SubAssign
    + Default
    + Debug
    + Send
    + Sync
    + 'static
{
    /// The additive identity.
    const ZERO: Self;
    /// Whether the type is a floating-point type (round-off must be tolerated).
    const IS_FLOAT: bool;
    /// Converts a small integer (used for test data and instance generation).
    fn from_i32(v: i32) -> Self;
    /// Lossy conversion for reporting.
    fn to_f64(self) -> f64;
    /// Conversion from `f64` (rounded and saturated for integers).
    fn from_f64(v: f64) -> Self;
    /// Half of `self`, rounded up for integers (a valid lower bound from twice a bound).
    fn half_ceil(self) -> Self;
    /// Absolute value.
    fn abs_value(self) -> Self;
    /// Residuals at or below this tolerance count as zero, given the largest capacity
    /// magnitude `scale` of the problem: zero for integers, `scale · 1e-12` for floats.
    fn tolerance(scale: Self) -> Self;
}

impl Capacity for i32 {
    #[inline]
    fn from_f64(v: f64) -> Self {
        v.round() as i32
    }
    const ZERO: Self = 0;
    const IS_FLOAT: bool = false;
    #[inline]
    fn from_i32(v: i32) -> Self {
        v
    }
    #[inline]
    fn to_f64(self) -> f64 {
        f64::from(self)
    }
    #[inline]
    fn half_ceil(self) -> Self {
        self.div_euclid(2) + self.rem_euclid(2)
    }
    #[inline]
    fn abs_value(self) -> Self {
        self.abs()
    }
    #[inline]
    fn tolerance(_scale: Self) -> Self {
        0
    }
}

impl Capacity for i64 {
    #[inline]
    fn from_f64(v: f64) -> Self {
        v.round() as i64
    }
    const ZERO: Self = 0;
    const IS_FLOAT: bool = false;
    #[inline]
    fn from_i32(v: i32) -> Self {
        i64::from(v)
    }
    #[inline]
    fn to_f64(self) -> f64 {
        self as f64
    }
    #[inline]
    fn half_ceil(self) -> Self {
        self.div_euclid(2) + self.rem_euclid(2)
    }
    #[inline]
    fn abs_value(self) -> Self {
        self.abs()
    }
    #[inline]
    fn tolerance(_scale: Self) -> Self {
        0
    }
}

impl Capacity for f64 {
    #[inline]
    fn from_f64(v: f64) -> Self {
        v
    }
    const ZERO: Self = 0.0;
    const IS_FLOAT: bool = true;
    #[inline]
    fn from_i32(v: i32) -> Self {
        f64::from(v)
    }
    #[inline]
    fn to_f64(self) -> f64 {
        self
    }
    #[inline]
    fn half_ceil(self) -> Self {
        self * 0.5
    }
    #[inline]
    fn abs_value(self) -> Self {
        self.abs()
    }
    #[inline]
    fn tolerance(scale: Self) -> Self {
        scale.abs() * 1e-12
    }
}

/// The side of a minimum cut a node lies on.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Segment {
    /// The source side S.
    Source,
    /// The sink side T.
    Sink,
}

/// "No node / no arc": not in the active queue, or no parent (a free node).
const NONE: u32 = u32::MAX;
/// Parent marker of a node attached directly to its terminal.
const TERMINAL: u32 = u32::MAX - 1;
/// Parent marker of an orphan awaiting adoption.
const ORPHAN: u32 = u32::MAX - 2;
/// Distance of a node whose tree origin is unknown.
const INFINITE_D: u32 = u32::MAX;

/// Per-node state of the search trees.
#[derive(Debug, Clone, Copy)]
struct Node<T> {
    /// Arc to the parent (node → parent), or `TERMINAL`, `ORPHAN`, `NONE`.
    parent: u32,
    /// Next node in the active FIFO (`NONE`: not active, itself: last).
    next: u32,
    /// Timestamp of the distance estimate.
    ts: u32,
    /// Distance to the terminal along parent arcs (estimate).
    dist: u32,
    /// Residual terminal capacity: > 0 from the source, < 0 to the sink.
    tr_cap: T,
    /// Whether the node belongs to the sink tree (meaningful when it has a parent).
    is_sink: bool,
    /// Whether the user marked the node for tree reuse.
    is_marked: bool,
}

/// One directed arc of the CSR array; `sister` is the reverse arc.
///
/// `rev_cap` mirrors the sister's `r_cap`, so that scans of a node's arcs (sink-tree growth,
/// adoption) read one cache line instead of chasing the sister into another node's arcs;
/// every flow update writes both copies ([`Graph::push_flow`]).
#[derive(Debug, Clone, Copy)]
struct Arc<T> {
    head: u32,
    sister: u32,
    r_cap: T,
    rev_cap: T,
}

/// The smallest of three capacities.
#[inline]
fn min3<T: PartialOrd>(a: T, b: T, c: T) -> T {
    let ab = if b < a { b } else { a };
    if c < ab {
        c
    } else {
        ab
    }
}

/// The arc joining the two search trees found by tree growth, with its endpoints.
#[derive(Debug, Clone, Copy)]
struct Middle<T> {
    /// The arc from the source tree to the sink tree.
    arc: u32,
    /// Its reverse arc.
    sister: u32,
    /// Its tail, in the source tree.
    tail: u32,
    /// Its head, in the sink tree.
    head: u32,
    /// Its residual capacity.
    r_cap: T,
}

/// A directed graph with source and sink terminals, solved by Boykov–Kolmogorov max-flow.
///
/// Build with [`Graph::add_tweights`] and [`Graph::add_edge`], call [`Graph::maxflow`],
/// read the cut with [`Graph::segment`]. After a solve, t-link capacities may change
/// ([`Graph::add_tweights`]), edge capacities may grow ([`Graph::add_edge_capacity`]),
/// edges may be added; mark the touched nodes with [`Graph::mark_node`] and call
/// `maxflow(true)` to continue from the previous flow and search trees.
#[derive(Debug, Clone)]
pub struct Graph<T: Capacity> {
    nodes: Vec<Node<T>>,
    /// CSR offsets (`num_nodes + 1` entries once built).
    first: Vec<u32>,
    arcs: Vec<Arc<T>>,
    /// Endpoints of every edge, in insertion order.
    edge_ends: Vec<(u32, u32)>,
    /// Capacities of edges not yet placed in the arc array.
    pending_caps: Vec<(T, T)>,
    /// Position of each edge's forward arc in `arcs` (for edges already built).
    edge_arc: Vec<u32>,
    /// Number of edges placed in `arcs`.
    built_edges: usize,
    flow: T,
    /// Largest capacity magnitude seen (sets the float round-off tolerance).
    scale: T,
    eps: T,
    time: u32,
    queue_first: u32,
    queue_last: u32,
    /// Orphans created by augmentation (pushed at the front).
    orphans: VecDeque<u32>,
    /// Orphans created while adopting (processed before the next augmentation orphan, as
    /// in the reference implementation: one orphan's whole subtree is settled first).
    orphans_rear: VecDeque<u32>,
    marked: Vec<u32>,
    /// Whether search trees from a previous solve are valid for reuse.
    trees_valid: bool,
}

impl<T: Capacity> Graph<T> {
    /// An empty graph on `num_nodes` nodes with room for `num_edges_hint` edges.
    pub fn new(num_nodes: usize, num_edges_hint: usize) -> Self {
        assert!(
            num_nodes < (ORPHAN as usize) / 2,
            "graph too large for u32 indices"
        );
        let node = Node {
            parent: NONE,
            next: NONE,
            ts: 0,
            dist: 0,
            tr_cap: T::ZERO,
            is_sink: false,
            is_marked: false,
        };
        Graph {
            nodes: vec![node; num_nodes],
            first: Vec::new(),
            arcs: Vec::new(),
            edge_ends: Vec::with_capacity(num_edges_hint),
            pending_caps: Vec::with_capacity(num_edges_hint),
            edge_arc: Vec::new(),
            built_edges: 0,
            flow: T::ZERO,
            scale: T::ZERO,
            eps: T::ZERO,
            time: 0,
            queue_first: NONE,
            queue_last: NONE,
            orphans: VecDeque::new(),
            orphans_rear: VecDeque::new(),
            marked: Vec::new(),
            trees_valid: false,
        }
    }

    /// Number of nodes.
    pub fn num_nodes(&self) -> usize {
        self.nodes.len()
    }

    /// Number of edges added so far.
    pub fn num_edges(&self) -> usize {
        self.edge_ends.len()
    }

    #[inline]
    fn note_scale(&mut self, c: T) {
        let a = c.abs_value();
        if a > self.scale {
            self.scale = a;
        }
    }

    /// Adds capacity `cap_source` to the link source → `node` and `cap_sink` to `node` → sink.
    ///
    /// Negative values are allowed: a constant is moved into the flow value so that the
    /// cut energy is unchanged (cut cost of `node` on the source side grows by
    /// `cap_sink`, on the sink side by `cap_source`). Callable after a solve too.
    pub fn add_tweights(&mut self, node: usize, cap_source: T, cap_sink: T) {
        let n = &mut self.nodes[node];
        let (mut cs, mut ct) = (cap_source, cap_sink);
        let delta = n.tr_cap;
        if delta > T::ZERO {
            cs += delta;
        } else {
            ct -= delta;
        }
        self.flow += if cs < ct { cs } else { ct };
        n.tr_cap = cs - ct;
        let tr = n.tr_cap;
        self.note_scale(tr);
    }

    /// The residual terminal capacity of `node`: > 0 from the source, < 0 to the sink.
    pub fn tr_residual(&self, node: usize) -> T {
        self.nodes[node].tr_cap
    }

    /// Adds the edge `i → j` with capacity `cap` and `j → i` with `rev_cap` (both ≥ 0);
    /// returns its id (consecutive from 0).
    pub fn add_edge(&mut self, i: usize, j: usize, cap: T, rev_cap: T) -> usize {
        assert!(
            i < self.nodes.len() && j < self.nodes.len(),
            "edge endpoint out of range"
        );
        debug_assert!(cap >= T::ZERO && rev_cap >= T::ZERO, "negative capacity");
        self.note_scale(cap);
        self.note_scale(rev_cap);
        self.edge_ends.push((i as u32, j as u32));
        self.pending_caps.push((cap, rev_cap));
        self.edge_ends.len() - 1
    }

    /// The endpoints `(i, j)` of edge `e`.
    #[inline]
    pub fn edge_ends(&self, e: usize) -> (usize, usize) {
        let (i, j) = self.edge_ends[e];
        (i as usize, j as usize)
    }

    /// Residual capacities `(i → j, j → i)` of edge `e` (its capacities before a solve).
    pub fn edge_residual(&self, e: usize) -> (T, T) {
        if e < self.built_edges {
            let a = self.edge_arc[e] as usize;
            let arc = self.arcs[a];
            (arc.r_cap, arc.rev_cap)
        } else {
            self.pending_caps[e - self.built_edges]
        }
    }

    /// Increases the capacities of edge `e` by `delta` (`i → j`) and `rev_delta` (`j → i`),
    /// both ≥ 0. After a solve, mark both endpoints before `maxflow(true)`.
    pub fn add_edge_capacity(&mut self, e: usize, delta: T, rev_delta: T) {
        assert!(
            delta >= T::ZERO && rev_delta >= T::ZERO,
            "capacities may only grow"
        );
        if e < self.built_edges {
            let a = self.edge_arc[e] as usize;
            let s = self.arcs[a].sister as usize;
            self.arcs[a].r_cap += delta;
            self.arcs[a].rev_cap += rev_delta;
            self.arcs[s].r_cap += rev_delta;
            self.arcs[s].rev_cap += delta;
            let (f, r) = (self.arcs[a].r_cap, self.arcs[s].r_cap);
            self.note_scale(f);
            self.note_scale(r);
        } else {
            let c = &mut self.pending_caps[e - self.built_edges];
            c.0 += delta;
            c.1 += rev_delta;
            let (f, r) = *c;
            self.note_scale(f);
            self.note_scale(r);
        }
    }

    /// Sum of the residual capacities of every arc at `node` (both directions) and of its
    /// terminal residual: a terminal link larger than this can never be cut (after a build).
    pub fn incident_residual(&self, node: usize) -> T {
        let mut sum = self.nodes[node].tr_cap.abs_value();
        for a in self.arc_range(node) {
            let arc = self.arcs[a];
            sum += arc.r_cap + arc.rev_cap;
        }
        sum
    }

    /// Marks `node` as changed since the last solve, for `maxflow(true)`.
    pub fn mark_node(&mut self, node: usize) {
        let n = &mut self.nodes[node];
        if !n.is_marked {
            n.is_marked = true;
            self.marked.push(node as u32);
        }
    }

    /// The current flow value (after [`Graph::maxflow`]: the maximum flow = minimum cut).
    pub fn flow(&self) -> T {
        self.flow
    }

    /// The side of the minimum cut of `node` after [`Graph::maxflow`]. Nodes in neither
    /// search tree may go either way; they are reported on the source side.
    #[inline]
    pub fn segment(&self, node: usize) -> Segment {
        let n = &self.nodes[node];
        if n.parent != NONE && n.is_sink {
            Segment::Sink
        } else {
            Segment::Source
        }
    }

    /// The search tree of `node` after [`Graph::maxflow`]: `Some(Source)` iff the node is
    /// reachable from the source in the residual graph (on the source side of every
    /// minimum cut), `Some(Sink)` iff it reaches the sink, `None` otherwise (free).
    #[inline]
    pub fn tree(&self, node: usize) -> Option<Segment> {
        let n = &self.nodes[node];
        if n.parent == NONE {
            None
        } else if n.is_sink {
            Some(Segment::Sink)
        } else {
            Some(Segment::Source)
        }
    }

    /// Calls `f(head, residual)` for every residual arc leaving `node` (after a build).
    pub fn for_each_residual_arc(&self, node: usize, mut f: impl FnMut(usize, T)) {
        if self.first.len() != self.nodes.len() + 1 {
            return;
        }
        let (b, e) = (self.first[node] as usize, self.first[node + 1] as usize);
        for arc in &self.arcs[b..e] {
            if arc.r_cap > self.eps {
                f(arc.head as usize, arc.r_cap);
            }
        }
    }

    /// The arc positions of `node` in the arc array (after a solve); see [`Graph::arc`].
    pub fn arc_range(&self, node: usize) -> std::ops::Range<usize> {
        if self.first.len() != self.nodes.len() + 1 {
            return 0..0;
        }
        self.first[node] as usize..self.first[node + 1] as usize
    }

    /// Head node and residual capacity of arc position `a` (from [`Graph::arc_range`]).
    #[inline]
    pub fn arc(&self, a: usize) -> (usize, T) {
        let arc = self.arcs[a];
        (arc.head as usize, arc.r_cap)
    }

    /// Raises the magnitude from which the float round-off tolerance is derived (callers
    /// that reparametrise energies pass the largest input energy; cancellation can make
    /// every capacity tiny). No effect for integers.
    pub fn raise_tolerance_scale(&mut self, scale: T) {
        self.note_scale(scale);
    }

    /// The round-off tolerance in use: residuals at or below it count as saturated.
    pub fn tolerance(&self) -> T {
        self.eps
    }

    /// Builds the compact arc array now (otherwise the first [`Graph::maxflow`] does it).
    /// Edges added later trigger a rebuild that keeps the current residuals.
    pub fn prepare(&mut self) {
        self.build();
    }

    /// Places pending edges into the CSR arc array (keeping the residuals of built ones).
    /// Returns whether the array was rebuilt.
    fn build(&mut self) -> bool {
        let m = self.edge_ends.len();
        if self.built_edges == m && self.first.len() == self.nodes.len() + 1 {
            return false;
        }
        let n = self.nodes.len();
        let mut caps: Vec<(T, T)> = Vec::with_capacity(m);
        for e in 0..self.built_edges {
            caps.push(self.edge_residual(e));
        }
        caps.append(&mut self.pending_caps);
        let mut first = vec![0u32; n + 1];
        for &(i, j) in &self.edge_ends {
            first[i as usize + 1] += 1;
            first[j as usize + 1] += 1;
        }
        for k in 0..n {
            first[k + 1] += first[k];
        }
        // Each node's arcs are placed last-added first, the order in which the reference
        // implementation's linked lists scan them (it steers tree growth on grids).
        let mut cursor: Vec<u32> = first[1..].to_vec();
        let blank = Arc {
            head: 0,
            sister: 0,
            r_cap: T::ZERO,
            rev_cap: T::ZERO,
        };
        let mut arcs = vec![blank; 2 * m];
        let mut edge_arc = vec![0u32; m];
        for (e, (&(i, j), &(c, rc))) in self.edge_ends.iter().zip(caps.iter()).enumerate() {
            cursor[i as usize] -= 1;
            let a = cursor[i as usize];
            cursor[j as usize] -= 1;
            let b = cursor[j as usize];
            arcs[a as usize] = Arc {
                head: j,
                sister: b,
                r_cap: c,
                rev_cap: rc,
            };
            arcs[b as usize] = Arc {
                head: i,
                sister: a,
                r_cap: rc,
                rev_cap: c,
            };
            edge_arc[e] = a;
        }
        self.first = first;
        self.arcs = arcs;
        self.edge_arc = edge_arc;
        self.built_edges = m;
        if self.trees_valid {
            // Trees refer to old arc positions: the next solve starts afresh.
            self.trees_valid = false;
        }
        true
    }

    /// Computes the maximum flow and returns its value (the minimum cut capacity,
    /// including constants moved out by negative t-weights).
    ///
    /// With `reuse_trees`, continues from the previous flow and search trees; only nodes
    /// marked with [`Graph::mark_node`] (and everything they disconnect) are revisited.
    pub fn maxflow(&mut self, reuse_trees: bool) -> T {
        self.build();
        self.eps = T::tolerance(self.scale);
        if reuse_trees && self.trees_valid {
            self.reuse_trees_init();
        } else {
            self.init();
        }
        self.run();
        self.trees_valid = true;
        self.flow
    }

    /// Saturates the paths source → i → j → sink of one arc between a node with
    /// residual from the source and a node with residual to the sink, before the search
    /// trees are grown. One sweep over the nodes in index order; node k settles its edges
    /// to lower-numbered neighbours only, whose nodes and arc slices were just swept and
    /// are still cached (on grids the forward neighbours would each be a cache miss).
    /// Any maximum flow gives the same residual reachability, so the cut and the labels
    /// do not depend on this order.
    fn push_terminal_pairs(&mut self) {
        let eps = self.eps;
        let n = self.nodes.len();
        let mut flow = T::ZERO;
        for k in 0..n {
            let mut tr_k = self.nodes[k].tr_cap;
            if tr_k <= eps && tr_k >= -eps {
                continue;
            }
            let (b, e) = (self.first[k] as usize, self.first[k + 1] as usize);
            for a in b..e {
                let arc = self.arcs[a];
                let h = arc.head as usize;
                if h >= k {
                    continue;
                }
                let tr_h = self.nodes[h].tr_cap;
                if tr_k > eps {
                    // source → k → h → sink along arc a.
                    if tr_h >= -eps || arc.r_cap <= eps {
                        continue;
                    }
                    let f = min3(arc.r_cap, tr_k, -tr_h);
                    self.push_flow(a as u32, arc.sister, f);
                    self.nodes[h].tr_cap = tr_h + f;
                    tr_k -= f;
                    flow += f;
                    if tr_k <= eps {
                        break;
                    }
                } else {
                    // source → h → k → sink along the sister of a.
                    if tr_h <= eps || arc.rev_cap <= eps {
                        continue;
                    }
                    let f = min3(arc.rev_cap, tr_h, -tr_k);
                    self.push_flow(arc.sister, a as u32, f);
                    self.nodes[h].tr_cap = tr_h - f;
                    tr_k += f;
                    flow += f;
                    if tr_k >= -eps {
                        break;
                    }
                }
            }
            self.nodes[k].tr_cap = tr_k;
        }
        self.flow += flow;
    }

    fn init(&mut self) {
        self.push_terminal_pairs();
        self.queue_first = NONE;
        self.queue_last = NONE;
        self.orphans.clear();
        self.orphans_rear.clear();
        self.time = 0;
        let eps = self.eps;
        for i in 0..self.nodes.len() {
            let n = &mut self.nodes[i];
            n.next = NONE;
            n.is_marked = false;
            n.ts = 0;
            if n.tr_cap > eps {
                n.is_sink = false;
                n.parent = TERMINAL;
                n.dist = 1;
                self.set_active(i as u32);
            } else if n.tr_cap < -eps {
                n.is_sink = true;
                n.parent = TERMINAL;
                n.dist = 1;
                self.set_active(i as u32);
            } else {
                n.parent = NONE;
            }
        }
        self.marked.clear();
    }

    fn reuse_trees_init(&mut self) {
        self.time += 1;
        let eps = self.eps;
        let marked = std::mem::take(&mut self.marked);
        for &iu in &marked {
            let i = iu as usize;
            self.nodes[i].is_marked = false;
            self.set_active(iu);
            let tr = self.nodes[i].tr_cap;
            if tr <= eps && tr >= -eps {
                let p = self.nodes[i].parent;
                if p != NONE && p != ORPHAN {
                    self.set_orphan_rear(iu);
                }
                continue;
            }
            let to_source = tr > eps;
            let n = self.nodes[i];
            if n.parent == NONE || n.parent == ORPHAN || n.is_sink == to_source {
                self.nodes[i].is_sink = !to_source;
                let (b, e) = (self.first[i] as usize, self.first[i + 1] as usize);
                for a in b..e {
                    let arc = self.arcs[a];
                    let j = arc.head as usize;
                    let nj = self.nodes[j];
                    if nj.is_marked {
                        continue;
                    }
                    if nj.parent == arc.sister {
                        self.set_orphan_rear(j as u32);
                    }
                    let nj = self.nodes[j];
                    if nj.parent != NONE && nj.parent != ORPHAN && nj.is_sink == to_source {
                        let r = if to_source { arc.r_cap } else { arc.rev_cap };
                        if r > eps {
                            self.set_active(j as u32);
                        }
                    }
                }
            }
            let n = &mut self.nodes[i];
            n.parent = TERMINAL;
            n.ts = self.time;
            n.dist = 1;
        }
        self.marked = marked;
        self.marked.clear();
        self.adopt_orphans();
    }

    #[inline]
    fn set_active(&mut self, i: u32) {
        if self.nodes[i as usize].next == NONE {
            if self.queue_last != NONE {
                self.nodes[self.queue_last as usize].next = i;
            } else {
                self.queue_first = i;
            }
            self.queue_last = i;
            self.nodes[i as usize].next = i;
        }
    }

    /// Pops the next active node that still belongs to a tree.
    #[inline]
    fn next_active(&mut self) -> u32 {
        loop {
            let i = self.queue_first;
            if i == NONE {
                return NONE;
            }
            let n = &mut self.nodes[i as usize];
            if n.next == i {
                self.queue_first = NONE;
                self.queue_last = NONE;
            } else {
                self.queue_first = n.next;
            }
            n.next = NONE;
            if n.parent != NONE {
                return i;
            }
        }
    }

    #[inline]
    fn set_orphan_front(&mut self, i: u32) {
        self.nodes[i as usize].parent = ORPHAN;
        self.orphans.push_front(i);
    }

    #[inline]
    fn set_orphan_rear(&mut self, i: u32) {
        self.nodes[i as usize].parent = ORPHAN;
        self.orphans_rear.push_back(i);
    }

    fn run(&mut self) {
        let mut current = NONE;
        loop {
            let mut i = current;
            if i != NONE {
                self.nodes[i as usize].next = NONE;
                if self.nodes[i as usize].parent == NONE {
                    i = NONE;
                }
            }
            if i == NONE {
                i = self.next_active();
                if i == NONE {
                    break;
                }
            }
            let iu = i as usize;
            let ni = self.nodes[iu];
            let middle = if ni.is_sink {
                self.grow::<true>(iu, ni)
            } else {
                self.grow::<false>(iu, ni)
            };
            self.time = self.time.wrapping_add(1);
            if let Some(middle) = middle {
                // Keep i active: it may have more paths to the other tree.
                self.nodes[iu].next = i;
                current = i;
                self.augment(middle);
                self.adopt_orphans();
            } else {
                current = NONE;
            }
        }
    }

    /// Sends `amount` along arc `a` whose sister is `s`, keeping both residual copies in
    /// step. The caller knows the sister, so the two writes do not wait for each other.
    #[inline]
    fn push_flow(&mut self, a: u32, s: u32, amount: T) {
        let arc = &mut self.arcs[a as usize];
        arc.r_cap -= amount;
        arc.rev_cap += amount;
        let sister = &mut self.arcs[s as usize];
        sister.r_cap += amount;
        sister.rev_cap -= amount;
    }

    /// Grows the tree of active node `i` (the sink tree if `SINK`) over its residual arcs.
    /// Returns the arc from the source tree to the sink tree it found, if any.
    #[inline]
    fn grow<const SINK: bool>(&mut self, i: usize, ni: Node<T>) -> Option<Middle<T>> {
        let eps = self.eps;
        let (b, e) = (self.first[i] as usize, self.first[i + 1] as usize);
        let arcs = &self.arcs[b..e];
        let nodes = &mut self.nodes;
        for (k, arc) in arcs.iter().enumerate() {
            let r = if SINK { arc.rev_cap } else { arc.r_cap };
            if r <= eps {
                continue;
            }
            let j = arc.head;
            let nj = &mut nodes[j as usize];
            if nj.parent == NONE {
                nj.is_sink = SINK;
                nj.parent = arc.sister;
                nj.ts = ni.ts;
                nj.dist = ni.dist + 1;
                // set_active, inlined: j is not queued yet unless its `next` is set.
                if nj.next == NONE {
                    nj.next = j;
                    if self.queue_last != NONE {
                        nodes[self.queue_last as usize].next = j;
                    } else {
                        self.queue_first = j;
                    }
                    self.queue_last = j;
                }
            } else if nj.is_sink != SINK {
                let here = (b + k) as u32;
                // Everything augment needs to start walking, without touching the sister.
                return Some(if SINK {
                    Middle {
                        arc: arc.sister,
                        sister: here,
                        tail: j,
                        head: i as u32,
                        r_cap: r,
                    }
                } else {
                    Middle {
                        arc: here,
                        sister: arc.sister,
                        tail: i as u32,
                        head: j,
                        r_cap: r,
                    }
                });
            } else if nj.ts <= ni.ts && nj.dist > ni.dist {
                nj.parent = arc.sister;
                nj.ts = ni.ts;
                nj.dist = ni.dist + 1;
            }
        }
        None
    }

    /// Pushes the bottleneck flow along source tree → `middle` → sink tree.
    ///
    /// Each tree is walked twice, child to parent: once for the bottleneck, once to push.
    /// The walks read only the child's parent arc (its `rev_cap` mirrors the sister's
    /// residual); the sister, in the parent's arc slice, is only written.
    fn augment(&mut self, middle: Middle<T>) {
        let eps = self.eps;
        let mut bottleneck = middle.r_cap;
        // Source tree: walk from the tail of `middle` to the source.
        let mut i = middle.tail;
        loop {
            let a = self.nodes[i as usize].parent;
            if a == TERMINAL {
                break;
            }
            let arc = &self.arcs[a as usize];
            if bottleneck > arc.rev_cap {
                bottleneck = arc.rev_cap;
            }
            i = arc.head;
        }
        let tr = self.nodes[i as usize].tr_cap;
        if bottleneck > tr {
            bottleneck = tr;
        }
        // Sink tree.
        let mut i = middle.head;
        loop {
            let a = self.nodes[i as usize].parent;
            if a == TERMINAL {
                break;
            }
            let arc = &self.arcs[a as usize];
            if bottleneck > arc.r_cap {
                bottleneck = arc.r_cap;
            }
            i = arc.head;
        }
        let tr = -self.nodes[i as usize].tr_cap;
        if bottleneck > tr {
            bottleneck = tr;
        }
        // Augment.
        self.push_flow(middle.arc, middle.sister, bottleneck);
        let mut i = middle.tail;
        loop {
            let a = self.nodes[i as usize].parent;
            if a == TERMINAL {
                break;
            }
            let arc = self.arcs[a as usize];
            // Flow runs parent → i along the sister of the parent arc.
            self.push_flow(arc.sister, a, bottleneck);
            if arc.rev_cap - bottleneck <= eps {
                self.set_orphan_front(i);
            }
            i = arc.head;
        }
        let n = &mut self.nodes[i as usize];
        n.tr_cap -= bottleneck;
        if n.tr_cap <= eps {
            self.set_orphan_front(i);
        }
        let mut i = middle.head;
        loop {
            let a = self.nodes[i as usize].parent;
            if a == TERMINAL {
                break;
            }
            let arc = self.arcs[a as usize];
            self.push_flow(a, arc.sister, bottleneck);
            if arc.r_cap - bottleneck <= eps {
                self.set_orphan_front(i);
            }
            i = arc.head;
        }
        let n = &mut self.nodes[i as usize];
        n.tr_cap += bottleneck;
        if n.tr_cap >= -eps {
            self.set_orphan_front(i);
        }
        self.flow += bottleneck;
    }

    fn adopt_orphans(&mut self) {
        loop {
            let i = match self.orphans_rear.pop_front() {
                Some(i) => i,
                None => match self.orphans.pop_front() {
                    Some(i) => i,
                    None => break,
                },
            };
            if self.nodes[i as usize].is_sink {
                self.process_orphan::<true>(i);
            } else {
                self.process_orphan::<false>(i);
            }
        }
    }

    /// Tries to find a new parent for orphan `i` in its tree (`SINK` selects the tree);
    /// otherwise frees it and orphans its children.
    fn process_orphan<const SINK: bool>(&mut self, i: u32) {
        let eps = self.eps;
        let iu = i as usize;
        let (b, e) = (self.first[iu] as usize, self.first[iu + 1] as usize);
        let mut d_min = INFINITE_D;
        let mut a0_min = NONE;
        let time = self.time;
        let arcs = &self.arcs;
        let nodes = &mut self.nodes;
        for (k, arc0) in arcs[b..e].iter().enumerate() {
            // Residual from the candidate parent j into i (source tree) or i → j (sink tree).
            let r = if SINK { arc0.r_cap } else { arc0.rev_cap };
            if r <= eps {
                continue;
            }
            let mut j = arc0.head;
            let nj = &nodes[j as usize];
            if nj.is_sink != SINK || nj.parent == NONE {
                continue;
            }
            // Check the origin of j.
            let mut d: u32 = 0;
            loop {
                let n = &mut nodes[j as usize];
                if n.ts == time {
                    d = d.saturating_add(n.dist);
                    break;
                }
                let a = n.parent;
                d += 1;
                if a == TERMINAL {
                    n.ts = time;
                    n.dist = 1;
                    break;
                }
                if a == ORPHAN || a == NONE {
                    d = INFINITE_D;
                    break;
                }
                j = arcs[a as usize].head;
            }
            if d < INFINITE_D {
                if d < d_min {
                    a0_min = (b + k) as u32;
                    d_min = d;
                }
                // Set marks along the path.
                let mut j = arc0.head;
                loop {
                    let n = &mut nodes[j as usize];
                    if n.ts == time {
                        break;
                    }
                    n.ts = time;
                    n.dist = d;
                    d = d.saturating_sub(1);
                    j = arcs[n.parent as usize].head;
                }
            }
        }
        if a0_min != NONE {
            let n = &mut self.nodes[iu];
            n.parent = a0_min;
            n.ts = self.time;
            n.dist = d_min + 1;
            return;
        }
        self.nodes[iu].parent = NONE;
        for a0 in b..e {
            let arc0 = self.arcs[a0];
            let j = arc0.head;
            let nj = self.nodes[j as usize];
            if nj.is_sink != SINK || nj.parent == NONE {
                continue;
            }
            let r = if SINK { arc0.r_cap } else { arc0.rev_cap };
            if r > eps {
                self.set_active(j);
            }
            let a = nj.parent;
            if a != TERMINAL && a != ORPHAN && self.arcs[a as usize].head == i {
                self.set_orphan_rear(j);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn two_node_chain_by_hand() {
        let mut g = Graph::<i32>::new(2, 1);
        g.add_tweights(0, 5, 0);
        g.add_tweights(1, 0, 4);
        g.add_edge(0, 1, 3, 0);
        assert_eq!(g.maxflow(false), 3);
        assert_eq!(g.segment(0), Segment::Source);
        assert_eq!(g.segment(1), Segment::Sink);
    }

    #[test]
    fn negative_tweights_move_constants_into_flow() {
        // Node 0: source side costs 2 (sink cap), sink side costs 7: cut on source side.
        let mut g = Graph::<i64>::new(1, 0);
        g.add_tweights(0, 7, 2);
        assert_eq!(g.maxflow(false), 2);
        assert_eq!(g.segment(0), Segment::Source);
        g.add_tweights(0, -6, 0); // now costs: source side 2, sink side 1
        assert_eq!(g.maxflow(false), 1);
        assert_eq!(g.segment(0), Segment::Sink);
    }

    #[test]
    fn diamond_with_cross_edge() {
        let mut g = Graph::<f64>::new(4, 5);
        g.add_tweights(0, 10.0, 0.0);
        g.add_tweights(3, 0.0, 10.0);
        g.add_edge(0, 1, 2.5, 0.0);
        g.add_edge(0, 2, 4.0, 0.0);
        g.add_edge(1, 3, 3.0, 0.0);
        g.add_edge(2, 3, 1.5, 0.0);
        g.add_edge(2, 1, 2.0, 0.0);
        let f = g.maxflow(false);
        assert!((f - 4.5).abs() < 1e-12);
        g.add_tweights(1, 0.0, 1.0);
        g.mark_node(1);
        let f = g.maxflow(true);
        assert!((f - 5.5).abs() < 1e-12, "{f}");
    }
}
