//! The spatial relation graph stored in the SRTree (thesis §3.3.2): one node per object,
//! one edge per ordered pair with at least one true relation, labelled with every relation
//! that holds (multi-label edges), and the queries a dialogue system asks of it.

use crate::objects::OrientedBox;
use geodata::classes::Class;
use serde::{Deserialize, Serialize};

/// A qualitative spatial relation between two objects as seen from a viewpoint.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
pub enum Relation {
    /// `a` is supported by `b`.
    On,
    /// `a` is left of `b`.
    LeftOf,
    /// `a` is behind `b`.
    Behind,
    /// `a` is right of `b` (the converse of LeftOf).
    RightOf,
    /// `a` is in front of `b` (the converse of Behind).
    InFrontOf,
}

impl Relation {
    /// The three base relations that are classified and reasoned over.
    pub const BASE: [Relation; 3] = [Relation::On, Relation::LeftOf, Relation::Behind];
    /// All five relations.
    pub const ALL: [Relation; 5] = [
        Relation::On,
        Relation::LeftOf,
        Relation::Behind,
        Relation::RightOf,
        Relation::InFrontOf,
    ];

    /// The name as in the thesis and the JSON keys.
    pub fn name(self) -> &'static str {
        match self {
            Relation::On => "On",
            Relation::LeftOf => "LeftOf",
            Relation::Behind => "Behind",
            Relation::RightOf => "RightOf",
            Relation::InFrontOf => "InFrontOf",
        }
    }

    /// The relation with this name (case-insensitive), if any.
    pub fn from_name(name: &str) -> Option<Relation> {
        Relation::ALL
            .into_iter()
            .find(|r| r.name().eq_ignore_ascii_case(name))
    }

    /// Bit of the relation in [`RelationEdge::bits`].
    pub fn bit(self) -> u8 {
        1 << (self as u8)
    }
}

/// An object of the map with its class and geometry.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ObjectNode {
    /// Object id (as in the cloud's `object` column).
    pub id: u32,
    /// Majority class of its cells.
    pub class: Class,
    /// Occupied cells of the object.
    pub cells: usize,
    /// Mean of its cell centres, metres.
    pub centroid: [f64; 3],
    /// Its oriented bounding box.
    pub bbox: OrientedBox,
}

impl crate::objects::MapObject {
    /// The graph node of this object.
    pub fn node(&self) -> ObjectNode {
        ObjectNode {
            id: self.id,
            class: self.class,
            cells: self.cells.len(),
            centroid: self.centroid,
            bbox: self.bbox,
        }
    }
}

/// A labelled edge: the relations that hold for the ordered pair (a, b).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct RelationEdge {
    /// First object id.
    pub a: u32,
    /// Second object id.
    pub b: u32,
    /// One bit per [`Relation`] ([`Relation::bit`]).
    pub bits: u8,
}

impl RelationEdge {
    /// Whether the edge carries a relation.
    pub fn has(&self, r: Relation) -> bool {
        self.bits & r.bit() != 0
    }

    /// The relations on the edge.
    pub fn relations(&self) -> Vec<Relation> {
        Relation::ALL.into_iter().filter(|&r| self.has(r)).collect()
    }
}

/// The viewpoint relations were inferred for: observer position and viewing direction.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Viewpoint {
    /// Observer position, metres (z: eye height).
    pub position: [f64; 3],
    /// Viewing direction, radians counter-clockwise from the x axis.
    pub yaw_rad: f64,
}

impl Viewpoint {
    /// A point in the viewpoint frame: x forward, y left, z up (relative to the eye).
    pub fn to_view(&self, p: [f64; 3]) -> [f64; 3] {
        let (s, c) = self.yaw_rad.sin_cos();
        let d = [
            p[0] - self.position[0],
            p[1] - self.position[1],
            p[2] - self.position[2],
        ];
        [c * d[0] + s * d[1], -s * d[0] + c * d[1], d[2]]
    }
}

/// Objects and the relations between them.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct RelationGraph {
    /// The viewpoint of the relations (None: no relations inferred yet).
    pub viewpoint: Option<Viewpoint>,
    /// The objects.
    pub objects: Vec<ObjectNode>,
    /// Edges with at least one relation, sorted by (a, b).
    pub edges: Vec<RelationEdge>,
}

impl RelationGraph {
    /// The object with this id.
    pub fn object(&self, id: u32) -> Option<&ObjectNode> {
        self.objects.iter().find(|o| o.id == id)
    }

    /// Objects `x` with `R(x, object)`: "what is left of the tree?" (sorted ids).
    pub fn subjects_of(&self, relation: Relation, object: u32) -> Vec<u32> {
        self.edges
            .iter()
            .filter(|e| e.b == object && e.has(relation))
            .map(|e| e.a)
            .collect()
    }

    /// Objects `y` with `R(object, y)`: "what is the car on?" (sorted ids).
    pub fn targets_of(&self, relation: Relation, object: u32) -> Vec<u32> {
        self.edges
            .iter()
            .filter(|e| e.a == object && e.has(relation))
            .map(|e| e.b)
            .collect()
    }

    /// Objects whose whole angular extent lies left of a point as seen from a viewpoint
    /// (objects behind the observer excluded), sorted by id.
    pub fn objects_left_of_point(&self, point: [f64; 3], viewpoint: &Viewpoint) -> Vec<u32> {
        let p = viewpoint.to_view(point);
        let angle_p = p[1].atan2(p[0]);
        let mut out: Vec<u32> = self
            .objects
            .iter()
            .filter(|o| {
                let corners = o.bbox.corners().map(|c| viewpoint.to_view(c));
                corners.iter().all(|c| c[0] > 0.0)
                    && corners.iter().all(|c| c[1].atan2(c[0]) > angle_p)
            })
            .map(|o| o.id)
            .collect();
        out.sort_unstable();
        out
    }

    /// The edges `(a, b)` of one relation that no longer path `a → … → b` of it implies:
    /// the transitive reduction, which draws a chain `a LeftOf b LeftOf c` without the
    /// implied `a LeftOf c` (sorted by (a, b)).
    ///
    /// Cost: one depth-first search per edge, O(E · (V + E)).
    pub fn transitive_reduction(&self, relation: Relation) -> Vec<(u32, u32)> {
        let edges: Vec<(u32, u32)> = self
            .edges
            .iter()
            .filter(|e| e.has(relation) && e.a != e.b)
            .map(|e| (e.a, e.b))
            .collect();
        let successors = |a: u32| edges.iter().filter(move |e| e.0 == a).map(|e| e.1);
        edges
            .iter()
            .copied()
            .filter(|&(a, b)| {
                // Is b reachable from a without the direct edge?
                let mut seen = vec![a];
                let mut stack: Vec<u32> = successors(a).filter(|&c| c != b).collect();
                while let Some(c) = stack.pop() {
                    if c == b {
                        return false;
                    }
                    if seen.contains(&c) {
                        continue;
                    }
                    seen.push(c);
                    stack.extend(successors(c));
                }
                true
            })
            .collect()
    }

    /// The graph in Graphviz DOT: nodes labelled `class #id`, one edge per pair and label list.
    pub fn to_dot(&self) -> String {
        let mut s = String::from("digraph relations {\n  rankdir=LR;\n");
        for o in &self.objects {
            s += &format!("  o{} [label=\"{} #{}\"];\n", o.id, o.class.name(), o.id);
        }
        for e in &self.edges {
            let names: Vec<&str> = e
                .relations()
                .iter()
                .filter(|r| Relation::BASE.contains(r))
                .map(|r| r.name())
                .collect();
            if !names.is_empty() {
                s += &format!("  o{} -> o{} [label=\"{}\"];\n", e.a, e.b, names.join(","));
            }
        }
        s + "}\n"
    }

    /// The graph as text: a count line, then one line per edge with its relations.
    pub fn text(&self) -> String {
        let mut s = format!(
            "{} objects, {} labelled edges:\n",
            self.objects.len(),
            self.edges.len()
        );
        for e in &self.edges {
            let (a, b) = (self.object(e.a), self.object(e.b));
            let names: Vec<&str> = e.relations().iter().map(|r| r.name()).collect();
            s += &format!(
                "  {} #{} → {} #{}: {}\n",
                a.map_or("?", |o| o.class.name()),
                e.a,
                b.map_or("?", |o| o.class.name()),
                e.b,
                names.join(", ")
            );
        }
        s
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn node(id: u32, x: f64, y: f64) -> ObjectNode {
        ObjectNode {
            id,
            class: Class::Car,
            cells: 10,
            centroid: [x, y, 0.5],
            bbox: OrientedBox {
                centre: [x, y, 0.5],
                half_extents: [0.5, 0.5, 0.5],
                yaw_rad: 0.0,
            },
        }
    }

    #[test]
    fn queries_follow_edges_and_geometry() {
        let g = RelationGraph {
            viewpoint: None,
            objects: vec![node(1, 10.0, 5.0), node(2, 10.0, -5.0), node(3, -10.0, 5.0)],
            edges: vec![
                RelationEdge {
                    a: 1,
                    b: 2,
                    bits: Relation::LeftOf.bit(),
                },
                RelationEdge {
                    a: 2,
                    b: 1,
                    bits: Relation::RightOf.bit(),
                },
            ],
        };
        assert_eq!(g.subjects_of(Relation::LeftOf, 2), vec![1]);
        assert_eq!(g.targets_of(Relation::RightOf, 2), vec![1]);
        let vp = Viewpoint {
            position: [0.0, 0.0, 1.8],
            yaw_rad: 0.0,
        };
        assert_eq!(g.objects_left_of_point([10.0, 0.0, 0.0], &vp), vec![1]);
        assert!(g.to_dot().contains("o1 -> o2 [label=\"LeftOf\"]"));
        assert_eq!(
            g.text(),
            "3 objects, 2 labelled edges:\n  car #1 → car #2: LeftOf\n  car #2 → car #1: RightOf\n"
        );
        assert_eq!(Relation::from_name("behind"), Some(Relation::Behind));
    }

    #[test]
    fn transitive_reduction_drops_implied_edges_only() {
        let edge = |a, b| RelationEdge {
            a,
            b,
            bits: Relation::LeftOf.bit(),
        };
        // 1 → 2 → 3 → 4 with the implied 1 → 3, 1 → 4, 2 → 4, and a separate 5 → 4.
        let g = RelationGraph {
            viewpoint: None,
            objects: (1..=5).map(|i| node(i, 10.0, i as f64)).collect(),
            edges: vec![
                edge(1, 2),
                edge(1, 3),
                edge(1, 4),
                edge(2, 3),
                edge(2, 4),
                edge(3, 4),
                edge(5, 4),
            ],
        };
        assert_eq!(
            g.transitive_reduction(Relation::LeftOf),
            vec![(1, 2), (2, 3), (3, 4), (5, 4)]
        );
        assert!(g.transitive_reduction(Relation::Behind).is_empty());
    }
}
