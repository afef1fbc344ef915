//! `urbansem pbo …`: minimise pseudo-Boolean objectives from `.opb` files.

use anyhow::Context;
use clap::{Args, Subcommand};
use pbo::opb::read_opb;
use pbo::qssr::{solve, QssrOptions, QssrResult};
use pbo::quadratize::Quadratizer;
use serde_json::json;
use std::path::PathBuf;
use std::time::Instant;

/// Subcommands of `urbansem pbo`.
#[derive(Subcommand)]
pub enum PboCommand {
    /// Minimise the objective of an .opb file by QSSR (quadratize, QPBO, fix, repeat) and improve.
    Solve(SolveArgs),
}

/// Options of `urbansem pbo solve`.
#[derive(Args)]
pub struct SolveArgs {
    /// The pseudo-Boolean competition .opb file (objective only, non-linear terms allowed).
    pub file: PathBuf,
    /// Order reduction for terms of degree ≥ 3.
    #[arg(long, default_value = "ish", value_parser = parse_quadratizer)]
    pub quadratize: Quadratizer,
    /// Run probing (QPBO-P) in every round.
    #[arg(long)]
    pub probe: bool,
    /// QPBO-I iterations on the variables left unlabelled.
    #[arg(long, default_value_t = 0, value_name = "N")]
    pub improve: usize,
    /// Seed of the random choices in improve.
    #[arg(long, default_value_t = 0, value_name = "S")]
    pub seed: u64,
    /// Print one JSON object instead of text.
    #[arg(long)]
    pub json: bool,
}

fn parse_quadratizer(s: &str) -> Result<Quadratizer, String> {
    s.parse()
}

/// Runs one `urbansem pbo` subcommand.
pub fn run(command: PboCommand) -> anyhow::Result<()> {
    match command {
        PboCommand::Solve(args) => solve_file(&args),
    }
}

fn solve_file(args: &SolveArgs) -> anyhow::Result<()> {
    let t0 = Instant::now();
    let problem = read_opb(&args.file).context("reading the objective")?;
    let parse_s = t0.elapsed().as_secs_f64();
    let options = QssrOptions {
        quadratizer: args.quadratize,
        probe: args.probe,
        improve_rounds: args.improve,
        seed: args.seed,
        ..QssrOptions::default()
    };
    let result = solve(&problem.poly, &options);
    let total_s = t0.elapsed().as_secs_f64();
    let sign = match problem.sense {
        pbo::opb::Sense::Minimize => 1.0,
        pbo::opb::Sense::Maximize => -1.0,
    };
    if args.json {
        let assignment: serde_json::Map<String, serde_json::Value> = problem
            .names
            .iter()
            .zip(&result.assignment)
            .map(|(name, &v)| (name.clone(), json!(u8::from(v))))
            .collect();
        let out = json!({
            "file": args.file.display().to_string(),
            "sense": if sign > 0.0 { "min" } else { "max" },
            "variables": problem.poly.num_vars(),
            "terms": problem.poly.num_terms(),
            "degree": problem.poly.degree(),
            "higher_order_terms": problem.poly.num_higher_order_terms(),
            "quadratize": args.quadratize.name(),
            "probe": args.probe,
            "improve": args.improve,
            "seed": args.seed,
            "energy": result.energy,
            "lower_bound": result.lower_bound,
            "objective": sign * result.energy,
            "labelled_fraction": result.labelled_fraction,
            "rounds": rounds_json(&result),
            "seconds": {
                "parse": parse_s,
                "quadratize": result.seconds.quadratize,
                "solve": result.seconds.solve + result.seconds.improve,
                "improve": result.seconds.improve,
                "total": total_s,
            },
            "assignment": assignment,
        });
        println!("{}", serde_json::to_string_pretty(&out)?);
    } else {
        println!(
            "{}: {} variables, {} terms (degree {}, {} higher-order)",
            args.file.display(),
            problem.poly.num_vars(),
            problem.poly.num_terms(),
            problem.poly.degree(),
            problem.poly.num_higher_order_terms()
        );
        println!("round  free vars  higher-order  slacks  fixed(qpbo)  fixed(probe)  lower bound  energy");
        for (i, r) in result.rounds.iter().enumerate() {
            println!(
                "{:>5}  {:>9}  {:>12}  {:>6}  {:>11}  {:>12}  {:>11.6}  {:.6}",
                i + 1,
                r.free_variables,
                r.higher_order_terms,
                r.slacks,
                r.fixed_by_qpbo,
                r.fixed_by_probe,
                r.lower_bound,
                r.energy
            );
        }
        if sign < 0.0 {
            println!("(max: objective; energy and bounds are of its negation, which is minimised)");
            println!("objective         {}", sign * result.energy);
        }
        println!("energy            {}", result.energy);
        println!("lower bound       {}", result.lower_bound);
        println!(
            "labelled          {:.2} %",
            100.0 * result.labelled_fraction
        );
        println!(
            "seconds           parse {:.4}  quadratize {:.4}  solve {:.4}  improve {:.4}  total {:.4}",
            parse_s,
            result.seconds.quadratize,
            result.seconds.solve,
            result.seconds.improve,
            total_s
        );
    }
    Ok(())
}

fn rounds_json(result: &QssrResult) -> serde_json::Value {
    result
        .rounds
        .iter()
        .map(|r| {
            json!({
                "free_variables": r.free_variables,
                "higher_order_terms": r.higher_order_terms,
                "slacks": r.slacks,
                "fixed_by_qpbo": r.fixed_by_qpbo,
                "fixed_by_probe": r.fixed_by_probe,
                "lower_bound": r.lower_bound,
                "energy": r.energy,
                "seconds_quadratize": r.seconds_quadratize,
                "seconds_solve": r.seconds_solve,
            })
        })
        .collect()
}
