//! Fuzz targets of every urbansem reader: one function per target, taking arbitrary bytes.
//!
//! Where it sits: beside the pipeline, not in it. Each function feeds its bytes to one reader
//! (or, for [`mln_infer`], to the whole parse → ground → solve path of `urbansem mln infer`)
//! and ignores whether the reader returns `Ok` or `Err`: a returned error is the reader
//! doing its job, a panic, a hang or an out-of-memory is a bug (issue 16). The same
//! functions are called by the cargo-fuzz targets in `fuzz/` and by the corpus replay test
//! `tests/replay.rs`, which runs every committed corpus and crash file through them.
//!
//! Readers that take only a path get the bytes as a file in a fresh temporary folder (under
//! `/dev/shm` when it exists, so no disk is touched); [`TARGETS`] lists every target by
//! the name of its corpus folder, and [`seeds`] builds the seed inputs from our own writers
//! and hand-written files.
//!
//! ```
//! // Any bytes are fine; the functions never return anything.
//! fuzzing::opb(b"* #variable= 2\nmin: +1 x1 -2 x1 x2 ;\n");
//! fuzzing::mln_program(b"Smokes(person)\n1.5 Smokes(x)\n");
//! ```

pub mod scale;
pub mod seeds;

use std::path::{Path, PathBuf};
use std::sync::OnceLock;

/// Separates the parts of a multi-part input (program, evidence and query of
/// [`mln_infer`]; the two JSON files of [`dataset_json`]).
pub const SEPARATOR: &[u8] = b"\n%%\n";

/// Largest number of groundings per formula that [`mln_infer`] lets the grounder enumerate:
/// a legitimate program over large domains is refused with `GroundError::TooLarge` instead
/// of grounding for minutes.
pub const MLN_INFER_MAX_GROUNDINGS: usize = 4096;

/// Largest number of ground atoms and factors [`mln_infer`] passes on to the solver.
pub const MLN_INFER_MAX_GROUND_SIZE: usize = 20_000;

/// A fuzz target: its name (the folder under `fuzz/corpus/`) and its function.
pub type Target = (&'static str, fn(&[u8]));

/// Every target, by corpus folder name.
pub const TARGETS: [Target; 14] = [
    ("opb", opb),
    ("mln_program", mln_program),
    ("mln_evidence", mln_evidence),
    ("mln_query", mln_query),
    ("mln_infer", mln_infer),
    ("osm_xml", osm_xml),
    ("osm_pbf", osm_pbf),
    ("ply", ply),
    ("pcd", pcd),
    ("las", las),
    ("kitti_bin", kitti_bin),
    ("srt", srt),
    ("streets_model", streets_model),
    ("dataset_json", dataset_json),
];

/// Splits `data` at the first `parts - 1` occurrences of [`SEPARATOR`]; missing parts are empty.
pub fn split_parts(data: &[u8], parts: usize) -> Vec<&[u8]> {
    let mut out = Vec::with_capacity(parts);
    let mut rest = data;
    while out.len() + 1 < parts {
        match rest.windows(SEPARATOR.len()).position(|w| w == SEPARATOR) {
            Some(i) => {
                out.push(&rest[..i]);
                rest = &rest[i + SEPARATOR.len()..];
            }
            None => {
                out.push(rest);
                rest = &[];
            }
        }
    }
    out.push(rest);
    out
}

/// A fresh temporary folder, in memory (`/dev/shm`) where the system has one.
fn temp_dir() -> Option<tempfile::TempDir> {
    let builder = {
        let mut b = tempfile::Builder::new();
        b.prefix("urbansem-fuzz-");
        b
    };
    let shm = Path::new("/dev/shm");
    if shm.is_dir() {
        if let Ok(dir) = builder.tempdir_in(shm) {
            return Some(dir);
        }
    }
    builder.tempdir().ok()
}

/// Writes `data` to `dir/name` and returns the path (`None` if the write failed).
fn write_file(dir: &Path, name: &str, data: &[u8]) -> Option<PathBuf> {
    let path = dir.join(name);
    std::fs::write(&path, data).ok().map(|()| path)
}

/// Runs `read` on `data` written to a file called `name` in a fresh temporary folder.
fn with_file(name: &str, data: &[u8], read: impl FnOnce(&Path)) {
    let Some(dir) = temp_dir() else { return };
    if let Some(path) = write_file(dir.path(), name, data) {
        read(&path);
    }
}

/// `pbo::opb::parse_opb` on the bytes, when they are UTF-8 (other inputs are skipped).
pub fn opb(data: &[u8]) {
    if let Ok(text) = std::str::from_utf8(data) {
        let _ = pbo::opb::parse_opb(text, "fuzz.opb");
    }
}

/// `mln::parse::parse_program` on the bytes (lossy UTF-8).
pub fn mln_program(data: &[u8]) {
    let text = String::from_utf8_lossy(data);
    let _ = mln::parse::parse_program(&text, "fuzz.mln");
}

/// The program that [`mln_evidence`] and [`mln_query`] read their atoms against: types with
/// listed and integer-range domains, closed (`*`) and open predicates, arities 1 to 3.
pub const FIXED_PROGRAM: &str = "\
person = { Anna, Bob, \"Carl Jr\" }
num = { 1, ..., 5 }
*Friends(person, person)
*Age(person, num)
Smokes(person)
Cancer(person)
Knows(person, person, num)
Rains(num)
1.5 Smokes(x) => Cancer(x)
1.1 Smokes(x) ^ Friends(x, y) => Smokes(y)
Friends(x, y) => Friends(y, x).
-0.5 Age(x, n) ^ Knows(x, y, n) => Rains(n)
";

fn fixed_program() -> Option<&'static mln::parse::Program> {
    static PROGRAM: OnceLock<Option<mln::parse::Program>> = OnceLock::new();
    PROGRAM
        .get_or_init(|| mln::parse::parse_program(FIXED_PROGRAM, "fixed.mln").ok())
        .as_ref()
}

/// `mln::parse::parse_evidence` on the bytes (lossy UTF-8), against [`FIXED_PROGRAM`].
pub fn mln_evidence(data: &[u8]) {
    let Some(program) = fixed_program() else {
        return;
    };
    let text = String::from_utf8_lossy(data);
    let _ = mln::parse::parse_evidence(&text, "fuzz.db", program);
}

/// `mln::parse::parse_query` and `parse_query_predicates` on the bytes (lossy UTF-8),
/// against [`FIXED_PROGRAM`].
pub fn mln_query(data: &[u8]) {
    let Some(program) = fixed_program() else {
        return;
    };
    let text = String::from_utf8_lossy(data);
    let _ = mln::parse::parse_query(&text, "fuzz.query", program);
    let _ = mln::parse::parse_query_predicates(&text, program);
}

/// The whole path of `urbansem mln infer` on tiny inputs: the bytes are split at
/// [`SEPARATOR`] into program, evidence and query (a query part without `(` is read as the
/// `-q` predicate list), then parsed, grounded with at most [`MLN_INFER_MAX_GROUNDINGS`]
/// groundings per formula, exported as WCNF and solved with the default method.
pub fn mln_infer(data: &[u8]) {
    let parts = split_parts(data, 3);
    let [program, evidence, query] = [0, 1, 2].map(|k| String::from_utf8_lossy(parts[k]));
    let Ok(program) = mln::parse::parse_program(&program, "fuzz.mln") else {
        return;
    };
    let Ok(evidence) = mln::parse::parse_evidence(&evidence, "fuzz.db", &program) else {
        return;
    };
    let query = if query.contains('(') {
        mln::parse::parse_query(&query, "fuzz.query", &program)
    } else {
        mln::parse::parse_query_predicates(query.trim(), &program)
    };
    let Ok(query) = query else { return };
    let Ok(program) = mln::ground::expand_per_constant(program, &evidence, &query) else {
        return;
    };
    let options = mln::ground::GroundOptions {
        max_groundings: MLN_INFER_MAX_GROUNDINGS,
        lazy: true,
    };
    let Ok(problem) = mln::ground::ground(&program, &evidence, "fuzz.db", &query, &options) else {
        return;
    };
    if problem.atoms.len() > MLN_INFER_MAX_GROUND_SIZE
        || problem.factors.len() > MLN_INFER_MAX_GROUND_SIZE
    {
        return;
    }
    let _ = mln::wcnf::write_wcnf(&problem, 1e6, &mut std::io::sink());
    let result = mln::infer::map_inference(&problem, &mln::infer::InferOptions::default());
    for i in 0..problem.atoms.len().min(8) {
        let _ = problem.atom_name(&program, i);
    }
    let _ = result.scores;
}

/// `OsmMap::from_xml_reader` on the bytes, and `OsmMap::from_xml_str` when they are UTF-8.
pub fn osm_xml(data: &[u8]) {
    let _ = geodata::osm::OsmMap::from_xml_reader(data, "fuzz.osm", None);
    if let Ok(text) = std::str::from_utf8(data) {
        let _ = geodata::osm::OsmMap::from_xml_str(text);
    }
}

/// `OsmMap::load` on the bytes as a `.osm.pbf` file.
pub fn osm_pbf(data: &[u8]) {
    with_file("fuzz.osm.pbf", data, |path| {
        let _ = geodata::osm::OsmMap::load(path);
    });
}

/// Reads the bytes as a point cloud of the format named by `name`'s extension, failing on
/// non-finite positions and then dropping them.
fn cloud(name: &str, data: &[u8]) {
    with_file(name, data, |path| {
        let mut options = geodata::cloud::ReadOptions::default();
        if geodata::cloud::read_cloud_with(path, &options).is_err() {
            options.drop_non_finite = true;
            let _ = geodata::cloud::read_cloud_with(path, &options);
        }
    });
}

/// The PLY reader on the bytes as a `.ply` file.
pub fn ply(data: &[u8]) {
    cloud("fuzz.ply", data);
}

/// The PCD reader on the bytes as a `.pcd` file.
pub fn pcd(data: &[u8]) {
    cloud("fuzz.pcd", data);
}

/// The LAS/LAZ reader on the bytes as a `.las` file (the header says whether it is LAZ).
pub fn las(data: &[u8]) {
    cloud("fuzz.las", data);
}

/// The KITTI Velodyne reader on the bytes as a `.bin` file, then as a label file.
pub fn kitti_bin(data: &[u8]) {
    cloud("fuzz.bin", data);
    with_file("fuzz.label", data, |path| {
        let _ = geodata::cloud::kitti::read_label_file(path, None);
        let _ = geodata::cloud::kitti::read_label_file(path, Some(data.len() / 4));
    });
}

/// `srtree::io::decode_map` on the bytes as they are, then with their last 8 bytes replaced
/// by the right checksum, so the fuzzer gets past the checksum to the fields.
pub fn srt(data: &[u8]) {
    let path = Path::new("fuzz.srt");
    let _ = srtree::io::decode_map(data, path);
    if let Some(body) = data.len().checked_sub(8) {
        let mut bytes = data.to_vec();
        let sum = srtree::io::checksum(&bytes[..body]);
        bytes[body..].copy_from_slice(&sum.to_le_bytes());
        let _ = srtree::io::decode_map(&bytes, path);
    }
}

/// The map and cloud [`streets_model`] runs a decoded model on: two streets meeting at a
/// corner, with a synthetic labelled ground cloud around them.
fn streets_fixture() -> Option<&'static (geodata::osm::OsmMap, geodata::cloud::PointCloud)> {
    static FIXTURE: OnceLock<Option<(geodata::osm::OsmMap, geodata::cloud::PointCloud)>> =
        OnceLock::new();
    FIXTURE
        .get_or_init(|| {
            let map = geodata::osm::OsmMap::from_xml_str(seeds::STREETS_MAP_XML).ok()?;
            let truth = seeds::streets_truth(&map);
            let cloud = streets::synthetic::ground_cloud(&map, &truth, 0.5, 12.0, 1);
            Some((map, cloud))
        })
        .as_ref()
}

/// `streets::model::StreetModel::from_json` on the bytes; a model it accepts then estimates
/// the streets of a small fixed map and cloud, as `urbansem streets estimate` does.
pub fn streets_model(data: &[u8]) {
    let Ok(model) = streets::model::StreetModel::from_json(data, Path::new("fuzz.json")) else {
        return;
    };
    if let Some((map, cloud)) = streets_fixture() {
        let _ = model.estimate(map, cloud, "fixture.osm", "fixture.ply");
    }
}

/// The simulated-dataset readers (`localize::eval::SimDataset::open`,
/// `streets::dataset::StreetsDataset::load`, `srtree::dataset::RelationsDataset::load`) on
/// a folder whose `dataset.json` is the first part of the bytes and whose `truth.json`,
/// `segments.json` and `scene_000.json` are the second; the folder also holds a small map
/// (`map.osm`) and labelled clouds (`cloud.ply`, `scene_000.ply`) written by our writers.
pub fn dataset_json(data: &[u8]) {
    let parts = split_parts(data, 2);
    let Some(fixture) = seeds::dataset_fixture() else {
        return;
    };
    let Some(dir) = temp_dir() else { return };
    let d = dir.path();
    let written = [
        ("dataset.json", parts[0]),
        ("truth.json", parts[1]),
        ("segments.json", parts[1]),
        ("scene_000.json", parts[1]),
        ("map.osm", fixture.map_osm.as_slice()),
        ("cloud.ply", fixture.streets_ply.as_slice()),
        ("scene_000.ply", fixture.scene_ply.as_slice()),
    ]
    .iter()
    .all(|(name, bytes)| write_file(d, name, bytes).is_some());
    if !written {
        return;
    }
    if let Ok(ds) = localize::eval::SimDataset::open(d) {
        let _ = ds.load(0);
    }
    let _ = streets::dataset::StreetsDataset::load(d);
    let _ = srtree::dataset::RelationsDataset::load(
        d,
        &srtree::map::MapOptions::default(),
        &srtree::objects::ObjectOptions::default(),
    );
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parts_split_at_the_separator_and_missing_parts_are_empty() {
        assert_eq!(
            split_parts(b"a\n%%\nb\n%%\nc\n%%\nd", 3),
            vec![&b"a"[..], b"b", b"c\n%%\nd"]
        );
        assert_eq!(split_parts(b"abc", 3), vec![&b"abc"[..], b"", b""]);
        assert_eq!(split_parts(b"", 1), vec![&b""[..]]);
    }

    #[test]
    fn the_fixed_program_parses() {
        let program = fixed_program().map(|p| p.predicates.len());
        assert_eq!(program, Some(6));
    }

    #[test]
    fn the_streets_fixture_has_streets_and_labelled_points() {
        let (map, cloud) = streets_fixture()
            .map(|(m, c)| (m.streets.segments.len(), c.len()))
            .unwrap_or_default();
        assert!(map >= 2 && cloud > 100, "{map} segments, {cloud} points");
    }
}
