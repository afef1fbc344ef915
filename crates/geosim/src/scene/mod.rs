//! The simulated world built from an OSM map: buildings, ground, clutter, and ray casting.
//!
//! - **Buildings**: every outline extruded to its height (`height` tag, else
//!   `building:levels` × 3 m + 1 m, else seeded 8–25 m). With the *map-error model* on,
//!   the world's buildings differ from the map as OSM outlines differ from reality: the
//!   map point of a world point p is p + D(p) with D a smooth seeded displacement field
//!   (imagery misregistration: shifts of a few metres, correlated over kilometres), every
//!   map node has its own small noise (shared nodes stay shared, so blocks keep their
//!   shape), some map buildings do not exist in the world, and the world has extra
//!   buildings the map lacks. Streets and their truth are not displaced.
//! - **Ground**: the paved driving area at z = 0 (capsules of radius wₛ/2 about each true
//!   centre line, see [`super::truth`]); everything else 0.15 m higher behind a kerb:
//!   sidewalks (capsules of radius wₛ/2 + sidewalk width about drivable segments, level with
//!   the street at lowered kerbs and on shared surfaces), other paved ground (footways, paths,
//!   cycleways, steps, pedestrian areas and a paved strip along every facade) and grass
//!   elsewhere. Materials, markings and lowered kerbs: [`super::ground`].
//!
//!   Labels: **Sidewalk** is only the sidewalk strip of a drivable segment, the ground its
//!   truth describes (so a streets dataset's bin labels agree with the true geometry of both
//!   targets); where the map draws a road's sidewalks as footways of their own, the strip
//!   reaches over them ([`super::truth`]), so they are sidewalk too. Other paved ground is
//!   labelled [`Class::Other`] with object id 0, as KITTI-360's `ground` class (footways and
//!   paths that are no road's sidewalk, squares, facade strips), and is neither driving area
//!   nor a street's sidewalk.
//! - **Clutter** a map does not have: parked cars along the kerbs, street trees and trees
//!   on grass, poles, bicycles, pedestrians, and fenced construction sites.
//!
//! Object ids: building `i` of [`Scene::buildings`] has id `i + 1`; the driving area of
//! segment `s` has [`Scene::street_object`]`(s)`, its sidewalks
//! [`Scene::sidewalk_object`]`(s)`; clutter objects follow; grass and plazas have id 0.

use super::ground::{GroundModel, GroundOptions, Look};
use super::raycast::{Caster, Shape};
use super::truth::{offset_centre_line, street_truth, StreetTruth, TruthOptions};
use super::{mix64, normal, purpose, stream_rng, SimError};
use geodata::classes::Class;
use geodata::osm::geometry::{
    point_in_polygon, point_in_ring, point_segment_distance, ring_bounds, signed_area,
};
use geodata::osm::model::StreetSegment;
use geodata::osm::OsmMap;
use geodata::projection::LocalFrame;
use rand::Rng;
use rstar::primitives::{GeomWithData, Rectangle};
use rstar::{RTree, AABB};
use serde::Serialize;

mod clutter;
mod map_error;
mod poses;
mod query;

pub use clutter::ClutterOptions;
use map_error::world_ring;
pub use map_error::{DisplacementField, FieldMode, MapErrorOptions};

/// Options of the simulated world.
#[derive(Debug, Clone, PartialEq)]
pub struct SceneOptions {
    /// True street geometry model.
    pub truth: TruthOptions,
    /// OSM map-error model (off by default).
    pub map_error: MapErrorOptions,
    /// Clutter.
    pub clutter: ClutterOptions,
    /// Kerb height: everything off the driving area is this much higher, metres.
    pub kerb_m: f64,
    /// Height range of buildings without `height` or `building:levels`, metres.
    pub building_height_range_m: [f64; 2],
    /// Width of the paved strip along every facade, metres.
    pub facade_path_m: f64,
    /// Ground materials and lowered kerbs.
    pub ground: GroundOptions,
    /// Grid cell side of the ray caster, metres.
    pub cell_m: f64,
}

impl Default for SceneOptions {
    fn default() -> Self {
        SceneOptions {
            truth: TruthOptions::default(),
            map_error: MapErrorOptions::none(),
            clutter: ClutterOptions::default(),
            kerb_m: 0.15,
            building_height_range_m: [8.0, 25.0],
            facade_path_m: 1.5,
            ground: GroundOptions::default(),
            cell_m: 4.0,
        }
    }
}

/// A building of the world.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct WorldBuilding {
    /// The map building it comes from (`None`: an extra building the map lacks).
    pub map_index: Option<usize>,
    /// Outer ring, counter-clockwise, metres in the local frame.
    pub outer: Vec<[f64; 2]>,
    /// Holes.
    pub inners: Vec<Vec<[f64; 2]>>,
    /// Height of the walls, metres.
    pub height_m: f64,
    /// Shift of the outline's vertex centroid from the map's, metres (zero without map error).
    pub shift_m: [f64; 2],
    /// Local rotation of the world outline relative to the map's (minus the field's rotation
    /// at its centroid), radians.
    pub rotation_rad: f64,
}

/// A clutter object with its true oriented bounding box.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SceneObject {
    /// Object id carried by its points.
    pub id: u32,
    /// Class of its points.
    pub class: Class,
    /// Centre of the bounding box, metres.
    pub centre: [f64; 3],
    /// Half extents of the box along its yaw direction, across, and up, metres.
    pub half_extents: [f64; 3],
    /// Yaw of the box's first axis, counter-clockwise from east, radians.
    pub yaw_rad: f64,
    /// The street segment it was placed along.
    pub segment: usize,
}

/// What the map-error model did.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct MapErrorReport {
    /// Map buildings absent from the world (indices into the map's buildings).
    pub removed: Vec<usize>,
    /// World buildings absent from the map.
    pub extra: usize,
    /// Mean shift length of the kept buildings, metres.
    pub mean_shift_m: f64,
    /// The displacement field: the map point of a world point p is p + D(p).
    pub field: DisplacementField,
}

/// What a surface point is: class, object id, and a material index for intensity and colour.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Surface {
    /// Class of the point.
    pub class: Class,
    /// Object id of the point.
    pub object: u32,
}

/// Where a ray met the world.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SceneHit {
    /// Distance along the ray, metres.
    pub t: f64,
    /// Hit point, metres in the local frame.
    pub point: [f64; 3],
    /// Unit normal facing the ray.
    pub normal: [f64; 3],
    /// What was hit.
    pub surface: Surface,
}

/// The ground at a point.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GroundCell {
    /// Street, sidewalk or grass.
    pub class: Class,
    /// Object id (street or sidewalk of a segment; 0 for grass and plazas).
    pub object: u32,
    /// Ground height, metres.
    pub z: f64,
    /// The segment whose driving area or sidewalk this is.
    pub segment: Option<usize>,
}

/// A sensor pose: position of the sensor origin and heading.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Pose {
    /// Sensor origin, metres in the local frame (z above the street surface).
    pub position: [f64; 3],
    /// Heading of the sensor's x axis, counter-clockwise from east (local frame), radians.
    pub yaw_rad: f64,
}

/// A capsule of the ground index: a true centre line with its street and sidewalk radii.
#[derive(Debug, Clone, Copy)]
struct Capsule {
    a: [f64; 2],
    b: [f64; 2],
    street_r: f64,
    sidewalk_r: f64,
    drivable: bool,
    segment: usize,
}

/// A uniform grid over capsules for ground classification.
#[derive(Debug, Clone)]
struct GroundIndex {
    min: [f64; 2],
    cell_m: f64,
    nx: usize,
    ny: usize,
    cell_start: Vec<u32>,
    items: Vec<u32>,
    capsules: Vec<Capsule>,
}

impl GroundIndex {
    fn new(capsules: Vec<Capsule>, min: [f64; 2], max: [f64; 2], cell_m: f64) -> Self {
        let nx = (((max[0] - min[0]) / cell_m).ceil() as usize).max(1);
        let ny = (((max[1] - min[1]) / cell_m).ceil() as usize).max(1);
        let range = |c: &Capsule| {
            let r = c.sidewalk_r;
            let lo = [c.a[0].min(c.b[0]) - r, c.a[1].min(c.b[1]) - r];
            let hi = [c.a[0].max(c.b[0]) + r, c.a[1].max(c.b[1]) + r];
            let f = |v: f64, k: usize, n: usize| {
                (((v - min[k]) / cell_m).floor().max(0.0) as usize).min(n - 1)
            };
            (
                f(lo[0], 0, nx),
                f(lo[1], 1, ny),
                f(hi[0], 0, nx),
                f(hi[1], 1, ny),
            )
        };
        let mut counts = vec![0u32; nx * ny + 1];
        for c in &capsules {
            let (x0, y0, x1, y1) = range(c);
            for iy in y0..=y1 {
                for ix in x0..=x1 {
                    counts[iy * nx + ix + 1] += 1;
                }
            }
        }
        for c in 0..nx * ny {
            counts[c + 1] += counts[c];
        }
        let mut fill = counts.clone();
        let mut items = vec![0u32; counts[nx * ny] as usize];
        for (i, c) in capsules.iter().enumerate() {
            let (x0, y0, x1, y1) = range(c);
            for iy in y0..=y1 {
                for ix in x0..=x1 {
                    let cell = iy * nx + ix;
                    items[fill[cell] as usize] = i as u32;
                    fill[cell] += 1;
                }
            }
        }
        GroundIndex {
            min,
            cell_m,
            nx,
            ny,
            cell_start: counts,
            items,
            capsules,
        }
    }

    fn near(&self, p: [f64; 2]) -> impl Iterator<Item = &Capsule> {
        let fx = (p[0] - self.min[0]) / self.cell_m;
        let fy = (p[1] - self.min[1]) / self.cell_m;
        let slice: &[u32] = if fx >= 0.0 && fy >= 0.0 {
            let (ix, iy) = (fx as usize, fy as usize);
            if ix < self.nx && iy < self.ny {
                let c = iy * self.nx + ix;
                &self.items[self.cell_start[c] as usize..self.cell_start[c + 1] as usize]
            } else {
                &[]
            }
        } else {
            &[]
        };
        slice.iter().map(|&i| &self.capsules[i as usize])
    }
}

/// A pedestrian area: its ring and bounding box.
type Plaza = (Vec<[f64; 2]>, [f64; 2], [f64; 2]);

/// The simulated world.
#[derive(Debug, Clone)]
pub struct Scene {
    /// The map's local frame.
    pub frame: LocalFrame,
    /// The map's street segments (the indices every truth refers to).
    pub segments: Vec<StreetSegment>,
    /// True street geometry per segment.
    pub truth: Vec<StreetTruth>,
    /// Buildings of the world.
    pub buildings: Vec<WorldBuilding>,
    /// Clutter objects with their true boxes.
    pub objects: Vec<SceneObject>,
    /// What the map-error model changed.
    pub map_error: MapErrorReport,
    /// Kerb height, metres.
    pub kerb_m: f64,
    /// Extent of the map (min, max), metres.
    pub bounds: ([f64; 2], [f64; 2]),
    facade_path_m: f64,
    ground_model: GroundModel,
    plazas: Vec<Plaza>,
    surfaces: Vec<Surface>,
    caster: Caster,
    ground: GroundIndex,
    building_boxes: RTree<GeomWithData<Rectangle<[f64; 2]>, usize>>,
}

fn centroid(ring: &[[f64; 2]]) -> [f64; 2] {
    let n = ring.len().max(1) as f64;
    let s = ring
        .iter()
        .fold([0.0, 0.0], |s, p| [s[0] + p[0], s[1] + p[1]]);
    [s[0] / n, s[1] / n]
}

fn check_probability(name: &'static str, value: f64) -> Result<(), SimError> {
    if (0.0..=1.0).contains(&value) {
        Ok(())
    } else {
        Err(SimError::InvalidOption {
            name,
            value,
            expected: "a probability in [0, 1]",
        })
    }
}

fn check_non_negative(name: &'static str, value: f64) -> Result<(), SimError> {
    if value.is_finite() && value >= 0.0 {
        Ok(())
    } else {
        Err(SimError::InvalidOption {
            name,
            value,
            expected: "a finite value ≥ 0",
        })
    }
}

impl SceneOptions {
    fn validate(&self) -> Result<(), SimError> {
        let e = &self.map_error;
        check_non_negative("map_error.field_rms_m", e.field_rms_m)?;
        let [lo, hi] = e.field_wavelength_m;
        if !(lo.is_finite() && hi.is_finite() && lo >= 50.0 && hi >= lo) {
            return Err(SimError::InvalidOption {
                name: "map_error.field_wavelength_m",
                value: lo,
                expected: "50 m ≤ shortest ≤ longest wavelength (a smooth field)",
            });
        }
        check_non_negative("map_error.node_sigma_m", e.node_sigma_m)?;
        check_non_negative("map_error.max_node_m", e.max_node_m)?;
        check_probability("map_error.removed_probability", e.removed_probability)?;
        check_non_negative("map_error.extra_per_km2", e.extra_per_km2)?;
        let c = &self.clutter;
        for (name, p) in [
            ("clutter.car_probability", c.car_probability),
            ("clutter.tree_probability", c.tree_probability),
            ("clutter.bicycle_probability", c.bicycle_probability),
            ("clutter.pedestrian_probability", c.pedestrian_probability),
            (
                "clutter.construction_probability",
                c.construction_probability,
            ),
            ("clutter.grass_tree_probability", c.grass_tree_probability),
        ] {
            check_probability(name, p)?;
        }
        if !(c.pole_spacing_m.is_finite() && c.pole_spacing_m >= 1.0) {
            return Err(SimError::InvalidOption {
                name: "clutter.pole_spacing_m",
                value: c.pole_spacing_m,
                expected: "a distance ≥ 1 m",
            });
        }
        check_non_negative("kerb_m", self.kerb_m)?;
        check_non_negative("facade_path_m", self.facade_path_m)?;
        self.ground.validate()?;
        let [lo, hi] = self.building_height_range_m;
        if !(lo.is_finite() && hi.is_finite() && lo >= 3.0 && hi >= lo) {
            return Err(SimError::InvalidOption {
                name: "building_height_range_m",
                value: lo,
                expected: "3 m ≤ min ≤ max",
            });
        }
        if !(self.cell_m.is_finite() && self.cell_m >= 0.5) {
            return Err(SimError::InvalidOption {
                name: "cell_m",
                value: self.cell_m,
                expected: "a cell side ≥ 0.5 m",
            });
        }
        Ok(())
    }
}

/// Builder state for clutter: shapes, surfaces and objects grow together.
struct Clutter<'a> {
    shapes: Vec<Shape>,
    surfaces: Vec<Surface>,
    objects: Vec<SceneObject>,
    next_id: u32,
    buildings: &'a RTree<GeomWithData<Rectangle<[f64; 2]>, usize>>,
    world: &'a [WorldBuilding],
}

impl Clutter<'_> {
    fn inside_building(&self, p: [f64; 2], margin: f64) -> bool {
        let query = AABB::from_corners(
            [p[0] - margin, p[1] - margin],
            [p[0] + margin, p[1] + margin],
        );
        self.buildings
            .locate_in_envelope_intersecting(&query)
            .any(|g| {
                let b = &self.world[g.data];
                point_in_polygon(p, &b.outer, &b.inners)
                    || (margin > 0.0
                        && ring_edges(&b.outer)
                            .any(|(a, c)| point_segment_distance(p, a, c) < margin))
            })
    }

    fn add(
        &mut self,
        class: Class,
        shapes: Vec<Shape>,
        bbox: ([f64; 3], [f64; 3], f64),
        segment: usize,
    ) {
        let id = self.next_id;
        self.next_id += 1;
        for s in shapes {
            self.shapes.push(s);
            self.surfaces.push(Surface { class, object: id });
        }
        self.objects.push(SceneObject {
            id,
            class,
            centre: bbox.0,
            half_extents: bbox.1,
            yaw_rad: bbox.2,
            segment,
        });
    }
}

fn ring_edges(ring: &[[f64; 2]]) -> impl Iterator<Item = ([f64; 2], [f64; 2])> + '_ {
    (0..ring.len()).map(move |i| (ring[i], ring[(i + 1) % ring.len()]))
}

impl Scene {
    /// Builds the world of a map; deterministic for a seed.
    ///
    /// O(B + S + clutter) to build, plus the caster's grid.
    pub fn build(map: &OsmMap, options: &SceneOptions, seed: u64) -> Result<Scene, SimError> {
        options.validate()?;
        if map.buildings.is_empty() && map.streets.segments.is_empty() {
            return Err(SimError::EmptyMap);
        }
        let truth = street_truth(map, &options.truth, seed)?;
        let segments = map.streets.segments.clone();

        // Map extent.
        let (mut min, mut max) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
        let all_points = map
            .buildings
            .iter()
            .flat_map(|b| b.outer.iter())
            .chain(segments.iter().flat_map(|s| [&s.a, &s.b]));
        for p in all_points {
            for k in 0..2 {
                min[k] = min[k].min(p[k]);
                max[k] = max[k].max(p[k]);
            }
        }

        // World buildings with the map-error model.
        let e = &options.map_error;
        let field = DisplacementField::seeded(e, seed);
        let mut buildings = Vec::with_capacity(map.buildings.len());
        let mut report = MapErrorReport::default();
        let mut shift_sum = 0.0;
        for (i, b) in map.buildings.iter().enumerate() {
            let mut rng = stream_rng(seed, purpose::MAP_ERROR, i as u64);
            let removed_draw: f64 = rng.gen();
            if removed_draw < e.removed_probability {
                report.removed.push(i);
                continue;
            }
            let c = centroid(&b.outer);
            let mut hrng = stream_rng(seed, purpose::HEIGHT, i as u64);
            let [hlo, hhi] = options.building_height_range_m;
            let drawn = hrng.gen_range(hlo..=hhi);
            let height_m = b
                .height_m
                .filter(|h| h.is_finite() && *h >= 2.0)
                .or(b
                    .levels
                    .filter(|l| l.is_finite() && *l >= 1.0)
                    .map(|l| 3.0 * l + 1.0))
                .unwrap_or(drawn)
                .min(300.0);
            let outer = world_ring(&b.outer, &field, e, seed);
            let wc = centroid(&outer);
            let shift = [wc[0] - c[0], wc[1] - c[1]];
            shift_sum += (shift[0] * shift[0] + shift[1] * shift[1]).sqrt();
            buildings.push(WorldBuilding {
                map_index: Some(i),
                outer,
                inners: b
                    .inners
                    .iter()
                    .map(|r| world_ring(r, &field, e, seed))
                    .collect(),
                height_m,
                shift_m: shift,
                rotation_rad: -field.rotation_rad(wc),
            });
        }
        report.mean_shift_m = shift_sum / buildings.len().max(1) as f64;
        report.field = field;

        // Ground capsules.
        let mut capsules = Vec::new();
        for (s, (seg, t)) in segments.iter().zip(&truth).enumerate() {
            if !t.on_ground || seg.length_m <= 0.0 {
                continue;
            }
            let [a, b] = offset_centre_line(seg, t);
            let street_r = 0.5 * t.width_m;
            capsules.push(Capsule {
                a,
                b,
                street_r: if t.drivable { street_r } else { 0.0 },
                sidewalk_r: street_r + if t.drivable { t.sidewalk_m } else { 0.0 },
                drivable: t.drivable,
                segment: s,
            });
        }
        let margin = 60.0;
        let (gmin, gmax) = if min[0].is_finite() {
            (
                [min[0] - margin, min[1] - margin],
                [max[0] + margin, max[1] + margin],
            )
        } else {
            ([-margin, -margin], [margin, margin])
        };
        let ground = GroundIndex::new(capsules, gmin, gmax, 8.0);
        let plazas = map
            .highways
            .iter()
            .filter(|h| h.area && h.points.len() >= 3)
            .map(|h| {
                let (lo, hi) = ring_bounds(&h.points);
                (h.points.clone(), lo, hi)
            })
            .collect();

        let building_tree = |bs: &[WorldBuilding]| {
            RTree::bulk_load(
                bs.iter()
                    .enumerate()
                    .map(|(i, b)| {
                        let (lo, hi) = ring_bounds(&b.outer);
                        GeomWithData::new(Rectangle::from_corners(lo, hi), i)
                    })
                    .collect(),
            )
        };
        let ground_model = GroundModel::new(&segments, &truth, &options.ground, seed);
        let mut scene = Scene {
            frame: map.frame,
            segments,
            truth,
            buildings,
            objects: Vec::new(),
            map_error: report,
            kerb_m: options.kerb_m,
            bounds: (gmin, gmax),
            facade_path_m: options.facade_path_m,
            ground_model,
            plazas,
            surfaces: Vec::new(),
            caster: Caster::new(Vec::new(), options.cell_m, (gmin, gmax)),
            ground,
            building_boxes: RTree::new(),
        };

        // Extra buildings in free space (grass), away from every street and building.
        if e.extra_per_km2 > 0.0 && min[0].is_finite() {
            let area_km2 = (max[0] - min[0]) * (max[1] - min[1]) / 1e6;
            let wanted = (e.extra_per_km2 * area_km2).round() as usize;
            let mut rng = stream_rng(seed, purpose::EXTRA_BUILDINGS, 0);
            let mut tree = building_tree(&scene.buildings);
            let mut placed = 0;
            for _ in 0..wanted * 50 {
                if placed >= wanted {
                    break;
                }
                let c = [
                    rng.gen_range(min[0]..=max[0]),
                    rng.gen_range(min[1]..=max[1]),
                ];
                let (hx, hy) = (rng.gen_range(4.0..10.0), rng.gen_range(4.0..10.0));
                let yaw: f64 = rng.gen_range(-std::f64::consts::PI..std::f64::consts::PI);
                let height_m = rng.gen_range(
                    options.building_height_range_m[0]..=options.building_height_range_m[1],
                );
                let (s, co) = yaw.sin_cos();
                let outer: Vec<[f64; 2]> = [[-hx, -hy], [hx, -hy], [hx, hy], [-hx, hy]]
                    .iter()
                    .map(|q| [c[0] + co * q[0] - s * q[1], c[1] + s * q[0] + co * q[1]])
                    .collect();
                let mut probe = outer.clone();
                probe.push(c);
                let free = probe.iter().all(|&p| {
                    scene.ground_class_without_facades(p).class == Class::Grass
                        && scene.ground.near(p).all(|cap| {
                            point_segment_distance(p, cap.a, cap.b) > cap.sidewalk_r + 4.0
                        })
                });
                let (lo, hi) = ring_bounds(&outer);
                let query =
                    AABB::from_corners([lo[0] - 3.0, lo[1] - 3.0], [hi[0] + 3.0, hi[1] + 3.0]);
                if !free
                    || tree
                        .locate_in_envelope_intersecting(&query)
                        .next()
                        .is_some()
                {
                    continue;
                }
                tree.insert(GeomWithData::new(
                    Rectangle::from_corners(lo, hi),
                    scene.buildings.len(),
                ));
                scene.buildings.push(WorldBuilding {
                    map_index: None,
                    outer,
                    inners: Vec::new(),
                    height_m,
                    shift_m: [0.0, 0.0],
                    rotation_rad: 0.0,
                });
                placed += 1;
            }
            scene.map_error.extra = placed;
        }
        scene.building_boxes = building_tree(&scene.buildings);

        // Walls.
        let mut shapes = Vec::new();
        let mut surfaces = Vec::new();
        for (i, b) in scene.buildings.iter().enumerate() {
            let object = i as u32 + 1;
            for ring in std::iter::once(&b.outer).chain(b.inners.iter()) {
                for (a, c) in ring_edges(ring) {
                    shapes.push(Shape::Wall {
                        a,
                        b: c,
                        z_min: -0.5,
                        z_max: b.height_m,
                    });
                    surfaces.push(Surface {
                        class: Class::Building,
                        object,
                    });
                }
            }
        }
        let walls = shapes.len();
        let mut clutter = Clutter {
            shapes,
            surfaces,
            objects: Vec::new(),
            next_id: scene.sidewalk_object(scene.segments.len()),
            buildings: &scene.building_boxes,
            world: &scene.buildings,
        };
        scene.place_clutter(&mut clutter, &options.clutter, seed);
        let Clutter {
            shapes,
            surfaces,
            objects,
            ..
        } = clutter;
        debug_assert!(shapes.len() >= walls);
        scene.surfaces = surfaces;
        scene.objects = objects;
        scene.caster = Caster::new(shapes, options.cell_m, (gmin, gmax));
        Ok(scene)
    }

    /// Object id of segment `s`'s driving area.
    pub fn street_object(&self, s: usize) -> u32 {
        (self.buildings.len() + 1 + s) as u32
    }

    /// Object id of segment `s`'s sidewalks (both sides).
    pub fn sidewalk_object(&self, s: usize) -> u32 {
        (self.buildings.len() + 1 + self.segments.len() + s) as u32
    }

    /// Number of solid shapes the caster holds (walls and clutter parts).
    pub fn shape_count(&self) -> usize {
        self.caster.shapes().len()
    }

    /// A stable colour for an object (facades and cars differ from object to object).
    pub fn object_tint(object: u32) -> [i32; 3] {
        let h = mix64(u64::from(object));
        [
            (h & 0x3f) as i32 - 32,
            ((h >> 8) & 0x3f) as i32 - 32,
            ((h >> 16) & 0x3f) as i32 - 32,
        ]
    }

    /// Signed area of the world's buildings, m² (a cheap summary for reports).
    pub fn building_area_m2(&self) -> f64 {
        self.buildings.iter().map(|b| signed_area(&b.outer)).sum()
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::city::{generate_city, CityOptions};

    /// The embedded procedural city at 400 m, the shared fixture of the simulator tests.
    pub(crate) fn small_map(seed: u64) -> OsmMap {
        let xml = generate_city(
            &CityOptions {
                size_m: 400.0,
                ..CityOptions::default()
            },
            seed,
        )
        .unwrap();
        OsmMap::from_xml_str(&xml).unwrap()
    }

    #[test]
    fn scene_has_every_kind_of_clutter_and_is_deterministic() {
        let map = small_map(3);
        let a = Scene::build(&map, &SceneOptions::default(), 5).unwrap();
        let b = Scene::build(&map, &SceneOptions::default(), 5).unwrap();
        assert_eq!(a.objects, b.objects);
        assert_eq!(a.buildings, b.buildings);
        assert_eq!(a.buildings.len(), map.buildings.len());
        for class in [Class::Car, Class::Tree, Class::Pole, Class::Other] {
            assert!(
                a.objects.iter().any(|o| o.class == class),
                "no {class} in the scene"
            );
        }
        for o in &a.objects {
            assert!(!a.inside_building([o.centre[0], o.centre[1]]), "{o:?}");
        }
    }

    #[test]
    fn map_error_moves_removes_and_adds_buildings() {
        let map = small_map(4);
        let options = SceneOptions {
            map_error: MapErrorOptions {
                extra_per_km2: 60.0,
                removed_probability: 0.1,
                ..MapErrorOptions::osm_like()
            },
            ..SceneOptions::default()
        };
        let scene = Scene::build(&map, &options, 2).unwrap();
        assert!(!scene.map_error.removed.is_empty());
        assert!(scene.map_error.extra > 0);
        assert!(scene.map_error.mean_shift_m > 0.3 && scene.map_error.mean_shift_m < 8.0);
        assert_eq!(
            scene.buildings.len(),
            map.buildings.len() - scene.map_error.removed.len() + scene.map_error.extra
        );
        // Each world node maps back onto its map node up to the node noise.
        let field = &scene.map_error.field;
        for b in scene.buildings.iter().filter(|b| b.map_index.is_some()) {
            let m = &map.buildings[b.map_index.unwrap()].outer;
            for (w, m) in b.outer.iter().zip(m) {
                let back = field.map_from_world(*w);
                assert!((back[0] - m[0]).abs() <= 0.76, "{back:?} vs {m:?}");
                assert!((back[1] - m[1]).abs() <= 0.76, "{back:?} vs {m:?}");
            }
        }
    }

    #[test]
    fn shared_map_nodes_stay_shared_in_the_world() {
        // Two buildings sharing the wall x = 10 (nodes (10, 0) and (10, 8)).
        let mut map = small_map(4);
        let a = vec![[0.0, 0.0], [10.0, 0.0], [10.0, 8.0], [0.0, 8.0]];
        let b = vec![[10.0, 0.0], [20.0, 0.0], [20.0, 8.0], [10.0, 8.0]];
        map.buildings.truncate(2);
        map.buildings[0].outer = a;
        map.buildings[0].inners.clear();
        map.buildings[1].outer = b;
        map.buildings[1].inners.clear();
        let options = SceneOptions {
            map_error: MapErrorOptions {
                removed_probability: 0.0,
                extra_per_km2: 0.0,
                ..MapErrorOptions::osm_like()
            },
            ..SceneOptions::default()
        };
        let scene = Scene::build(&map, &options, 9).unwrap();
        let (wa, wb) = (&scene.buildings[0].outer, &scene.buildings[1].outer);
        assert_eq!(wa[1], wb[0]);
        assert_eq!(wa[2], wb[3]);
        assert_ne!(wa[0], [0.0, 0.0]);
    }

    #[test]
    fn displacement_field_has_its_rms_inverts_and_rotates_as_its_curl() {
        let options = MapErrorOptions::osm_like();
        let field = DisplacementField::seeded(&options, 11);
        let (mut sx, mut sy, mut n) = (0.0, 0.0, 0.0);
        for i in 0..60 {
            for j in 0..60 {
                let p = [i as f64 * 150.0 - 4500.0, j as f64 * 150.0 - 4500.0];
                let d = field.displacement_m(p);
                sx += d[0] * d[0];
                sy += d[1] * d[1];
                n += 1.0;
                let q = field.world_from_map(p);
                let back = field.map_from_world(q);
                assert!((back[0] - p[0]).abs() < 1e-9 && (back[1] - p[1]).abs() < 1e-9);
            }
        }
        for rms in [(sx / n).sqrt(), (sy / n).sqrt()] {
            assert!((rms - 1.75).abs() < 0.6, "rms {rms}");
        }
        // The rotation is the curl's half, checked by central differences.
        let p = [123.0, -456.0];
        let h = 0.5;
        let dx = |q: [f64; 2]| field.displacement_m(q);
        let ddy_dx = (dx([p[0] + h, p[1]])[1] - dx([p[0] - h, p[1]])[1]) / (2.0 * h);
        let ddx_dy = (dx([p[0], p[1] + h])[0] - dx([p[0], p[1] - h])[0]) / (2.0 * h);
        assert!((field.rotation_rad(p) - 0.5 * (ddy_dx - ddx_dy)).abs() < 1e-8);
        assert!(field.rotation_rad(p).abs() < 0.02);
        assert_eq!(DisplacementField::seeded(&options, 11), field);
        assert_ne!(DisplacementField::seeded(&options, 12), field);
        let zero = DisplacementField::seeded(&MapErrorOptions::none(), 11);
        assert_eq!(zero.map_from_world(p), p);
    }

    #[test]
    fn ground_classes_follow_the_truth() {
        let map = small_map(5);
        // Plain ground: every sidewalk raised by the kerb (no lowered sections).
        let options = SceneOptions {
            ground: GroundOptions::plain(),
            ..SceneOptions::default()
        };
        let scene = Scene::build(&map, &options, 1).unwrap();
        let (s, (seg, t)) = scene
            .segments
            .iter()
            .zip(&scene.truth)
            .enumerate()
            .find(|(_, (seg, t))| t.drivable && t.sidewalk_m > 1.0 && seg.length_m > 30.0)
            .unwrap();
        let [a, b] = offset_centre_line(seg, t);
        let mid = [(a[0] + b[0]) / 2.0, (a[1] + b[1]) / 2.0];
        let cell = scene.ground_at(mid);
        assert_eq!(cell.class, Class::Street);
        assert_eq!(cell.z, 0.0);
        let e = [(b[0] - a[0]) / seg.length_m, (b[1] - a[1]) / seg.length_m];
        let side = [
            mid[0] - e[1] * (t.width_m / 2.0 + 0.5),
            mid[1] + e[0] * (t.width_m / 2.0 + 0.5),
        ];
        let cell = scene.ground_at(side);
        assert_eq!(cell.class, Class::Sidewalk, "segment {s}");
        assert_eq!(cell.z, scene.kerb_m);
        // With the varied ground the class is the same; the sidewalk is raised unless lowered.
        let varied = Scene::build(&map, &SceneOptions::default(), 1).unwrap();
        let cell = varied.ground_at(side);
        assert_eq!(cell.class, Class::Sidewalk);
        let lowered = varied.ground_model.sidewalk_lowered(s, seg, side);
        assert_eq!(cell.z, if lowered { 0.0 } else { varied.kerb_m });
    }

    #[test]
    fn other_paved_ground_is_not_a_sidewalk() {
        let map = small_map(5);
        let scene = Scene::build(&map, &SceneOptions::default(), 1).unwrap();
        // Next to a wall, away from every street: the facade strip.
        let b = &scene.buildings[0];
        let (a, c) = (b.outer[0], b.outer[1]);
        let e = [c[0] - a[0], c[1] - a[1]];
        let len = (e[0] * e[0] + e[1] * e[1]).sqrt();
        let out = [e[1] / len, -e[0] / len];
        let p = [
            0.5 * (a[0] + c[0]) + 0.5 * out[0],
            0.5 * (a[1] + c[1]) + 0.5 * out[1],
        ];
        let cell = scene.ground_at(p);
        if cell.segment.is_none() && !scene.inside_building(p) {
            assert_eq!(cell.class, Class::Other);
            assert_eq!(cell.object, 0);
        }
        // Footways are other paved ground too.
        for (s, (seg, t)) in scene.segments.iter().zip(&scene.truth).enumerate() {
            if t.drivable || !t.on_ground || seg.length_m < 1.0 {
                continue;
            }
            let [a, b] = offset_centre_line(seg, t);
            let mid = [(a[0] + b[0]) / 2.0, (a[1] + b[1]) / 2.0];
            let cell = scene.ground_at(mid);
            if cell.segment == Some(s) {
                assert_eq!(cell.class, Class::Other);
                assert!(Scene::is_ground(Surface {
                    class: cell.class,
                    object: cell.object
                }));
            }
        }
    }

    #[test]
    fn rejects_empty_maps_and_bad_options() {
        let map = small_map(1);
        let bad = SceneOptions {
            kerb_m: f64::NAN,
            ..SceneOptions::default()
        };
        assert!(matches!(
            Scene::build(&map, &bad, 1),
            Err(SimError::InvalidOption { name: "kerb_m", .. })
        ));
        let mut empty = map.clone();
        empty.buildings.clear();
        empty.streets = Default::default();
        assert!(matches!(
            Scene::build(&empty, &SceneOptions::default(), 1),
            Err(SimError::EmptyMap)
        ));
    }
}
