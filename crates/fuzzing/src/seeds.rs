//! Seed inputs of every target, built by our own writers or written by hand (nothing is
//! copied from `../shared/data`): `cargo run -p fuzzing --example write_seeds` writes them to
//! `fuzz/corpus/<target>/seed-<name>` before the corpus is minimised.

use geodata::classes::Class;
use geodata::cloud::{Columns, Encoding, PointCloud, PointRecord, Precision};
use std::path::Path;
use std::sync::OnceLock;

/// One seed: its target, a short name and its bytes.
#[derive(Debug, Clone)]
pub struct Seed {
    /// Target (corpus folder) name.
    pub target: &'static str,
    /// File name without the `seed-` prefix.
    pub name: String,
    /// The input.
    pub bytes: Vec<u8>,
}

fn seed(target: &'static str, name: &str, bytes: impl Into<Vec<u8>>) -> Seed {
    Seed {
        target,
        name: name.to_owned(),
        bytes: bytes.into(),
    }
}

/// A small OSM map: two drivable streets meeting at a corner, a footway, a building way
/// and a multipolygon building with a courtyard.
pub const STREETS_MAP_XML: &str = r#"<?xml version="1.0" encoding="UTF-8"?>
<osm version="0.6" generator="urbansem fuzz seeds">
  <bounds minlat="59.3490" minlon="18.0700" maxlat="59.3510" maxlon="18.0740"/>
  <node id="1" lat="59.3500" lon="18.0700"/>
  <node id="2" lat="59.3500" lon="18.0720"/>
  <node id="3" lat="59.3510" lon="18.0720"/>
  <node id="4" lat="59.3490" lon="18.0740"/>
  <node id="10" lat="59.3502" lon="18.0703"/>
  <node id="11" lat="59.3502" lon="18.0706"/>
  <node id="12" lat="59.3504" lon="18.0706"/>
  <node id="13" lat="59.3504" lon="18.0703"/>
  <node id="20" lat="59.3492" lon="18.0703"/>
  <node id="21" lat="59.3492" lon="18.0710"/>
  <node id="22" lat="59.3496" lon="18.0710"/>
  <node id="23" lat="59.3496" lon="18.0703"/>
  <node id="24" lat="59.3493" lon="18.0705"/>
  <node id="25" lat="59.3493" lon="18.0707"/>
  <node id="26" lat="59.3495" lon="18.0707"/>
  <node id="27" lat="59.3495" lon="18.0705"/>
  <way id="100">
    <nd ref="1"/><nd ref="2"/><nd ref="3"/>
    <tag k="highway" v="residential"/><tag k="name" v="A &amp; B &lt;street&gt;"/>
  </way>
  <way id="101">
    <nd ref="2"/><nd ref="4"/>
    <tag k="highway" v="primary"/>
  </way>
  <way id="102">
    <nd ref="1"/><nd ref="4"/>
    <tag k="highway" v="footway"/>
  </way>
  <way id="200">
    <nd ref="10"/><nd ref="11"/><nd ref="12"/><nd ref="13"/><nd ref="10"/>
    <tag k="building" v="yes"/><tag k="building:levels" v="3"/>
  </way>
  <way id="201"><nd ref="20"/><nd ref="21"/><nd ref="22"/><nd ref="23"/><nd ref="20"/></way>
  <way id="202"><nd ref="24"/><nd ref="25"/><nd ref="26"/><nd ref="27"/><nd ref="24"/></way>
  <relation id="300">
    <member type="way" ref="201" role="outer"/>
    <member type="way" ref="202" role="inner"/>
    <tag k="type" v="multipolygon"/><tag k="building" v="yes"/>
  </relation>
</osm>
"#;

/// Ground truth of every segment of `map`: centred, 7 m wide, 2 m sidewalks, observed.
pub fn streets_truth(map: &geodata::osm::OsmMap) -> Vec<streets::dataset::SegmentTruth> {
    map.streets
        .segments
        .iter()
        .enumerate()
        .map(|(i, s)| streets::dataset::SegmentTruth {
            segment: i,
            offset_m: 0.0,
            width_m: 7.0,
            sidewalk_m: 2.0,
            outer_offset_m: None,
            outer_observed: true,
            drivable: geodata::osm::tags::is_drivable(&s.highway),
            observed: true,
            points: 0,
        })
        .collect()
}

/// A few points with every optional column, one of them far away.
pub fn small_cloud(columns: Columns, precision: Precision) -> PointCloud {
    let mut cloud = PointCloud::with_columns(columns, precision, 6);
    for k in 0..6u8 {
        let f = f64::from(k);
        cloud.push(&PointRecord {
            position: [f * 0.5 - 1.0, 2.0 - f * 0.25, 0.1 * f],
            intensity: 0.1 * f32::from(k),
            rgb: [k * 40, 255 - k * 30, 7 * k],
            label: Class::ALL[usize::from(k) % Class::COUNT].id(),
            raw_label: 40 + u32::from(k),
            object: u32::from(k / 2),
        });
    }
    cloud
}

/// Every column on.
pub const ALL_COLUMNS: Columns = Columns {
    intensity: true,
    rgb: true,
    label: true,
    raw_label: true,
    object: true,
};

/// Bytes our writer produces for `cloud` as `name` (extension picks the format).
fn written_cloud(name: &str, cloud: &PointCloud, encoding: Encoding) -> Option<Vec<u8>> {
    let dir = tempfile::tempdir().ok()?;
    let path = dir.path().join(name);
    geodata::cloud::write_cloud_with(&path, cloud, &geodata::cloud::WriteOptions { encoding })
        .ok()?;
    std::fs::read(&path).ok()
}

/// The fixed files of the [`crate::dataset_json`] folder.
#[derive(Debug, Clone)]
pub struct DatasetFixture {
    /// `map.osm`: [`STREETS_MAP_XML`].
    pub map_osm: Vec<u8>,
    /// `cloud.ply`: a labelled ground cloud around the streets.
    pub streets_ply: Vec<u8>,
    /// `scene_000.ply`: two labelled objects (ids 1 and 2) on a ground patch.
    pub scene_ply: Vec<u8>,
}

/// A relations scene: a car (object 1) beside a pole (object 2) on a street patch (object 0).
fn scene_cloud() -> PointCloud {
    let columns = Columns {
        label: true,
        object: true,
        ..Columns::default()
    };
    let mut cloud = PointCloud::with_columns(columns, Precision::F32, 0);
    let mut push = |p: [f64; 3], class: Class, object: u32| {
        cloud.push(&PointRecord {
            position: p,
            label: class.id(),
            object,
            ..PointRecord::default()
        });
    };
    for i in 0..20 {
        for j in 0..20 {
            push(
                [f64::from(i) * 0.2, f64::from(j) * 0.2, 0.0],
                Class::Street,
                0,
            );
        }
    }
    for i in 0..8 {
        for j in 0..4 {
            for k in 1..5 {
                let p = [
                    1.0 + f64::from(i) * 0.2,
                    1.0 + f64::from(j) * 0.2,
                    f64::from(k) * 0.2,
                ];
                push(p, Class::Car, 1);
            }
        }
    }
    for k in 1..12 {
        push([3.0, 3.0, f64::from(k) * 0.2], Class::Pole, 2);
        push([3.1, 3.0, f64::from(k) * 0.2], Class::Pole, 2);
    }
    cloud
}

/// The fixed files of the dataset target, built once.
pub fn dataset_fixture() -> Option<&'static DatasetFixture> {
    static FIXTURE: OnceLock<Option<DatasetFixture>> = OnceLock::new();
    FIXTURE
        .get_or_init(|| {
            let map = geodata::osm::OsmMap::from_xml_str(STREETS_MAP_XML).ok()?;
            let truth = streets_truth(&map);
            let ground = streets::synthetic::ground_cloud(&map, &truth, 1.0, 10.0, 1);
            Some(DatasetFixture {
                map_osm: STREETS_MAP_XML.as_bytes().to_vec(),
                streets_ply: written_cloud("cloud.ply", &ground, Encoding::BinaryLittleEndian)?,
                scene_ply: written_cloud(
                    "scene.ply",
                    &scene_cloud(),
                    Encoding::BinaryLittleEndian,
                )?,
            })
        })
        .as_ref()
}

fn join_parts(parts: &[&str]) -> Vec<u8> {
    parts
        .join(std::str::from_utf8(crate::SEPARATOR).unwrap_or("\n%%\n"))
        .into_bytes()
}

fn opb_seeds(out: &mut Vec<Seed>) {
    let grid = pbo::instances::denoising_grid(3, 3, 1);
    let poly = grid.to_polynomial();
    let problem = pbo::opb::OpbProblem {
        names: (1..=poly.num_vars()).map(|i| format!("x{i}")).collect(),
        poly,
        sense: pbo::opb::Sense::Minimize,
        declared: None,
    };
    out.push(seed("opb", "denoising-3x3", pbo::opb::write_opb(&problem)));
    out.push(seed(
        "opb",
        "cubic-max",
        "* #variable= 4 #constraint= 0\n* a comment\nmax: +3 x1 x2 x3 -2 ~x2 x4 +1.5 x4 -7 ;\n",
    ));
    out.push(seed(
        "opb",
        "min-names",
        "min: 2 a +3 b_1 -1 a b_1 +0 c ;\n",
    ));
}

fn mln_seeds(out: &mut Vec<Seed>) {
    let fs = mln::generate::friends_smokers(
        &mln::generate::FriendsSmokersOptions {
            persons: 4,
            friends_per_person: 2,
            known_share: 0.5,
            ..Default::default()
        },
        1,
    );
    let id = mln::generate::image_denoising(3, 1);
    let rich = "\
// types, ranges, quoted constants, closed predicates
person = { Anna, Bob, \"Carl Jr\" }
num = { 1, ..., 3 }
*Friends(person, person)
*Age(person, num)
Smokes(person)
Cancer(person)
Likes(person, person)
/* a block
   comment */
1.5 Smokes(x) => Cancer(x)
-0.7 Smokes(x) ^ Friends(x, y) => Smokes(y)
2 Friends(x, y) <=> Friends(y, x)
0.5 EXIST y Likes(x, y) v !Smokes(x)
1 FORALL y Friends(x, y) => Likes(x, y)
@1.2 Age(x, 2) ^ x != y ^ Age(y, 2) => Likes(x, y)
Smokes(Anna) v Cancer(Bob).
Likes(x, x)
";
    let rich_evidence =
        "Friends(Anna, Bob)\n!Friends(Bob, \"Carl Jr\")\nAge(Anna, 2)\nAge(Bob, 3)\n// c\n";
    out.push(seed("mln_program", "fs", fs.program.clone()));
    out.push(seed("mln_program", "id", id.program.clone()));
    out.push(seed("mln_program", "rich", rich));
    out.push(seed("mln_program", "fixed", crate::FIXED_PROGRAM));
    out.push(seed(
        "mln_evidence",
        "fixed",
        "Friends(Anna, Bob)\n!Friends(Bob, \"Carl Jr\")\nAge(Anna, 3)\nKnows(Anna, Bob, 5)\nRains(2)\n!Smokes(Bob)\n",
    ));
    out.push(seed(
        "mln_evidence",
        "comments",
        "// only a comment\n\nCancer(Anna)\r\n",
    ));
    out.push(seed(
        "mln_query",
        "fixed",
        "Smokes(x)\nCancer(Anna)\nKnows(x, Bob, n)\nRains(n)\n",
    ));
    out.push(seed("mln_query", "list", "Smokes,Cancer, Rains"));
    out.push(seed(
        "mln_infer",
        "fs",
        join_parts(&[&fs.program, &fs.evidence, &fs.query]),
    ));
    out.push(seed(
        "mln_infer",
        "id",
        join_parts(&[&id.program, &id.evidence, "On"]),
    ));
    out.push(seed(
        "mln_infer",
        "rich",
        join_parts(&[rich, rich_evidence, "Smokes(x)\nCancer(Bob)\nLikes(x, y)\n"]),
    ));
}

/// A protobuf writer just big enough for OSM PBF seeds.
#[derive(Default)]
struct Proto(Vec<u8>);

impl Proto {
    fn varint(&mut self, mut v: u64) {
        while v >= 0x80 {
            self.0.push((v as u8) | 0x80);
            v >>= 7;
        }
        self.0.push(v as u8);
    }
    fn key(&mut self, field: u32, wire: u8) {
        self.varint(u64::from(field) << 3 | u64::from(wire));
    }
    fn uint(&mut self, field: u32, v: u64) -> &mut Self {
        self.key(field, 0);
        self.varint(v);
        self
    }
    fn sint(&mut self, field: u32, v: i64) -> &mut Self {
        self.uint(field, ((v << 1) ^ (v >> 63)) as u64)
    }
    fn bytes(&mut self, field: u32, b: &[u8]) -> &mut Self {
        self.key(field, 2);
        self.varint(b.len() as u64);
        self.0.extend_from_slice(b);
        self
    }
    fn packed_sint_delta(&mut self, field: u32, values: &[i64]) -> &mut Self {
        let mut p = Proto::default();
        let mut last = 0;
        for &v in values {
            let d = v - last;
            last = v;
            p.varint(((d << 1) ^ (d >> 63)) as u64);
        }
        self.bytes(field, &p.0)
    }
    fn packed_uint(&mut self, field: u32, values: &[u64]) -> &mut Self {
        let mut p = Proto::default();
        for &v in values {
            p.varint(v);
        }
        self.bytes(field, &p.0)
    }
}

/// One file block: the blob header and a raw (or zlib) blob around `payload`.
fn pbf_block(kind: &str, payload: &[u8], zlib: bool) -> Vec<u8> {
    let mut blob = Proto::default();
    if zlib {
        use std::io::Write;
        let mut e = flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::fast());
        let compressed = e
            .write_all(payload)
            .ok()
            .and_then(|()| e.finish().ok())
            .unwrap_or_default();
        blob.uint(2, payload.len() as u64).bytes(3, &compressed);
    } else {
        blob.bytes(1, payload);
    }
    let mut header = Proto::default();
    header
        .bytes(1, kind.as_bytes())
        .uint(3, blob.0.len() as u64);
    let mut out = (header.0.len() as u32).to_be_bytes().to_vec();
    out.extend_from_slice(&header.0);
    out.extend_from_slice(&blob.0);
    out
}

/// A tiny `.osm.pbf`: header block, dense nodes, a highway way and a building way, a
/// multipolygon relation.
pub fn tiny_pbf(zlib: bool) -> Vec<u8> {
    let mut bbox = Proto::default();
    bbox.sint(1, 18_070_000_000)
        .sint(2, 18_074_000_000)
        .sint(3, 59_351_000_000)
        .sint(4, 59_349_000_000);
    let mut header = Proto::default();
    header
        .bytes(1, &bbox.0)
        .bytes(4, b"OsmSchema-V0.6")
        .bytes(4, b"DenseNodes")
        .bytes(16, b"urbansem seeds");
    let strings: [&[u8]; 8] = [
        b"",
        b"highway",
        b"residential",
        b"building",
        b"yes",
        b"type",
        b"multipolygon",
        b"outer",
    ];
    let mut table = Proto::default();
    for s in strings {
        table.bytes(1, s);
    }
    // Coordinates in units of 100 nanodegrees (granularity 100).
    let lat = |d: f64| (d * 1e7).round() as i64;
    let nodes: [(i64, f64, f64); 7] = [
        (1, 59.3500, 18.0700),
        (2, 59.3500, 18.0720),
        (3, 59.3510, 18.0720),
        (10, 59.3502, 18.0703),
        (11, 59.3502, 18.0706),
        (12, 59.3504, 18.0706),
        (13, 59.3504, 18.0703),
    ];
    let mut dense = Proto::default();
    dense
        .packed_sint_delta(1, &nodes.map(|n| n.0))
        .packed_sint_delta(8, &nodes.map(|n| lat(n.1)))
        .packed_sint_delta(9, &nodes.map(|n| lat(n.2)))
        .packed_uint(10, &[0, 0, 0, 0, 0, 0, 0]);
    let mut highway = Proto::default();
    highway
        .uint(1, 100)
        .packed_uint(2, &[1])
        .packed_uint(3, &[2])
        .packed_sint_delta(8, &[1, 2, 3]);
    let mut building = Proto::default();
    building
        .uint(1, 200)
        .packed_uint(2, &[3])
        .packed_uint(3, &[4])
        .packed_sint_delta(8, &[10, 11, 12, 13, 10]);
    let mut ring = Proto::default();
    ring.uint(1, 201)
        .packed_sint_delta(8, &[10, 11, 12, 13, 10]);
    let mut relation = Proto::default();
    relation
        .uint(1, 300)
        .packed_uint(2, &[5, 3])
        .packed_uint(3, &[6, 4])
        .packed_uint(8, &[7])
        .packed_sint_delta(9, &[201])
        .packed_uint(10, &[1]);
    let mut group = Proto::default();
    group.bytes(2, &dense.0);
    let mut ways = Proto::default();
    ways.bytes(3, &highway.0)
        .bytes(3, &building.0)
        .bytes(3, &ring.0)
        .bytes(4, &relation.0);
    let mut block = Proto::default();
    block
        .bytes(1, &table.0)
        .bytes(2, &group.0)
        .bytes(2, &ways.0)
        .uint(17, 100);
    let mut out = pbf_block("OSMHeader", &header.0, zlib);
    out.extend(pbf_block("OSMData", &block.0, zlib));
    out
}

fn osm_seeds(out: &mut Vec<Seed>) {
    out.push(seed("osm_xml", "streets", STREETS_MAP_XML));
    let options = geosim::city::CityOptions {
        size_m: 260.0,
        block_m: 120.0,
        ..geosim::city::CityOptions::default()
    };
    if let Ok(city) = geosim::city::generate_city(&options, 3) {
        out.push(seed("osm_xml", "city", city));
    }
    out.push(seed("osm_pbf", "tiny-raw", tiny_pbf(false)));
    out.push(seed("osm_pbf", "tiny-zlib", tiny_pbf(true)));
}

fn cloud_seeds(out: &mut Vec<Seed>) {
    let full = small_cloud(ALL_COLUMNS, Precision::F32);
    let full64 = small_cloud(ALL_COLUMNS, Precision::F64);
    let bare = small_cloud(Columns::default(), Precision::F32);
    let encodings = [
        ("ascii", Encoding::Ascii),
        ("binary", Encoding::BinaryLittleEndian),
        ("be", Encoding::BinaryBigEndian),
        ("compressed", Encoding::BinaryCompressed),
    ];
    for (target, ext, kinds) in [
        ("ply", "ply", &encodings[..3]),
        (
            "pcd",
            "pcd",
            &[encodings[0], encodings[1], encodings[3]][..],
        ),
        ("las", "las", &encodings[1..2]),
        ("las", "laz", &encodings[1..2]),
        ("kitti_bin", "bin", &encodings[1..2]),
    ] {
        for (name, encoding) in kinds {
            for (cname, cloud) in [("full", &full), ("f64", &full64), ("bare", &bare)] {
                if let Some(bytes) = written_cloud(&format!("seed.{ext}"), cloud, *encoding) {
                    out.push(seed(target, &format!("{ext}-{name}-{cname}"), bytes));
                }
            }
        }
    }
    out.push(seed(
        "ply",
        "hand-ascii-faces",
        "ply\nformat ascii 1.0\ncomment hand written\nelement vertex 3\nproperty double x\nproperty double y\nproperty double z\nproperty uchar red\nproperty uchar green\nproperty uchar blue\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0 1 2 3\n1 1 1 4 5 6\n2 0 1 7 8 9\n3 0 1 2\n",
    ));
    out.push(seed(
        "pcd",
        "hand-ascii-organized",
        "# .PCD v0.7\nVERSION 0.7\nFIELDS x y z rgb\nSIZE 4 4 4 4\nTYPE F F F F\nCOUNT 1 1 1 1\nWIDTH 2\nHEIGHT 2\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS 4\nDATA ascii\n1 2 3 4.2108e+06\n4 5 6 4.2108e+06\nnan nan nan 0\n7 8 9 0",
    ));
}

fn srt_seeds(out: &mut Vec<Seed>) {
    use srtree::map::{MapOptions, SrMap};
    let cloud = small_cloud(ALL_COLUMNS, Precision::F32);
    let mut scene = scene_cloud();
    scene.rgb = Some(vec![[10, 20, 30]; scene.len()]);
    for (name, cloud, ray_casting) in [("small", &cloud, false), ("scene", &scene, true)] {
        let Ok(mut map) = SrMap::new(MapOptions {
            resolution_m: 0.2,
            ray_casting,
            ..MapOptions::default()
        }) else {
            continue;
        };
        if map.insert_cloud(cloud, Some([0.0, 0.0, 1.5])).is_err() {
            continue;
        }
        let mut map = srtree::semantic::SemanticMap::new(map);
        map.relations.edges.push(srtree::graph::RelationEdge {
            a: 1,
            b: 2,
            bits: srtree::graph::Relation::On.bit(),
        });
        out.push(seed("srt", name, srtree::io::encode_map(&map)));
    }
}

/// A small trained street model (SVM on the fixture's bins) as `urbansem streets train`
/// writes it.
fn street_model_json() -> Option<Vec<u8>> {
    use streets::model::{segment_bins, BinClassifier, ClassifierOptions, GeometryOptions};
    let map = geodata::osm::OsmMap::from_xml_str(STREETS_MAP_XML).ok()?;
    let truth = streets_truth(&map);
    let cloud = streets::synthetic::ground_cloud(&map, &truth, 0.5, 12.0, 1);
    let geometry = GeometryOptions::default();
    let which: Vec<usize> = (0..truth.len()).filter(|&s| truth[s].drivable).collect();
    let (mut x, mut y, mut geoms) = (Vec::new(), Vec::new(), Vec::new());
    for (&s, b) in which
        .iter()
        .zip(&segment_bins(&map, &cloud, &which, &geometry))
    {
        let Some(b) = b else { continue };
        geoms.push((truth[s].offset_m, truth[s].width_m));
        for k in b.usable() {
            if let Some(c) = b.features.truth[k] {
                x.extend_from_slice(b.features.row(k));
                y.push(streets::model::Target::DrivingArea.positive(c));
            }
        }
    }
    let classifier = BinClassifier::train(
        &x,
        &y,
        &ClassifierOptions {
            max_train_bins: 24,
            calibration_bins: 24,
            ..ClassifierOptions::default()
        },
    )
    .ok()?;
    let model = streets::model::StreetModel {
        target: streets::model::Target::DrivingArea,
        geometry,
        classifier,
        prior: streets::potentials::GeometryPrior::fit(&geoms),
        sidewalk_prior: None,
        tag_prior: Some(streets::prior::TagPrior::fit(
            &geoms
                .iter()
                .map(|&g| {
                    let tags = streets::prior::SegmentTags {
                        class: "residential".into(),
                        width_m: None,
                        lanes: Some(2),
                        no_sidewalk: false,
                        mapped_sidewalk_m: None,
                    };
                    (tags, g)
                })
                .collect::<Vec<_>>(),
            false,
        )),
    };
    serde_json::to_vec(&model).ok()
}

fn streets_seeds(out: &mut Vec<Seed>) {
    if let Some(model) = street_model_json() {
        out.push(seed("streets_model", "trained", model));
    }
}

fn dataset_seeds(out: &mut Vec<Seed>) {
    let map = geodata::osm::OsmMap::from_xml_str(STREETS_MAP_XML).ok();
    let truth = map.as_ref().map(streets_truth).unwrap_or_default();
    let segments = serde_json::to_string_pretty(&truth).unwrap_or_default();
    out.push(seed(
        "dataset_json",
        "streets",
        join_parts(&[
            r#"{"kind": "streets", "map": "map.osm", "route_m": 120.5}"#,
            &segments,
        ]),
    ));
    out.push(seed(
        "dataset_json",
        "localization",
        join_parts(&[
            r#"{"kind": "localization", "map": "map.osm", "seed": 1}"#,
            r#"{"cloud.ply": {"x": 1.5, "y": -2.0, "yaw": 0.3}, "scan_001.ply": {"x": 0, "y": 0, "yaw_grid": 1.0}}"#,
        ]),
    ));
    out.push(seed(
        "dataset_json",
        "relations",
        join_parts(&[
            r#"{"kind": "relations", "train": [0], "test": [0]}"#,
            r#"{"viewpoint": {"x": 0.5, "y": 0.5, "z": 1.7, "yaw": 0.2},
 "objects": [{"id": 1, "class": "car", "ground": 0, "centre": [1.7, 1.3, 0.5], "half_extents": [0.8, 0.4, 0.5], "yaw_rad": 0.0},
             {"id": 2, "class": "pole"}],
 "pairs": [{"a": 1, "b": 2, "truth": {"On": false, "LeftOf": true, "Behind": false}, "annotated": {"On": false, "LeftOf": true, "Behind": true}},
           {"a": 2, "b": 7, "truth": {"On": true, "LeftOf": false, "Behind": false}, "annotated": {"On": true, "LeftOf": false, "Behind": false}}]}"#,
        ]),
    ));
}

/// Every seed of every target.
pub fn seeds() -> Vec<Seed> {
    let mut out = Vec::new();
    opb_seeds(&mut out);
    mln_seeds(&mut out);
    osm_seeds(&mut out);
    cloud_seeds(&mut out);
    srt_seeds(&mut out);
    streets_seeds(&mut out);
    dataset_seeds(&mut out);
    out
}

/// Writes every seed to `corpus/<target>/seed-<name>` under `fuzz_dir`.
pub fn write_seeds(fuzz_dir: &Path) -> std::io::Result<usize> {
    let all = seeds();
    for s in &all {
        let dir = fuzz_dir.join("corpus").join(s.target);
        std::fs::create_dir_all(&dir)?;
        std::fs::write(dir.join(format!("seed-{}", s.name)), &s.bytes)?;
    }
    Ok(all.len())
}
