//! The semantic map: the cell store ([`SrMap`]) and the spatial relation graph inferred over
//! its objects, as a `.srt` file holds them ([`crate::io`]).
//!
//! ```
//! use srtree::map::{MapOptions, SrMap};
//! use srtree::semantic::SemanticMap;
//! let map = SemanticMap::new(SrMap::new(MapOptions::default())?);
//! assert!(map.cells.is_empty() && map.relations.edges.is_empty());
//! # Ok::<(), srtree::SrtreeError>(())
//! ```

use crate::graph::RelationGraph;
use crate::map::SrMap;

/// A map's cells and the relation graph over its objects.
#[derive(Debug, Clone)]
pub struct SemanticMap {
    /// The occupied cells: occupancy, class histogram, colour and object per cell.
    pub cells: SrMap,
    /// The spatial relation graph inferred over the cells' objects.
    pub relations: RelationGraph,
}

impl SemanticMap {
    /// A semantic map of these cells, without relations yet.
    pub fn new(cells: SrMap) -> SemanticMap {
        SemanticMap {
            cells,
            relations: RelationGraph::default(),
        }
    }

    /// A semantic map of these cells with their extracted objects as graph nodes, without
    /// relations yet.
    pub fn with_objects(cells: SrMap, options: &crate::objects::ObjectOptions) -> SemanticMap {
        let objects = crate::objects::extract_objects(&cells, options);
        let mut map = SemanticMap::new(cells);
        map.relations.objects = objects.iter().map(|o| o.node()).collect();
        map
    }
}
