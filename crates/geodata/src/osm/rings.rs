//! Multipolygon ring assembly: join outer/inner member ways end to end into closed rings.

use super::{geometry, ring_from_closed, NodeTable, RawRelation};
use rustc_hash::FxHashMap;

/// Why a multipolygon relation produced no rings.
#[derive(Debug, PartialEq, Eq)]
pub(crate) enum RingError {
    /// A member way or one of its nodes is missing from the file.
    Missing,
    /// The member ways do not join into closed rings (or a ring is degenerate).
    Unclosed,
}

/// A polygon: outer ring (counter-clockwise) with its holes (clockwise).
pub(crate) type Polygon = (Vec<[f64; 2]>, Vec<Vec<[f64; 2]>>);

/// Joins way pieces (node id lists) into closed rings by matching end node ids.
///
/// Pieces are followed from their end: a piece whose first or last id equals the current
/// end is appended (reversed when needed). O(k²) in the number of pieces k.
pub(crate) fn join_pieces(mut remaining: Vec<Vec<i64>>) -> Result<Vec<Vec<i64>>, RingError> {
    let mut rings = Vec::new();
    while let Some(mut current) = remaining.pop() {
        loop {
            if current.len() >= 4 && current.first() == current.last() {
                rings.push(current);
                break;
            }
            let Some(&end) = current.last() else {
                return Err(RingError::Unclosed);
            };
            let Some(pos) = remaining
                .iter()
                .position(|p| p.first() == Some(&end) || p.last() == Some(&end))
            else {
                return Err(RingError::Unclosed);
            };
            let mut next = remaining.swap_remove(pos);
            if next.first() != Some(&end) {
                next.reverse();
            }
            current.extend(next.into_iter().skip(1));
        }
    }
    Ok(rings)
}

/// Builds the polygons of one building multipolygon relation.
pub(crate) fn assemble(
    rel: &RawRelation,
    way_refs: &FxHashMap<i64, &[i64]>,
    nodes: &NodeTable,
) -> Result<Vec<Polygon>, RingError> {
    let mut outer_pieces = Vec::new();
    let mut inner_pieces = Vec::new();
    for (way_id, role) in &rel.way_members {
        let refs = way_refs.get(way_id).ok_or(RingError::Missing)?;
        if role == "inner" {
            inner_pieces.push(refs.to_vec());
        } else {
            outer_pieces.push(refs.to_vec());
        }
    }
    if outer_pieces.is_empty() {
        return Err(RingError::Unclosed);
    }
    let to_rings = |pieces: Vec<Vec<i64>>, ccw: bool| -> Result<Vec<Vec<[f64; 2]>>, RingError> {
        join_pieces(pieces)?
            .iter()
            .map(|ids| {
                let points = nodes.project(ids).ok_or(RingError::Missing)?;
                ring_from_closed(points, ccw).ok_or(RingError::Unclosed)
            })
            .collect()
    };
    let outers = to_rings(outer_pieces, true)?;
    let inners = to_rings(inner_pieces, false)?;
    let mut polygons: Vec<Polygon> = outers.into_iter().map(|o| (o, Vec::new())).collect();
    for inner in inners {
        let Some(&probe) = inner.first() else {
            continue;
        };
        if let Some(poly) = polygons
            .iter_mut()
            .find(|(o, _)| geometry::point_in_ring(probe, o))
        {
            poly.1.push(inner);
        }
    }
    Ok(polygons)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn joins_reversed_pieces_into_one_ring() {
        let rings = join_pieces(vec![vec![1, 2, 3], vec![5, 4, 3], vec![5, 6, 1]]).unwrap();
        assert_eq!(rings.len(), 1);
        let ring = &rings[0];
        assert_eq!(ring.first(), ring.last());
        assert_eq!(ring.len(), 7);
    }

    #[test]
    fn open_pieces_are_unclosed() {
        assert_eq!(
            join_pieces(vec![vec![1, 2, 3], vec![3, 4]]),
            Err(RingError::Unclosed)
        );
    }

    #[test]
    fn two_closed_rings_stay_apart() {
        let rings = join_pieces(vec![vec![1, 2, 3, 1], vec![4, 5, 6, 4]]).unwrap();
        assert_eq!(rings.len(), 2);
    }
}
