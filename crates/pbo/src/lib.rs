//! Pseudo-Boolean optimization: the engine under every urbansem inference.
//!
//! Where it sits in the pipeline: `mln` grounds a Markov logic network into a
//! [`polynomial::Polynomial`]; this crate minimises it. The stages, in data-flow order:
//!
//! - [`polynomial`]: multilinear pseudo-Boolean functions over literals, posiforms.
//! - [`quadratize`]: order reduction with slack variables (ISH, ASM, FIX; GRD later).
//! - [`maxflow`]: Boykov–Kolmogorov max-flow / min-cut with tree reuse.
//! - [`qpbo`]: roof duality on the doubled graph, probing (QPBO-P) and improve (QPBO-I).
//! - [`qssr`]: iterated quadratize → QPBO → fix persistencies in the original function.
//! - [`tabu`]: one-flip tabu search and Gray-code enumeration with incremental gains.
//! - [`opb`]: the pseudo-Boolean competition `.opb` objective format.
//! - [`report`]: an `.opb` objective minimised by QSSR, as `urbansem pbo solve` prints it.
//! - [`instances`]: seeded benchmark instances (denoising grid, random sparse, 3-D segmentation).

pub mod instances;
pub mod maxflow;
pub mod opb;
pub mod polynomial;
pub mod qpbo;
pub mod qssr;
pub mod quadratize;
pub mod report;
pub mod tabu;
