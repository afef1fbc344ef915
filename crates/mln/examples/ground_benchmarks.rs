//! Grounds every MLN benchmark in `../shared/data/mln` and prints its size and time.
//!
//! `cargo run --release -p mln --example ground_benchmarks`

use mln::ground::{ground, GroundOptions};
use mln::parse::{read_evidence, read_program, read_query};
use std::path::PathBuf;
use std::time::Instant;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let root = PathBuf::from(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../../shared/data/mln"
    ));
    let sets = [
        ("smoke", "smoke/tuffy"),
        ("LP", "lp/tuffy"),
        ("RC", "rc/rockit"),
        ("KB", "kb/mlcnn"),
        ("PR", "pr/rockit"),
        ("ER", "er/rockit"),
    ];
    println!(
        "{:<6} {:>9} {:>10} {:>12} {:>9} {:>9}",
        "set", "atoms", "factors", "higher-ord", "parse s", "ground s"
    );
    for (name, dir) in sets {
        let t0 = Instant::now();
        let program = read_program(&root.join(dir).join("prog.mln"))?;
        let evidence = read_evidence(&root.join(dir).join("evidence.db"), &program)?;
        let query = read_query(&root.join(dir).join("query.db"), &program)?;
        let t1 = Instant::now();
        let path = root.join(dir).join("evidence.db").display().to_string();
        let problem = ground(
            &program,
            &evidence,
            &path,
            &query,
            &GroundOptions::default(),
        )?;
        let t2 = Instant::now();
        println!(
            "{:<6} {:>9} {:>10} {:>12} {:>9.3} {:>9.3}",
            name,
            problem.atoms.len(),
            problem.factors.len(),
            problem.higher_order_factors(),
            (t1 - t0).as_secs_f64(),
            (t2 - t1).as_secs_f64()
        );
    }
    Ok(())
}
