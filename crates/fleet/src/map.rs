//! The map-building job as shards: semantic maps (`.srt`) of every street a fleet drove, one
//! shard per map tile, from labelled clouds already registered in the map's local frame.
//!
//! The plan ([`plan_map`]) reads every input cloud once: the cells its points fall in (keys of
//! the map's cell grid, `--resolution`), hence the non-empty tiles of side `tile_m` (a whole
//! number of cells) and the inputs touching each, and the cell bounding box of every object
//! (the clouds' instance ids). Each object is owned by the tile holding the centre of its box,
//! and its owner's *window* is the tile's core grown to hold the boxes of all objects it owns.
//!
//! A shard ([`tile_lines`]) inserts the points of its window (from the inputs that touch it,
//! each checked against the plan's size and CRC-32) into an [`SrMap`], extracts the objects,
//! writes the window's map as `tile-K.srt` beside its result, and returns one JSON line: the
//! tile, its map file, the cells of its core and its owned objects. Every cell of a core is
//! built from exactly the points the whole map puts in it, in the same order, and every owned
//! object from all its cells, so the cores partition the whole map's cells and the owned
//! objects are the whole map's objects (tested). The merge ([`merge_parts`]) writes a WGS84
//! GeoJSON: each object's box footprint and each tile's core with its map file.

use crate::plan::{
    absolute, cloud_files, tile_stages, Job, JobOptions, MapJob, MapTile, Plan, Shard, PLAN_FORMAT,
    PLAN_VERSION,
};
use crate::{invalid, io_err, FleetError, Result};
use geodata::cloud::{read_cloud, PointCloud};
use geodata::osm::OsmMap;
use localize::tiles::FileRef;
use serde::{Deserialize, Serialize};
use serde_json::{json, Map, Value};
use srtree::map::{MapOptions, SrMap};
use srtree::objects::{extract_objects, ObjectOptions};
use srtree::semantic::SemanticMap;
use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

/// The stage name of the map job's shards.
pub const STAGE: &str = "map-tiles";

/// Cloud file extensions the map job takes from its input folder.
const CLOUD_EXTENSIONS: [&str; 6] = ["ply", "pcd", "las", "laz", "bin", "xyz"];

/// One owned object of a tile's result.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ObjectRecord {
    /// Instance id (as in the clouds).
    pub id: u32,
    /// Majority class name.
    pub class: String,
    /// Occupied cells.
    pub cells: usize,
    /// Mean of its cell centres, metres (local frame).
    pub centroid: [f64; 3],
    /// Oriented box centre, metres.
    pub centre: [f64; 3],
    /// Oriented box half extents, metres.
    pub half_extents: [f64; 3],
    /// Oriented box yaw, radians.
    pub yaw_rad: f64,
}

/// A map shard's result line.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct MapTileResult {
    /// The tile's position in the plan.
    pub tile: usize,
    /// Its core in metres `[x0, y0, x1, y1]` (local frame).
    pub core_m: [f64; 4],
    /// Its map file (the window's cells and objects), beside the results.
    pub map: String,
    /// The map file's size, bytes.
    pub bytes: u64,
    /// The map file's CRC-32.
    pub crc32: u32,
    /// Occupied cells of the core.
    pub core_cells: usize,
    /// Cells of the window's map.
    pub window_cells: usize,
    /// The objects the tile owns, by id.
    pub objects: Vec<ObjectRecord>,
}

/// The merged answer of a map-building plan (`shard merge --out map.geojson`).
#[derive(Debug, Clone, PartialEq)]
pub struct MapMerge {
    /// The plan.
    pub plan: String,
    /// Every tile's result, in plan order.
    pub tiles: Vec<MapTileResult>,
    /// WGS84 GeoJSON: each object's box footprint and each tile's core.
    pub geojson: Value,
    /// Shards merged.
    pub shards: usize,
    /// Seconds of the merge.
    pub seconds: f64,
}

fn cell_options(resolution_m: f64) -> MapOptions {
    MapOptions {
        resolution_m,
        ..MapOptions::default()
    }
}

fn in_box(k: [i32; 3], b: [i32; 4]) -> bool {
    k[0] >= b[0] && k[0] < b[2] && k[1] >= b[1] && k[1] < b[3]
}

fn union(a: [i32; 4], b: [i32; 4]) -> [i32; 4] {
    [
        a[0].min(b[0]),
        a[1].min(b[1]),
        a[2].max(b[2]),
        a[3].max(b[3]),
    ]
}

fn overlaps(a: [i32; 4], b: [i32; 4]) -> bool {
    a[0] < b[2] && b[0] < a[2] && a[1] < b[3] && b[1] < a[3]
}

/// The cloud files of `inputs` (a folder: every cloud file in it by name; a file: itself).
fn input_files(inputs: &Path) -> Result<Vec<PathBuf>> {
    if inputs.is_file() {
        return Ok(vec![inputs.to_path_buf()]);
    }
    cloud_files(inputs, &CLOUD_EXTENSIONS, "labelled cloud files")
}

/// Plans the map-building job: the labelled clouds of `inputs` (a folder or one file, in the
/// local frame of the OSM `map`) into `tile_m` tiles of `resolution_m` cells, results (and
/// the tiles' `.srt` maps) into `out`.
pub fn plan_map(
    map: &Path,
    inputs: &Path,
    out: &Path,
    tile_m: f64,
    resolution_m: f64,
) -> Result<Plan> {
    let cells = tile_m / resolution_m;
    if !(resolution_m > 0.0 && resolution_m.is_finite() && tile_m.is_finite())
        || cells < 1.0
        || (cells - cells.round()).abs() > 1e-6
        || cells.round() > f64::from(i32::MAX / 4)
    {
        return Err(invalid(
            map,
            format!("tile {tile_m} m with {resolution_m} m cells: the tile side must be a positive whole number of cells"),
        ));
    }
    let tile_cells = cells.round() as i32;
    let map_abs = absolute(map)?;
    OsmMap::load(&map_abs)?;
    let map_ref = FileRef::of(&map_abs, &map_abs.to_string_lossy())?;
    let grid = SrMap::new(cell_options(resolution_m)).map_err(srtree_err(map))?;
    let files = input_files(inputs)?;
    let tile_of = |k: [i32; 3]| [k[0].div_euclid(tile_cells), k[1].div_euclid(tile_cells)];
    let core_of = |g: [i32; 2]| {
        [
            g[0] * tile_cells,
            g[1] * tile_cells,
            (g[0] + 1) * tile_cells,
            (g[1] + 1) * tile_cells,
        ]
    };
    let mut refs = Vec::with_capacity(files.len());
    let mut input_boxes: Vec<Option<[i32; 4]>> = Vec::with_capacity(files.len());
    let mut tiles: BTreeSet<[i32; 2]> = BTreeSet::new();
    let mut object_boxes: BTreeMap<u32, [i32; 4]> = BTreeMap::new();
    for f in &files {
        let abs = absolute(f)?;
        refs.push(FileRef::of(&abs, &abs.to_string_lossy())?);
        let cloud = read_cloud(&abs).map_err(|e| io_err(&abs, e))?;
        let mut b: Option<[i32; 4]> = None;
        for (i, p) in cloud.positions.iter().enumerate() {
            if !p.iter().all(|v| v.is_finite()) {
                continue;
            }
            let k = grid.key_of(*p);
            let cell = [k[0], k[1], k[0] + 1, k[1] + 1];
            b = Some(b.map_or(cell, |b| union(b, cell)));
            tiles.insert(tile_of(k));
            if let Some(&id) = cloud.object.as_ref().and_then(|o| o.get(i)) {
                if id != 0 {
                    let e = object_boxes.entry(id).or_insert(cell);
                    *e = union(*e, cell);
                }
            }
        }
        input_boxes.push(b);
    }
    if tiles.is_empty() {
        return Err(invalid(
            inputs,
            "no finite point in the inputs: nothing to map".into(),
        ));
    }
    // Each object to the tile holding the centre of its box.
    let mut owned: BTreeMap<[i32; 2], Vec<u32>> = BTreeMap::new();
    for (&id, b) in &object_boxes {
        let centre = [
            (b[0] + b[2] - 1).div_euclid(2),
            (b[1] + b[3] - 1).div_euclid(2),
            0,
        ];
        let g = tile_of(centre);
        tiles.insert(g);
        owned.entry(g).or_default().push(id);
    }
    let map_tiles: Vec<MapTile> = tiles
        .into_iter()
        .map(|g| {
            let core = core_of(g);
            let objects = owned.remove(&g).unwrap_or_default();
            let window = objects
                .iter()
                .filter_map(|id| object_boxes.get(id))
                .fold(core, |w, b| union(w, *b));
            let inputs = input_boxes
                .iter()
                .enumerate()
                .filter(|(_, b)| b.is_some_and(|b| overlaps(b, window)))
                .map(|(i, _)| i)
                .collect();
            MapTile {
                grid: g,
                core,
                window,
                objects,
                inputs,
            }
        })
        .collect();
    std::fs::create_dir_all(out).map_err(|e| io_err(out, e))?;
    let out_abs = absolute(out)?;
    let (stages, shards) = tile_stages(&[STAGE], map_tiles.len(), [0, refs.len()]);
    Ok(Plan {
        format: PLAN_FORMAT.into(),
        version: PLAN_VERSION,
        job: Job::Map,
        map: map_ref,
        inputs: refs,
        options: JobOptions::default(),
        batch_size: files.len(),
        out: out_abs.to_string_lossy().into_owned(),
        stages,
        shards,
        model: None,
        driving_model: None,
        tile_m: Some(tile_m),
        street_tiles: Vec::new(),
        map_job: Some(MapJob { resolution_m }),
        map_tiles,
    })
}

fn srtree_err(path: &Path) -> impl Fn(srtree::SrtreeError) -> FleetError + '_ {
    move |e| invalid(path, e.to_string())
}

/// The plan's map-job options and tile `k`.
fn job_tile<'p>(
    plan_path: &Path,
    plan: &'p Plan,
    k: Option<usize>,
) -> Result<(&'p MapJob, &'p MapTile)> {
    let job = plan
        .map_job
        .as_ref()
        .ok_or_else(|| invalid(plan_path, "a map plan without its map options".into()))?;
    let tile = k.and_then(|k| plan.map_tiles.get(k)).ok_or_else(|| {
        invalid(
            plan_path,
            format!(
                "a shard names tile {k:?}; the plan lists {} map tiles",
                plan.map_tiles.len()
            ),
        )
    })?;
    Ok((job, tile))
}

/// The map file of tile `k` of a map plan (beside the results).
pub fn tile_map_path(plan: &Plan, k: usize) -> PathBuf {
    Path::new(&plan.out).join(format!("tile-{k:06}.srt"))
}

/// A map shard's result lines: its tile's [`MapTileResult`] as one JSON line; writes the
/// window's map beside it.
pub fn tile_lines(plan_path: &Path, plan: &Plan, shard: &Shard) -> Result<Vec<String>> {
    let (job, tile) = job_tile(plan_path, plan, shard.tile)?;
    let k = shard.tile.unwrap_or_default();
    let mut cells = SrMap::new(cell_options(job.resolution_m)).map_err(srtree_err(plan_path))?;
    let mut clouds: Vec<PointCloud> = Vec::with_capacity(tile.inputs.len());
    for &i in &tile.inputs {
        let file = plan.inputs.get(i).ok_or_else(|| {
            invalid(
                plan_path,
                format!(
                    "tile {k} names input {i}; the plan lists {}",
                    plan.inputs.len()
                ),
            )
        })?;
        let (path, _) = crate::streets::checked_bytes(file, "cloud")?;
        let cloud = read_cloud(&path).map_err(|e| io_err(&path, e))?;
        let window = tile.window;
        let kept = cloud.filter(|j| {
            cloud.positions.get(j).is_some_and(|p| {
                p.iter().all(|v| v.is_finite()) && in_box(cells.key_of(*p), window)
            })
        });
        clouds.push(kept);
    }
    let scans: Vec<(&PointCloud, Option<[f64; 3]>)> = clouds.iter().map(|c| (c, None)).collect();
    cells.insert_scans(&scans).map_err(srtree_err(plan_path))?;
    let objects = extract_objects(&cells, &ObjectOptions::default());
    let core_cells = cells
        .cells()
        .iter()
        .filter(|c| c.occupied() && in_box(c.key, tile.core))
        .count();
    let window_cells = cells.len();
    let wanted: BTreeSet<u32> = tile.objects.iter().copied().collect();
    let records: Vec<ObjectRecord> = objects
        .iter()
        .filter(|o| wanted.contains(&o.id))
        .map(|o| ObjectRecord {
            id: o.id,
            class: o.class.name().to_owned(),
            cells: o.cells.len(),
            centroid: o.centroid,
            centre: o.bbox.centre,
            half_extents: o.bbox.half_extents,
            yaw_rad: o.bbox.yaw_rad,
        })
        .collect();
    let mut semantic = SemanticMap::new(cells);
    semantic.relations.objects = objects.iter().map(|o| o.node()).collect();
    let path = tile_map_path(plan, k);
    let tmp = path.with_extension("srt.part");
    srtree::io::write_map(&tmp, &semantic).map_err(srtree_err(&tmp))?;
    let bytes = std::fs::read(&tmp).map_err(|e| io_err(&tmp, e))?;
    std::fs::rename(&tmp, &path).map_err(|e| io_err(&path, e))?;
    let r = job.resolution_m;
    let result = MapTileResult {
        tile: k,
        core_m: tile.core.map(|v| f64::from(v) * r),
        map: path
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default(),
        bytes: bytes.len() as u64,
        crc32: crc32fast::hash(&bytes),
        core_cells,
        window_cells,
        objects: records,
    };
    let line = serde_json::to_string(&result).map_err(|e| io_err(plan_path, e))?;
    Ok(vec![line])
}

/// The merge of a map-building plan from its shards' results (one per tile).
pub fn merge_parts(plan_path: &Path, plan: &Plan, parts: Vec<MapTileResult>) -> Result<MapMerge> {
    let t = std::time::Instant::now();
    let (path, _) = crate::streets::checked_bytes(&plan.map, "map")?;
    let osm = OsmMap::load(&path)?;
    let frame = &osm.frame;
    let mut features = Vec::new();
    for part in &parts {
        let [x0, y0, x1, y1] = part.core_m;
        let ring = geodata::geojson::ring(frame, &[[x0, y0], [x1, y0], [x1, y1], [x0, y1]], true);
        let mut props = Map::new();
        props.insert("kind".into(), json!("tile"));
        props.insert("tile".into(), json!(part.tile));
        props.insert("map".into(), json!(part.map));
        props.insert("cells".into(), json!(part.core_cells));
        props.insert("objects".into(), json!(part.objects.len()));
        features.push(geodata::geojson::feature(
            json!({"type": "Polygon", "coordinates": [ring]}),
            props,
        ));
        for o in &part.objects {
            let b = srtree::objects::OrientedBox {
                centre: o.centre,
                half_extents: o.half_extents,
                yaw_rad: o.yaw_rad,
            };
            let ring = geodata::geojson::ring(frame, &b.footprint(), true);
            let mut props = Map::new();
            props.insert("kind".into(), json!("object"));
            props.insert("id".into(), json!(o.id));
            props.insert("class".into(), json!(o.class));
            props.insert("cells".into(), json!(o.cells));
            props.insert("tile".into(), json!(part.tile));
            props.insert("z_min".into(), json!(o.centre[2] - o.half_extents[2]));
            props.insert("z_max".into(), json!(o.centre[2] + o.half_extents[2]));
            features.push(geodata::geojson::feature(
                json!({"type": "Polygon", "coordinates": [ring]}),
                props,
            ));
        }
    }
    let geojson = geodata::geojson::feature_collection(features);
    geodata::geojson::validate(&geojson)
        .map_err(|e| invalid(plan_path, format!("internal: the merged GeoJSON: {e}")))?;
    Ok(MapMerge {
        plan: plan_path.display().to_string(),
        tiles: parts,
        geojson,
        shards: plan.shards.len(),
        seconds: t.elapsed().as_secs_f64(),
    })
}
