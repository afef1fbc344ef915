//! Runs input files through one fuzz target in an ordinary build, without cargo-fuzz, and
//! prints the time each took: `cargo run --release -p fuzzing --example replay_one -- TARGET FILE…`.

use std::time::Instant;

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let Some((target, files)) = args.split_first() else {
        eprintln!("usage: replay_one TARGET FILE…");
        std::process::exit(2);
    };
    let Some((_, run)) = fuzzing::TARGETS.iter().find(|(name, _)| name == target) else {
        eprintln!(
            "unknown target {target}; targets: {:?}",
            fuzzing::TARGETS.map(|t| t.0)
        );
        std::process::exit(2);
    };
    for file in files {
        let data = match std::fs::read(file) {
            Ok(d) => d,
            Err(e) => {
                eprintln!("{file}: {e}");
                std::process::exit(1);
            }
        };
        let t0 = Instant::now();
        run(&data);
        println!(
            "{file}: {} bytes, {:.3} s",
            data.len(),
            t0.elapsed().as_secs_f64()
        );
    }
}
