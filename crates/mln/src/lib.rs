//! Markov logic networks (thesis §3.2): the Alchemy/Tuffy/RockIt language, grounding,
//! the pseudo-Boolean form (PBMLN) and MAP inference on `pbo`.
//!
//! Where it sits in the pipeline: above `pbo` (which minimises the ground polynomial) and
//! below `srtree` (whose spatial-relation consistency is an MLN). Stages, in data-flow order:
//!
//! - [`parse`]: programs (`.mln`), evidence (`.db`) and queries, with file:line:col errors.
//! - [`ground`]: join-based grounding with evidence simplification → the cost polynomial.
//! - [`infer`]: MAP inference (QPBO/QSSR, MaxWalkSAT on formulas or monomials).
//! - [`learn`]: discriminative weight learning (voted perceptron on MAP counts).
//! - [`marginal`]: marginal probabilities (MC-SAT; exact enumeration for small problems).
//! - [`walksat`]: MaxWalkSAT over weighted conjunctive factors.
//! - [`wcnf`]: the ground problem as weighted partial MaxSAT for exact solvers.
//! - [`generate`]: seeded generators of the thesis' F&S, −F&S and ID problems.
//! - [`files`]: a problem on disk read and grounded, answers, benchmark problems, reports.

pub mod files;
pub mod generate;
pub mod ground;
pub mod infer;
pub mod learn;
pub mod marginal;
pub mod parse;
pub mod walksat;
pub mod wcnf;
