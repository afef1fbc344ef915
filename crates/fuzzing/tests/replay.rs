//! Replays the committed fuzz corpus and every kept crash input through its target (issue 16).
//!
//! For each target of [`fuzzing::TARGETS`], every file of `fuzz/corpus/<target>/` (the
//! minimised corpus) and of `fuzz/artifacts/<target>/` (inputs that once crashed, hung or ran
//! out of memory, kept as regressions) goes through the target function. A panic fails the
//! test with the file's name; a hang shows as a CI timeout (no timing assertions). A target
//! without a corpus folder fails the test.
//!
//! Artifacts named `open-*` reproduce a bug that is not fixed yet, in a reader whose owner
//! has it on their list (`fuzz/README.md`); they are listed on stderr but not run (one of
//! them aborts the process on a 64 GB allocation). Dropping the prefix puts an input under
//! replay once its bug is fixed.
//!
//! Run with `cargo test -p fuzzing --release` (the readers are slow without optimisation).

use std::path::{Path, PathBuf};

fn fuzz_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../fuzz")
}

/// Files of a folder, sorted by name (empty if it does not exist).
fn files(dir: &Path) -> Vec<PathBuf> {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return Vec::new();
    };
    let mut out: Vec<PathBuf> = entries
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.is_file())
        .collect();
    out.sort();
    out
}

/// Runs every corpus and artifact file of `target`; returns how many ran.
fn replay(target: &str) -> usize {
    let (_, run) = fuzzing::TARGETS
        .iter()
        .find(|(name, _)| *name == target)
        .unwrap_or_else(|| panic!("no fuzz target named {target}"));
    let corpus = fuzz_dir().join("corpus").join(target);
    assert!(
        corpus.is_dir(),
        "the corpus folder {} of target {target} is missing: run `cargo run -p fuzzing --example write_seeds` and fuzz it (fuzz/README.md)",
        corpus.display()
    );
    let (open, fixed): (Vec<PathBuf>, Vec<PathBuf>) =
        files(&fuzz_dir().join("artifacts").join(target))
            .into_iter()
            .partition(|p| {
                p.file_name()
                    .is_some_and(|n| n.to_string_lossy().starts_with("open-"))
            });
    for path in &open {
        eprintln!("{target}: not replayed, bug still open: {}", path.display());
    }
    let inputs: Vec<PathBuf> = files(&corpus).into_iter().chain(fixed).collect();
    assert!(
        !inputs.is_empty(),
        "the corpus folder {} of target {target} is empty",
        corpus.display()
    );
    for path in &inputs {
        let data =
            std::fs::read(path).unwrap_or_else(|e| panic!("cannot read {}: {e}", path.display()));
        let outcome = std::panic::catch_unwind(|| run(&data));
        assert!(
            outcome.is_ok(),
            "target {target} panicked on {} (replay it with `cargo fuzz run {target} {}`)",
            path.display(),
            path.display()
        );
    }
    inputs.len()
}

macro_rules! replay_tests {
    ($($target:ident),* $(,)?) => {
        $(
            #[test]
            fn $target() {
                let n = replay(stringify!($target));
                eprintln!("{}: {n} inputs replayed", stringify!($target));
            }
        )*

        #[test]
        fn every_target_has_a_replay_test() {
            let tested = [$(stringify!($target)),*];
            for (name, _) in fuzzing::TARGETS {
                assert!(tested.contains(&name), "target {name} has no replay test");
            }
        }
    };
}

replay_tests!(
    opb,
    mln_program,
    mln_evidence,
    mln_query,
    mln_infer,
    osm_xml,
    osm_pbf,
    ply,
    pcd,
    las,
    kitti_bin,
    srt,
    streets_model,
    dataset_json,
);
