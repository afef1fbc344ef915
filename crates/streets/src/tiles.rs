//! Street geometry tile by tile: a city cut into square tiles of the map's local frame, each
//! tile an independent job whose merged results equal [`StreetModel::estimate`] on the whole
//! map, bit for bit.
//!
//! **Why a tile can be exact.** A segment's potential depends on that segment, the map (its
//! intersections and competing centre lines) and the cloud only ([`PotentialStep`]). The
//! estimate couples observed segments along [`network_edges`](crate::model::network_edges), and
//! [`Network::max_product`](crate::inference::Network::max_product)
//! solves each connected component of that coupling graph on its own (tree components
//! exactly, loopy ones with their own stopping rule), so a segment's estimate is a function
//! of its component alone. A tile therefore owns the drivable segments whose midpoint lies
//! in its core square ([`TileGrid::tile_of`]) and reads, as its halo, every segment of the
//! coupling components its owned segments belong to — however far they reach. The
//! coupling graph is only known once potentials say which segments are observed, so
//! [`StreetModel::estimate_tile`] grows the halo breadth first: potentials of the owned
//! segments, then of each candidate neighbour ([`coupling`] over the map's neighbour
//! pairs) of every observed segment reached, until no new segment is reached. What it
//! reaches is exactly the union of the owned segments' components (plus, computed but
//! unused, the unobserved segments at their rims). Inference on that network gives each
//! owned segment the state the whole map gives it; a tile reports only its owned segments,
//! and [`merge_tiles`] sorts them back into the whole map's order.
//!
//! Cost: a tile computes potentials for its owned segments, its components and one ring of
//! unobserved neighbours; a component spanning many tiles is solved once per tile it
//! touches. The cloud is indexed once per tile, O(P).
//!
//! ```
//! use geodata::cloud::PointCloud;
//! use geodata::osm::OsmMap;
//! use streets::model::{Estimates, StreetModel};
//! use streets::tiles::{merge_tiles, plan_tiles};
//!
//! /// The whole map's estimate, one job per 1 km tile (each could run on its own machine).
//! fn by_tiles(model: &StreetModel, map: &OsmMap, cloud: &PointCloud) -> streets::Result<Estimates> {
//!     let parts = plan_tiles(map, 1000.0)?
//!         .iter()
//!         .map(|tile| model.estimate_tile(map, cloud, tile, "map.osm", "cloud.ply"))
//!         .collect::<streets::Result<Vec<_>>>()?;
//!     merge_tiles(parts)
//! }
//!
//! // A street of two ~150 m segments: 100 m tiles give each its own owner.
//! let map = OsmMap::from_xml_str(
//!     r#"<osm version="0.6"><node id="1" lat="48.0" lon="11.0"/>
//!        <node id="2" lat="48.0" lon="11.002"/><node id="3" lat="48.0" lon="11.004"/>
//!        <way id="5"><nd ref="1"/><nd ref="2"/><nd ref="3"/><tag k="highway" v="residential"/></way></osm>"#,
//! )?;
//! let plan = plan_tiles(&map, 100.0)?;
//! assert_eq!(plan.len(), 2);
//! assert!(plan.iter().all(|tile| tile.owned.len() == 1));
//! # Ok::<(), streets::StreetsError>(())
//! ```

use crate::model::{
    coupling, drivable_segments, Estimates, PotentialStep, SegmentEstimate, SegmentOutcome,
    StreetModel,
};
use crate::potentials::SegmentPotential;
use crate::{Result, StreetsError};
use geodata::cloud::PointCloud;
use geodata::osm::OsmMap;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

/// A tile's key: column and row of its core square in the grid.
pub type TileKey = (i64, i64);

/// Square tiles of the map's local metric frame (the frame of the segments' `a` and `b`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct TileGrid {
    /// Side of a tile, metres.
    pub tile_m: f64,
    /// Corner of tile (0, 0) in the local frame, metres.
    pub origin: [f64; 2],
}

impl TileGrid {
    /// A grid of `tile_m` tiles with tile (0, 0) at `origin`; tiles must be finite and positive.
    pub fn new(tile_m: f64, origin: [f64; 2]) -> Result<TileGrid> {
        if !(tile_m.is_finite() && tile_m > 0.0) {
            return Err(StreetsError::InvalidOption {
                name: "tile_m",
                value: tile_m,
                expected: "a finite tile side > 0 metres",
            });
        }
        for v in origin {
            if !v.is_finite() {
                return Err(StreetsError::InvalidOption {
                    name: "tile origin",
                    value: v,
                    expected: "finite coordinates in the map's local frame",
                });
            }
        }
        Ok(TileGrid { tile_m, origin })
    }

    /// The tile whose core square `[x0, x0 + tile_m) × [y0, y0 + tile_m)` holds `point`
    /// (every point has one; non-finite coordinates saturate to a border key).
    pub fn tile_of(&self, point: [f64; 2]) -> TileKey {
        (
            ((point[0] - self.origin[0]) / self.tile_m).floor() as i64,
            ((point[1] - self.origin[1]) / self.tile_m).floor() as i64,
        )
    }

    /// The core square of a tile: its lower and upper corners in the local frame, metres.
    pub fn core(&self, key: TileKey) -> ([f64; 2], [f64; 2]) {
        let lo = [
            self.origin[0] + key.0 as f64 * self.tile_m,
            self.origin[1] + key.1 as f64 * self.tile_m,
        ];
        (lo, [lo[0] + self.tile_m, lo[1] + self.tile_m])
    }

    /// Every tile owning at least one drivable segment (by its midpoint), ordered by key.
    pub fn plan(&self, map: &OsmMap) -> Vec<StreetTile> {
        let mut tiles: BTreeMap<TileKey, Vec<usize>> = BTreeMap::new();
        for (s, seg) in map.streets.segments.iter().enumerate() {
            if geodata::osm::tags::is_drivable(&seg.highway) {
                let mid = [0.5 * (seg.a[0] + seg.b[0]), 0.5 * (seg.a[1] + seg.b[1])];
                tiles.entry(self.tile_of(mid)).or_default().push(s);
            }
        }
        tiles
            .into_iter()
            .map(|(key, owned)| StreetTile { key, owned })
            .collect()
    }
}

/// One tile of a plan: its key and the drivable segments it owns.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct StreetTile {
    /// The tile's key in its grid.
    pub key: TileKey,
    /// Segments (indices into the map's street segments) whose midpoint lies in the core, ascending.
    pub owned: Vec<usize>,
}

/// Tiles of `tile_m` metres with tile (0, 0) at the local frame's origin; see [`TileGrid::plan`].
pub fn plan_tiles(map: &OsmMap, tile_m: f64) -> Result<Vec<StreetTile>> {
    Ok(TileGrid::new(tile_m, [0.0, 0.0])?.plan(map))
}

/// One tile's share of [`StreetModel::estimate`]: its owned segments' estimates and counts.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TileEstimates {
    /// The tile's key.
    pub key: TileKey,
    /// Estimates of the owned observed segments, ascending by segment.
    pub segments: Vec<SegmentEstimate>,
    /// Owned segments shorter than a bin.
    pub too_short: usize,
    /// Owned segments without usable bins.
    pub unobserved: usize,
    /// Whether every coupling component holding an owned segment is a tree (inference exact).
    pub exact: bool,
    /// Observed segments of other tiles in the owned segments' components (the halo), ascending.
    pub halo: Vec<usize>,
}

impl StreetModel {
    /// Estimates the segments `tile` owns, reading the whole coupling component of each
    /// (see the [module doc](crate::tiles)); equal to their entries in
    /// [`StreetModel::estimate`]. Owned segments that are not drivable are ignored, as
    /// `estimate` ignores them; an index outside the map is [`StreetsError::TilePlan`]. A
    /// tile off the cloud is no error (its segments count as unobserved), so `_cloud_name`
    /// only keeps the signature of `estimate`.
    pub fn estimate_tile(
        &self,
        map: &OsmMap,
        cloud: &PointCloud,
        tile: &StreetTile,
        map_name: &str,
        _cloud_name: &str,
    ) -> Result<TileEstimates> {
        drivable_segments(map, map_name)?;
        self.estimate_tile_with(PotentialStep::new(self, map, cloud), map, tile)
    }

    /// [`StreetModel::estimate_tile`] for a with-sidewalk model whose priors are centred on
    /// the driving area (`driving`, the whole map's driving-area estimates, e.g. the merge of
    /// a driving-area model's tiles); equal to the owned segments' entries in
    /// [`StreetModel::estimate_given_driving_area`] with the same `driving`.
    pub fn estimate_tile_given_driving_area(
        &self,
        map: &OsmMap,
        cloud: &PointCloud,
        tile: &StreetTile,
        map_name: &str,
        driving: &[SegmentEstimate],
    ) -> Result<TileEstimates> {
        drivable_segments(map, map_name)?;
        let step = self.step_given_driving_area(map, cloud, driving);
        self.estimate_tile_with(step, map, tile)
    }

    /// The owned segments' estimates of `tile` with the potentials of `step`.
    fn estimate_tile_with(
        &self,
        step: PotentialStep<'_>,
        map: &OsmMap,
        tile: &StreetTile,
    ) -> Result<TileEstimates> {
        let segs = &map.streets.segments;
        if let Some(&segment) = tile.owned.iter().find(|&&s| s >= segs.len()) {
            return Err(StreetsError::TilePlan {
                tile: tile.key,
                segment,
                segments: segs.len(),
            });
        }
        let drivable: Vec<bool> = segs
            .iter()
            .map(|s| geodata::osm::tags::is_drivable(&s.highway))
            .collect();
        // Candidate couplings: a pair is an edge of the network iff both ends are observed.
        let mut candidates: Vec<Vec<usize>> = vec![Vec::new(); segs.len()];
        for &[s1, s2] in &map.streets.neighbour_pairs {
            let ok = drivable.get(s1).copied().unwrap_or(false)
                && drivable.get(s2).copied().unwrap_or(false)
                && coupling(map, s1, s2, &self.geometry).is_some();
            if ok {
                candidates[s1].push(s2);
                candidates[s2].push(s1);
            }
        }
        let mut owned: Vec<usize> = tile
            .owned
            .iter()
            .copied()
            .filter(|&s| drivable[s])
            .collect();
        owned.sort_unstable();
        owned.dedup();
        let mut reached = vec![false; segs.len()];
        owned.iter().for_each(|&s| reached[s] = true);
        let mut outcomes: BTreeMap<usize, SegmentOutcome> = BTreeMap::new();
        let mut frontier = owned.clone();
        // Breadth first along candidate couplings, expanding observed segments only.
        while !frontier.is_empty() {
            let found = step.outcomes(&frontier)?;
            let mut next = Vec::new();
            for (&s, outcome) in frontier.iter().zip(found) {
                if matches!(outcome, SegmentOutcome::Observed { .. }) {
                    for &t in &candidates[s] {
                        if !reached[t] {
                            reached[t] = true;
                            next.push(t);
                        }
                    }
                }
                outcomes.insert(s, outcome);
            }
            next.sort_unstable();
            frontier = next;
        }
        let count = |kind: fn(&SegmentOutcome) -> bool| {
            owned
                .iter()
                .filter(|s| outcomes.get(s).is_some_and(kind))
                .count()
        };
        let too_short = count(|o| matches!(o, SegmentOutcome::TooShort));
        let unobserved = count(|o| matches!(o, SegmentOutcome::Unobserved));
        let observed: Vec<(usize, SegmentPotential, usize)> = outcomes
            .into_iter()
            .filter_map(|(s, o)| match o {
                SegmentOutcome::Observed { potential, bins } => Some((s, potential, bins)),
                _ => None,
            })
            .collect();
        let halo: Vec<usize> = observed
            .iter()
            .map(|o| o.0)
            .filter(|s| owned.binary_search(s).is_err())
            .collect();
        // Every component here holds an owned segment, so `exact` covers exactly those.
        let (estimates, exact) = self.infer(map, observed);
        let segments = estimates
            .into_iter()
            .filter(|e| owned.binary_search(&e.segment).is_ok())
            .collect();
        Ok(TileEstimates {
            key: tile.key,
            segments,
            too_short,
            unobserved,
            exact,
            halo,
        })
    }
}

/// The whole map's [`Estimates`] from its tiles' shares: segments sorted by index, counts
/// summed, `exact` when every tile's components were trees. Equal to
/// [`StreetModel::estimate`] when the tiles are a plan of the whole map (where `estimate`
/// fails for lack of observed segments, the merge holds none); a segment reported by two
/// tiles is [`StreetsError::TileOverlap`].
pub fn merge_tiles(parts: Vec<TileEstimates>) -> Result<Estimates> {
    let mut owner: BTreeMap<usize, TileKey> = BTreeMap::new();
    let mut merged = Estimates {
        segments: Vec::new(),
        too_short: 0,
        unobserved: 0,
        exact: true,
    };
    for part in parts {
        for e in &part.segments {
            if let Some(&first) = owner.get(&e.segment) {
                return Err(StreetsError::TileOverlap {
                    segment: e.segment,
                    first,
                    second: part.key,
                });
            }
            owner.insert(e.segment, part.key);
        }
        merged.segments.extend(part.segments);
        merged.too_short += part.too_short;
        merged.unobserved += part.unobserved;
        merged.exact &= part.exact;
    }
    merged.segments.sort_by_key(|e| e.segment);
    Ok(merged)
}
