//! The seed inputs are valid files of their format: each reader accepts them, so the fuzzer
//! starts from inputs that reach deep into the reader rather than from its first check.

use fuzzing::seeds::{seeds, Seed};
use std::path::Path;

fn of(target: &str) -> Vec<Seed> {
    let out: Vec<Seed> = seeds().into_iter().filter(|s| s.target == target).collect();
    assert!(!out.is_empty(), "no seeds for {target}");
    out
}

fn text(s: &Seed) -> String {
    String::from_utf8(s.bytes.clone())
        .unwrap_or_else(|e| panic!("seed {} is not UTF-8: {e}", s.name))
}

#[test]
fn opb_and_mln_seeds_parse() {
    for s in of("opb") {
        pbo::opb::parse_opb(&text(&s), &s.name).unwrap();
    }
    for s in of("mln_program") {
        mln::parse::parse_program(&text(&s), &s.name).unwrap();
    }
    let program = mln::parse::parse_program(fuzzing::FIXED_PROGRAM, "fixed.mln").unwrap();
    for s in of("mln_evidence") {
        mln::parse::parse_evidence(&text(&s), &s.name, &program).unwrap();
    }
    for s in of("mln_query") {
        let atoms = if text(&s).contains('(') {
            mln::parse::parse_query(&text(&s), &s.name, &program).unwrap()
        } else {
            mln::parse::parse_query_predicates(&text(&s), &program).unwrap()
        };
        assert!(atoms.len() >= 3, "{}", s.name);
    }
    for s in of("mln_infer") {
        let parts = fuzzing::split_parts(&s.bytes, 3);
        assert!(parts.iter().all(|p| !p.is_empty()), "{}", s.name);
        let program = std::str::from_utf8(parts[0]).unwrap();
        let program = mln::parse::parse_program(program, &s.name).unwrap();
        let evidence = std::str::from_utf8(parts[1]).unwrap();
        mln::parse::parse_evidence(evidence, &s.name, &program).unwrap();
    }
}

#[test]
fn map_seeds_load() {
    for s in of("osm_xml") {
        let map = geodata::osm::OsmMap::from_xml_str(&text(&s)).unwrap();
        assert!(!map.streets.segments.is_empty(), "{}", s.name);
    }
    let dir = tempfile::tempdir().unwrap();
    for s in of("osm_pbf") {
        let path = dir.path().join(format!("{}.osm.pbf", s.name));
        std::fs::write(&path, &s.bytes).unwrap();
        let map = geodata::osm::OsmMap::load(&path).unwrap();
        assert_eq!(map.streets.segments.len(), 2, "{}", s.name);
        assert_eq!(map.buildings.len(), 2, "{}", s.name);
    }
    for s in of("srt") {
        srtree::io::decode_map(&s.bytes, Path::new(&s.name)).unwrap();
    }
    for s in of("streets_model") {
        streets::model::StreetModel::from_json(&s.bytes, Path::new(&s.name)).unwrap();
    }
}

#[test]
fn cloud_seeds_read() {
    let dir = tempfile::tempdir().unwrap();
    for target in ["ply", "pcd", "las", "kitti_bin"] {
        for s in of(target) {
            let ext = match target {
                "kitti_bin" => "bin",
                "las" if s.name.starts_with("laz") => "laz",
                t => t,
            };
            let path = dir.path().join(format!("{}.{ext}", s.name));
            std::fs::write(&path, &s.bytes).unwrap();
            let options = geodata::cloud::ReadOptions {
                drop_non_finite: true,
            };
            let (cloud, _) = geodata::cloud::read_cloud_with(&path, &options)
                .unwrap_or_else(|e| panic!("{}: {e}", s.name));
            assert!(cloud.len() >= 3, "{}", s.name);
        }
    }
}

#[test]
fn dataset_seeds_load_with_their_reader() {
    let fixture = fuzzing::seeds::dataset_fixture().unwrap();
    for s in of("dataset_json") {
        let dir = tempfile::tempdir().unwrap();
        let d = dir.path();
        let parts = fuzzing::split_parts(&s.bytes, 2);
        for (name, bytes) in [
            ("dataset.json", parts[0]),
            ("truth.json", parts[1]),
            ("segments.json", parts[1]),
            ("scene_000.json", parts[1]),
            ("map.osm", &fixture.map_osm[..]),
            ("cloud.ply", &fixture.streets_ply[..]),
            ("scene_000.ply", &fixture.scene_ply[..]),
        ] {
            std::fs::write(d.join(name), bytes).unwrap();
        }
        match s.name.as_str() {
            "localization" => {
                let ds = localize::eval::SimDataset::open(d).unwrap();
                assert_eq!(ds.truth.len(), 2);
                ds.load(0).unwrap();
            }
            "streets" => {
                streets::dataset::StreetsDataset::load(d).unwrap();
            }
            "relations" => {
                let ds = srtree::dataset::RelationsDataset::load(
                    d,
                    &srtree::map::MapOptions::default(),
                    &srtree::objects::ObjectOptions::default(),
                )
                .unwrap();
                assert_eq!(ds.train.len(), 1);
            }
            other => panic!("unexpected dataset seed {other}"),
        }
    }
}
