//! Reader of `relations` datasets written by `urbansem sim dataset --kind relations`.
//!
//! A dataset folder has `dataset.json` (`train`, `test`: scene indices) and per scene
//! `scene_XXX.ply` (a labelled scan in the local frame with `label` and `object` columns)
//! and `scene_XXX.json` (`viewpoint` `{x, y, z, yaw}`, `objects` `[{id, class, ground, …}]`,
//! `pairs` `[{a, b, truth: {On, LeftOf, Behind}, annotated: {…}}]`). Each scene's scan is
//! inserted into an [`SrMap`] and its objects extracted from the map, so the relations are
//! estimated from the map and never from the simulator's true boxes. Where `dataset.json`
//! names a `map_buildings` file (the robot map's building outlines near the scenes), the
//! buildings are completed from the outlines they stand in ([`MapOutlines`]).

use crate::amodal::{AnnotatedBox, MapOutlines};
use crate::error::{io_err, Result, SrtreeError};
use crate::features::ViewObject;
use crate::graph::{Relation, Viewpoint};
use crate::map::{MapOptions, SrMap};
use crate::objects::{extract_objects, ObjectOptions};
use geodata::simfiles::MapBuildings;
use rayon::prelude::*;
use serde_json::Value;
use std::path::{Path, PathBuf};

/// One annotated ordered pair, as indices into [`Scene::objects`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct LabelledPair {
    /// Subject index.
    pub a: usize,
    /// Object index.
    pub b: usize,
    /// Noise-free relations (bits of [`Relation`]).
    pub truth: u8,
    /// The annotator's relations (with annotator noise).
    pub annotated: u8,
}

/// One scene: its viewpoint, objects estimated from the map, and labelled pairs.
#[derive(Debug, Clone)]
pub struct Scene {
    /// Scene index in the dataset.
    pub index: usize,
    /// The viewpoint.
    pub viewpoint: Viewpoint,
    /// Objects of the dataset's list found in the map, seen from the viewpoint.
    pub objects: Vec<ViewObject>,
    /// The annotated box of each object (`None` where the file gives none); training reads
    /// them for the amodal class priors, evaluation never does.
    pub annotated_boxes: Vec<Option<AnnotatedBox>>,
    /// Labelled pairs between them.
    pub pairs: Vec<LabelledPair>,
    /// Pairs of the file whose objects the map did not hold (scored as all-false).
    pub missing_pairs: Vec<(u32, u32, u8)>,
}

/// A loaded dataset.
#[derive(Debug, Clone)]
pub struct RelationsDataset {
    /// The folder.
    pub dir: PathBuf,
    /// Training scenes.
    pub train: Vec<Scene>,
    /// Test scenes.
    pub test: Vec<Scene>,
}

/// A cross-dataset split ([`RelationsDataset::load_across`]).
#[derive(Debug, Clone)]
pub struct CrossSplit {
    /// The test dataset, every scene in `test` (its `train` empty).
    pub test: RelationsDataset,
    /// The training scenes of the other datasets.
    pub train: Vec<Scene>,
}

fn read_json(path: &Path) -> Result<Value> {
    let text = std::fs::read_to_string(path).map_err(io_err(path))?;
    serde_json::from_str(&text).map_err(|e| SrtreeError::Dataset {
        path: path.to_path_buf(),
        message: format!("line {}: {e}", e.line()),
    })
}

fn bad(path: &Path, message: String) -> SrtreeError {
    SrtreeError::Dataset {
        path: path.to_path_buf(),
        message,
    }
}

fn indices(meta: &Value, key: &str, path: &Path) -> Result<Vec<usize>> {
    meta.get(key)
        .and_then(Value::as_array)
        .ok_or_else(|| bad(path, format!("missing array `{key}` of scene indices")))?
        .iter()
        .map(|v| {
            v.as_u64()
                .map(|i| i as usize)
                .ok_or_else(|| bad(path, format!("`{key}` holds {v}, expected scene indices")))
        })
        .collect()
}

fn relation_bits(v: &Value, path: &Path, what: &str) -> Result<u8> {
    let mut bits = 0;
    for r in Relation::BASE {
        match v.get(r.name()).and_then(Value::as_bool) {
            Some(true) => bits |= r.bit(),
            Some(false) => {}
            None => {
                return Err(bad(
                    path,
                    format!("{what} lacks the boolean `{}`", r.name()),
                ))
            }
        }
    }
    Ok(bits)
}

/// Reads the viewpoint object `{x, y, z, yaw}` of a scene file.
pub fn read_viewpoint(v: &Value, path: &Path) -> Result<Viewpoint> {
    let num = |k: &str| {
        v.get(k)
            .and_then(Value::as_f64)
            .ok_or_else(|| bad(path, format!("viewpoint lacks the number `{k}`")))
    };
    Ok(Viewpoint {
        position: [num("x")?, num("y")?, num("z")?],
        yaw_rad: num("yaw")?,
    })
}

/// The annotated box of a listed object (`centre`, `half_extents`, `yaw_rad`), `None` if
/// it has none; present but malformed fields are an error.
fn annotated_box(o: &Value, path: &Path) -> Result<Option<AnnotatedBox>> {
    let (Some(centre), Some(half), Some(yaw)) =
        (o.get("centre"), o.get("half_extents"), o.get("yaw_rad"))
    else {
        return Ok(None);
    };
    let triple = |v: &Value, what: &str| -> Result<[f64; 3]> {
        let a = v.as_array().filter(|a| a.len() == 3).ok_or_else(|| {
            bad(
                path,
                format!("object `{what}` is not an array of 3 numbers: {o}"),
            )
        })?;
        let mut out = [0.0; 3];
        for (k, x) in a.iter().enumerate() {
            out[k] = x
                .as_f64()
                .filter(|x| x.is_finite())
                .ok_or_else(|| bad(path, format!("object `{what}` has a non-number: {o}")))?;
        }
        Ok(out)
    };
    Ok(Some(AnnotatedBox {
        centre: triple(centre, "centre")?,
        half_extents: triple(half, "half_extents")?,
        yaw_rad: yaw
            .as_f64()
            .filter(|x| x.is_finite())
            .ok_or_else(|| bad(path, format!("object `yaw_rad` is not a number: {o}")))?,
    }))
}

/// Reads a dataset's map building outlines ([`geodata::simfiles::MapBuildings`]).
pub fn read_map_buildings(path: &Path) -> Result<MapOutlines> {
    let text = std::fs::read_to_string(path).map_err(io_err(path))?;
    let file: MapBuildings = serde_json::from_str(&text)
        .map_err(|e| bad(path, format!("not a map-buildings file: {e}")))?;
    if file.frame != "local" {
        return Err(bad(
            path,
            format!("frame is {:?}, expected \"local\"", file.frame),
        ));
    }
    if let Some(b) = file
        .buildings
        .iter()
        .find(|b| b.outer.iter().flatten().any(|v| !v.is_finite()))
    {
        return Err(bad(
            path,
            format!("building {} has a vertex that is not finite", b.osm_id),
        ));
    }
    Ok(MapOutlines::new(
        file.buildings.into_iter().map(|b| b.outer),
    ))
}

/// Loads one scene: reads its scan into a map and its labels; buildings standing in
/// `outlines` are completed from them.
pub fn load_scene(
    dir: &Path,
    index: usize,
    map_options: &MapOptions,
    objects: &ObjectOptions,
    outlines: &MapOutlines,
) -> Result<Scene> {
    let json_path = dir.join(format!("scene_{index:03}.json"));
    let ply_path = dir.join(format!("scene_{index:03}.ply"));
    let json = read_json(&json_path)?;
    let viewpoint = read_viewpoint(
        json.get("viewpoint")
            .ok_or_else(|| bad(&json_path, "missing `viewpoint`".into()))?,
        &json_path,
    )?;
    let cloud = geodata::cloud::read_cloud(&ply_path)?;
    if cloud.object.is_none() {
        return Err(SrtreeError::MissingColumn {
            what: "a relations scene",
            column: "object",
        });
    }
    let mut map = SrMap::new(map_options.clone())?;
    map.insert_cloud(&cloud, Some(viewpoint.position))?;
    let extracted = extract_objects(&map, objects);
    let listed_objects = json
        .get("objects")
        .and_then(Value::as_array)
        .ok_or_else(|| bad(&json_path, "missing array `objects`".into()))?;
    let listed: Vec<u32> = listed_objects
        .iter()
        .map(|o| {
            o.get("id")
                .and_then(Value::as_u64)
                .map(|v| v as u32)
                .ok_or_else(|| bad(&json_path, format!("object without an integer `id`: {o}")))
        })
        .collect::<Result<_>>()?;
    let boxes: Vec<Option<AnnotatedBox>> = listed_objects
        .iter()
        .map(|o| annotated_box(o, &json_path))
        .collect::<Result<_>>()?;
    let view: Vec<ViewObject> = extracted
        .par_iter()
        .filter(|o| listed.contains(&o.id))
        .map(|o| ViewObject::from_map_object_with_outlines(&map, o, &viewpoint, outlines))
        .collect();
    let position = |id: u32| view.iter().position(|o| o.id == id);
    let mut pairs = Vec::new();
    let mut missing_pairs = Vec::new();
    for p in json
        .get("pairs")
        .and_then(Value::as_array)
        .ok_or_else(|| bad(&json_path, "missing array `pairs`".into()))?
    {
        let id = |k: &str| {
            p.get(k)
                .and_then(Value::as_u64)
                .map(|v| v as u32)
                .ok_or_else(|| bad(&json_path, format!("pair without an integer `{k}`: {p}")))
        };
        let (a, b) = (id("a")?, id("b")?);
        let truth = relation_bits(
            p.get("truth").unwrap_or(&Value::Null),
            &json_path,
            "a pair's `truth`",
        )?;
        let annotated = relation_bits(
            p.get("annotated").unwrap_or(&Value::Null),
            &json_path,
            "a pair's `annotated`",
        )?;
        match (position(a), position(b)) {
            (Some(a), Some(b)) => pairs.push(LabelledPair {
                a,
                b,
                truth,
                annotated,
            }),
            _ => missing_pairs.push((a, b, truth)),
        }
    }
    let annotated_boxes = view
        .iter()
        .map(|o| {
            listed
                .iter()
                .position(|&id| id == o.id)
                .and_then(|i| boxes[i])
        })
        .collect();
    Ok(Scene {
        index,
        viewpoint,
        annotated_boxes,
        objects: view,
        pairs,
        missing_pairs,
    })
}

impl RelationsDataset {
    /// A cross-dataset split: a model trains on every scene of `train_dirs` (their own
    /// train/test split ignored) and is tested on **every** scene of `test_dir`, none of
    /// which it saw. A test folder among the training folders is an error.
    pub fn load_across(
        test_dir: &Path,
        train_dirs: &[PathBuf],
        map_options: &MapOptions,
        objects: &ObjectOptions,
    ) -> Result<CrossSplit> {
        let test_canonical = test_dir.canonicalize().map_err(io_err(test_dir))?;
        if let Some(p) = train_dirs
            .iter()
            .find(|p| p.canonicalize().ok().as_ref() == Some(&test_canonical))
        {
            return Err(SrtreeError::TestAmongTraining { path: p.clone() });
        }
        let mut test = RelationsDataset::load(test_dir, map_options, objects)?;
        let mut train = Vec::new();
        for p in train_dirs {
            train.extend(RelationsDataset::load(p, map_options, objects)?.train);
        }
        let own_train = std::mem::take(&mut test.train);
        test.test.splice(0..0, own_train);
        Ok(CrossSplit { test, train })
    }

    /// Loads every train and test scene of a dataset folder (scenes in parallel).
    pub fn load(
        dir: impl AsRef<Path>,
        map_options: &MapOptions,
        objects: &ObjectOptions,
    ) -> Result<RelationsDataset> {
        let dir = dir.as_ref();
        let meta_path = dir.join("dataset.json");
        let meta = read_json(&meta_path)?;
        if meta.get("kind").and_then(Value::as_str) != Some("relations") {
            return Err(bad(
                &meta_path,
                format!(
                    "kind is {}, expected \"relations\"",
                    meta.get("kind").unwrap_or(&Value::Null)
                ),
            ));
        }
        let outlines = match meta.get("map_buildings") {
            None => MapOutlines::default(),
            Some(v) => {
                let name = v.as_str().ok_or_else(|| {
                    bad(
                        &meta_path,
                        format!("`map_buildings` is not a file name: {v}"),
                    )
                })?;
                read_map_buildings(&dir.join(name))?
            }
        };
        let load = |ids: Vec<usize>| -> Result<Vec<Scene>> {
            ids.into_par_iter()
                .map(|i| load_scene(dir, i, map_options, objects, &outlines))
                .collect()
        };
        Ok(RelationsDataset {
            dir: dir.to_path_buf(),
            train: load(indices(&meta, "train", &meta_path)?)?,
            test: load(indices(&meta, "test", &meta_path)?)?,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    #[test]
    fn annotated_boxes_are_read_absent_or_rejected_with_the_file() {
        let path = Path::new("scene_007.json");
        let o = json!({"id": 3, "centre": [1.0, 2.0, 0.5], "half_extents": [2.0, 0.9, 0.7], "yaw_rad": 0.25});
        let b = annotated_box(&o, path).ok().flatten();
        assert_eq!(
            b,
            Some(AnnotatedBox {
                centre: [1.0, 2.0, 0.5],
                half_extents: [2.0, 0.9, 0.7],
                yaw_rad: 0.25
            })
        );
        assert_eq!(annotated_box(&json!({"id": 3}), path).ok(), Some(None));
        for bad in [
            json!({"id": 3, "centre": [1.0, 2.0], "half_extents": [2.0, 0.9, 0.7], "yaw_rad": 0.0}),
            json!({"id": 3, "centre": [1.0, "x", 0.5], "half_extents": [2.0, 0.9, 0.7], "yaw_rad": 0.0}),
            json!({"id": 3, "centre": [1.0, 2.0, 0.5], "half_extents": [2.0, 0.9, 0.7], "yaw_rad": "north"}),
        ] {
            let message = annotated_box(&bad, path)
                .err()
                .map(|e| e.to_string())
                .unwrap_or_default();
            assert!(message.contains("scene_007.json"), "{message}");
        }
    }

    #[test]
    fn map_buildings_are_read_or_rejected_with_the_file() {
        let dir = std::env::temp_dir().join(format!("srtree-map-buildings-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("map_buildings.json");
        let good = json!({"frame": "local", "buildings": [
            {"osm_id": 7, "outer": [[0.0, 0.0], [10.0, 0.0], [10.0, 5.0], [0.0, 5.0]]},
            {"osm_id": 8, "outer": [[0.0, 0.0], [1.0, 0.0]]}
        ]});
        std::fs::write(&path, good.to_string()).unwrap();
        let outlines = read_map_buildings(&path).unwrap();
        assert_eq!(outlines.len(), 1, "a two-vertex ring is no outline");
        for (text, want) in [
            (
                json!({"frame": "utm:32N", "buildings": []}).to_string(),
                "frame",
            ),
            (json!({"frame": "local"}).to_string(), "buildings"),
            (
                json!({"frame": "local", "buildings": [{"osm_id": 1, "outer": [[0.0, "x"]]}]})
                    .to_string(),
                "not a map-buildings file",
            ),
            (
                "{\"frame\": \"local\", \"buildings\": [".to_string(),
                "not a map-buildings file",
            ),
        ] {
            std::fs::write(&path, text).unwrap();
            let message = read_map_buildings(&path)
                .err()
                .map(|e| e.to_string())
                .unwrap_or_default();
            assert!(
                message.contains("map_buildings.json") && message.contains(want),
                "{message}"
            );
        }
        let missing = read_map_buildings(&dir.join("absent.json"))
            .err()
            .map(|e| e.to_string());
        assert!(missing.unwrap_or_default().contains("absent.json"));
        std::fs::remove_dir_all(&dir).ok();
    }
}
