//! `urbansem pbo …`: minimise pseudo-Boolean objectives from `.opb` files.

use anyhow::Context;
use clap::{Args, Subcommand};
use pbo::qssr::QssrOptions;
use pbo::quadratize::Quadratizer;
use pbo::report::solve_opb_file;
use std::path::PathBuf;

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
    /// Order reduction for terms of degree ≥ 3: ish, asm, fix, grd.
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
    let options = QssrOptions {
        quadratizer: args.quadratize,
        probe: args.probe,
        improve_rounds: args.improve,
        seed: args.seed,
        ..QssrOptions::default()
    };
    let report = solve_opb_file(&args.file, &options).context("reading the objective")?;
    if args.json {
        super::print_json(&report)?;
    } else {
        print!("{}", report.text());
    }
    Ok(())
}
