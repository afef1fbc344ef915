//! `urbansem pbo solve`: an `.opb` objective read and minimised by [`crate::qssr`], as a
//! typed report.

use crate::opb::{read_opb, OpbError, Sense};
use crate::qssr::{solve, QssrOptions, QssrRound};
use serde::Serialize;
use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::Path;
use std::time::Instant;

/// Seconds per phase of a [`SolveReport`].
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SolveSeconds {
    /// Reading the file.
    pub parse: f64,
    /// Order reduction, all rounds.
    pub quadratize: f64,
    /// QPBO, probing and QPBO-I.
    pub solve: f64,
    /// QPBO-I on the residue.
    pub improve: f64,
    /// From the start of reading to the end of solving.
    pub total: f64,
    /// QPBO and probing alone (the text's `solve`).
    #[serde(skip)]
    pub qpbo: f64,
}

/// An `.opb` objective minimised by QSSR (`pbo solve --json`).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SolveReport {
    /// The `.opb` file.
    pub file: String,
    /// `min` or `max`, as the file asks.
    pub sense: String,
    /// Variables of the objective.
    pub variables: usize,
    /// Its terms.
    pub terms: usize,
    /// Its degree.
    pub degree: usize,
    /// Its terms of degree ≥ 3.
    pub higher_order_terms: usize,
    /// Order reduction.
    pub quadratize: String,
    /// Whether probing ran.
    pub probe: bool,
    /// QPBO-I iterations.
    pub improve: usize,
    /// Seed of QPBO-I.
    pub seed: u64,
    /// Energy of the assignment (of the negated objective for `max`).
    pub energy: f64,
    /// Best roof-dual lower bound on the energy.
    pub lower_bound: f64,
    /// The objective's value in the file's sense.
    pub objective: f64,
    /// Persistent share of the occurring variables.
    pub labelled_fraction: f64,
    /// One record per QSSR round.
    pub rounds: Vec<QssrRound>,
    /// Seconds per phase.
    pub seconds: SolveSeconds,
    /// The value (0 or 1) of every variable, by name.
    pub assignment: BTreeMap<String, u8>,
}

/// Reads the objective of an `.opb` file and minimises it by QSSR.
pub fn solve_opb_file(path: &Path, options: &QssrOptions) -> Result<SolveReport, OpbError> {
    let t0 = Instant::now();
    let problem = read_opb(path)?;
    let parse_s = t0.elapsed().as_secs_f64();
    let result = solve(&problem.poly, options);
    let total_s = t0.elapsed().as_secs_f64();
    let sign = match problem.sense {
        Sense::Minimize => 1.0,
        Sense::Maximize => -1.0,
    };
    Ok(SolveReport {
        file: path.display().to_string(),
        sense: if sign > 0.0 { "min" } else { "max" }.to_owned(),
        variables: problem.poly.num_vars(),
        terms: problem.poly.num_terms(),
        degree: problem.poly.degree(),
        higher_order_terms: problem.poly.num_higher_order_terms(),
        quadratize: options.quadratizer.name().to_owned(),
        probe: options.probe,
        improve: options.improve_rounds,
        seed: options.seed,
        energy: result.energy,
        lower_bound: result.lower_bound,
        objective: sign * result.energy,
        labelled_fraction: result.labelled_fraction,
        rounds: result.rounds,
        seconds: SolveSeconds {
            parse: parse_s,
            quadratize: result.seconds.quadratize,
            solve: result.seconds.solve + result.seconds.improve,
            improve: result.seconds.improve,
            total: total_s,
            qpbo: result.seconds.solve,
        },
        assignment: problem
            .names
            .iter()
            .zip(&result.assignment)
            .map(|(name, &v)| (name.clone(), u8::from(v)))
            .collect(),
    })
}

impl SolveReport {
    /// The problem's size, one line per round, the energy, bound and timings.
    pub fn text(&self) -> String {
        let mut out = String::new();
        let _ = writeln!(
            out,
            "{}: {} variables, {} terms (degree {}, {} higher-order)",
            self.file, self.variables, self.terms, self.degree, self.higher_order_terms
        );
        out.push_str(
            "round  free vars  higher-order  slacks  fixed(qpbo)  fixed(probe)  lower bound  energy\n",
        );
        for (i, r) in self.rounds.iter().enumerate() {
            let _ = writeln!(
                out,
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
        if self.sense == "max" {
            out.push_str(
                "(max: objective; energy and bounds are of its negation, which is minimised)\n",
            );
            let _ = writeln!(out, "objective         {}", self.objective);
        }
        let _ = writeln!(out, "energy            {}", self.energy);
        let _ = writeln!(out, "lower bound       {}", self.lower_bound);
        let _ = writeln!(
            out,
            "labelled          {:.2} %",
            100.0 * self.labelled_fraction
        );
        let s = &self.seconds;
        let _ = writeln!(
            out,
            "seconds           parse {:.4}  quadratize {:.4}  solve {:.4}  improve {:.4}  total {:.4}",
            s.parse, s.quadratize, s.qpbo, s.improve, s.total
        );
        out
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::expect_used)]
    use super::*;

    #[test]
    fn a_max_objective_is_reported_in_its_own_sense() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("f.opb");
        std::fs::write(&path, "max: +2 x1 x2 -1 x1 ;\n").unwrap();
        let r = solve_opb_file(&path, &QssrOptions::default()).unwrap();
        assert_eq!(r.sense, "max");
        assert_eq!(r.objective, 1.0);
        assert_eq!(r.energy, -1.0);
        assert_eq!(r.assignment.get("x1"), Some(&1));
        assert!(r.text().contains("objective         1\n"));
    }

    #[test]
    fn a_missing_file_is_an_io_error() {
        let r = solve_opb_file(Path::new("/nonexistent/f.opb"), &QssrOptions::default());
        assert!(matches!(r, Err(OpbError::Io { .. })));
    }
}
