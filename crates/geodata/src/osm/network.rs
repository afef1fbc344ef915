//! The street graph G = (P, S) of thesis §4.4.2: segments, intersections and neighbour pairs N.
//!
//! A segment is the straight piece between two consecutive nodes of a highway way. The thesis
//! defines N = {{s1, s2} : p_{s1,b} = p_{s2,e}}, i.e. one segment starts where the other ends.
//! OSM way direction is arbitrary (two ways may meet head to head), so we take the undirected
//! form of that rule: two segments are neighbours when they share a waypoint. Within one
//! way this is exactly the thesis's rule; at a junction of k segment ends it couples all
//! k(k−1)/2 pairs.
//!
//! An intersection is a node where ≥ 3 segment ends meet or that two different ways share.
//! Building the network is O(S log S).

use super::model::{HighwayWay, Intersection, StreetNetwork, StreetSegment};

/// Builds segments, intersections and neighbour pairs from highway ways (`area=yes` ways are skipped).
pub fn build_network(highways: &[HighwayWay]) -> StreetNetwork {
    let mut segments = Vec::new();
    for (way_index, way) in highways.iter().enumerate() {
        if way.area {
            continue;
        }
        let pairs = way.node_ids.windows(2).zip(way.points.windows(2));
        for (index_in_way, (ids, pts)) in pairs.enumerate() {
            let (&[from_node, to_node], &[a, b]) = (ids, pts) else {
                continue;
            };
            if from_node == to_node {
                continue;
            }
            segments.push(StreetSegment {
                way_index,
                index_in_way,
                from_node,
                to_node,
                a,
                b,
                length_m: ((b[0] - a[0]).powi(2) + (b[1] - a[1]).powi(2)).sqrt(),
                highway: way.highway.clone(),
            });
        }
    }
    // Segment ends sorted by node (then segment): each node's ends form one run, so no
    // per-node lists are allocated. (node id, segment id, way index, position).
    let mut ends: Vec<(i64, usize, usize, [f64; 2])> = Vec::with_capacity(2 * segments.len());
    for (id, s) in segments.iter().enumerate() {
        ends.push((s.from_node, id, s.way_index, s.a));
        ends.push((s.to_node, id, s.way_index, s.b));
    }
    ends.sort_unstable_by_key(|e| (e.0, e.1));
    let mut intersections = Vec::new();
    let mut neighbour_pairs = Vec::new();
    for run in ends.chunk_by(|x, y| x.0 == y.0) {
        let Some(&(node_id, _, first_way, position)) = run.first() else {
            continue;
        };
        let several_ways = run.iter().any(|e| e.2 != first_way);
        if let [a, b] = run {
            // The common case: a node inside one way joins its two segments.
            if !several_ways {
                if a.1 != b.1 {
                    neighbour_pairs.push([a.1, b.1]);
                }
                continue;
            }
        }
        let mut segment_ids: Vec<usize> = run.iter().map(|e| e.1).collect();
        segment_ids.dedup();
        for (i, &s1) in segment_ids.iter().enumerate() {
            for &s2 in segment_ids.iter().skip(i + 1) {
                neighbour_pairs.push([s1, s2]);
            }
        }
        if run.len() >= 3 || several_ways {
            intersections.push(Intersection {
                node_id,
                position,
                segment_ids,
            });
        }
    }
    neighbour_pairs.sort_unstable();
    neighbour_pairs.dedup();
    StreetNetwork {
        segments,
        intersections,
        neighbour_pairs,
    }
}

impl StreetNetwork {
    /// Connected components of the segment graph (segments joined through shared nodes): a
    /// component id per segment and the number of components. O(S α(S)).
    pub fn components(&self) -> (Vec<usize>, usize) {
        let n = self.segments.len();
        let mut parent: Vec<usize> = (0..n).collect();
        fn find(parent: &mut [usize], mut x: usize) -> usize {
            while parent[x] != x {
                parent[x] = parent[parent[x]];
                x = parent[x];
            }
            x
        }
        for &[s1, s2] in &self.neighbour_pairs {
            let (r1, r2) = (find(&mut parent, s1), find(&mut parent, s2));
            if r1 != r2 {
                parent[r1.max(r2)] = r1.min(r2);
            }
        }
        let mut label = vec![usize::MAX; n];
        let mut count = 0;
        let out = (0..n)
            .map(|s| {
                let r = find(&mut parent, s);
                if label[r] == usize::MAX {
                    label[r] = count;
                    count += 1;
                }
                label[r]
            })
            .collect();
        (out, count)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rustc_hash::FxHashMap;

    /// The network's intersections and neighbour pairs from per-node lists of segment ends
    /// (the straightforward construction the sorted one replaces).
    fn reference_junctions(segments: &[StreetSegment]) -> (Vec<Intersection>, Vec<[usize; 2]>) {
        let mut ends: FxHashMap<i64, Vec<(usize, [f64; 2], usize)>> = FxHashMap::default();
        for (id, s) in segments.iter().enumerate() {
            ends.entry(s.from_node)
                .or_default()
                .push((id, s.a, s.way_index));
            ends.entry(s.to_node)
                .or_default()
                .push((id, s.b, s.way_index));
        }
        let mut intersections = Vec::new();
        let mut neighbour_pairs = Vec::new();
        for (&node_id, list) in &ends {
            let several_ways = list.iter().any(|e| e.2 != list[0].2);
            let mut segment_ids: Vec<usize> = list.iter().map(|e| e.0).collect();
            segment_ids.sort_unstable();
            segment_ids.dedup();
            for (i, &s1) in segment_ids.iter().enumerate() {
                for &s2 in segment_ids.iter().skip(i + 1) {
                    neighbour_pairs.push([s1, s2]);
                }
            }
            if list.len() >= 3 || several_ways {
                intersections.push(Intersection {
                    node_id,
                    position: list[0].1,
                    segment_ids,
                });
            }
        }
        intersections.sort_unstable_by_key(|i| i.node_id);
        neighbour_pairs.sort_unstable();
        neighbour_pairs.dedup();
        (intersections, neighbour_pairs)
    }

    #[test]
    fn junctions_equal_the_per_node_reference_on_the_real_maps() {
        let dir = std::path::Path::new(concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../../../shared/data/osm"
        ));
        for name in [
            "monaco.osm.pbf",
            "helsinki_centre.osm.pbf",
            "kth_campus_stockholm.osm",
        ] {
            let map = crate::osm::OsmMap::load(dir.join(name)).unwrap();
            let net = &map.streets;
            let (intersections, pairs) = reference_junctions(&net.segments);
            assert!(!intersections.is_empty(), "{name}");
            assert_eq!(net.intersections.len(), intersections.len(), "{name}");
            for (a, b) in net.intersections.iter().zip(&intersections) {
                assert_eq!(
                    (a.node_id, a.position, &a.segment_ids),
                    (b.node_id, b.position, &b.segment_ids),
                    "{name}"
                );
            }
            assert_eq!(net.neighbour_pairs, pairs, "{name}");
        }
    }

    fn way(ids: &[i64], pts: &[[f64; 2]], area: bool) -> HighwayWay {
        HighwayWay {
            area,
            ..HighwayWay::plain(1, "residential", ids.to_vec(), pts.to_vec())
        }
    }

    #[test]
    fn t_junction_by_hand() {
        // Way A: 1-2-3 along x; way B: 2-4 up from the middle node 2.
        let a = way(&[1, 2, 3], &[[0.0, 0.0], [1.0, 0.0], [2.0, 0.0]], false);
        let b = way(&[2, 4], &[[1.0, 0.0], [1.0, 1.0]], false);
        let net = build_network(&[a, b]);
        assert_eq!(net.segments.len(), 3);
        assert_eq!(net.intersections.len(), 1);
        assert_eq!(net.intersections[0].node_id, 2);
        assert_eq!(net.intersections[0].segment_ids, vec![0, 1, 2]);
        assert_eq!(net.neighbour_pairs, vec![[0, 1], [0, 2], [1, 2]]);
        assert_eq!(net.components().1, 1);
    }

    #[test]
    fn two_ways_meeting_end_to_end_make_an_intersection_and_areas_are_skipped() {
        let a = way(&[1, 2], &[[0.0, 0.0], [1.0, 0.0]], false);
        let b = way(&[2, 3], &[[1.0, 0.0], [2.0, 0.0]], false);
        let c = way(
            &[7, 8, 9, 7],
            &[[5.0, 5.0], [6.0, 5.0], [6.0, 6.0], [5.0, 5.0]],
            true,
        );
        let d = way(&[10, 11], &[[9.0, 9.0], [9.0, 10.0]], false);
        let net = build_network(&[a, b, c, d]);
        assert_eq!(net.segments.len(), 3);
        assert_eq!(net.intersections.len(), 1);
        assert_eq!(net.neighbour_pairs, vec![[0, 1]]);
        assert_eq!(net.components().1, 2);
    }
}
