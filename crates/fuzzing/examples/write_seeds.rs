//! Writes the seed inputs of every fuzz target to `fuzz/corpus/<target>/seed-<name>`.
//!
//! `cargo run -p fuzzing --example write_seeds [FUZZ_DIR]` (default: `fuzz` in the workspace).

fn main() -> std::io::Result<()> {
    let dir = std::env::args_os().nth(1).map_or_else(
        || std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../fuzz"),
        std::path::PathBuf::from,
    );
    let n = fuzzing::seeds::write_seeds(&dir)?;
    println!("wrote {n} seeds under {}", dir.join("corpus").display());
    Ok(())
}
