//! `mln.infer`, `mln.marginals` and `mln.learn`: MAP and marginal inference on a Markov logic
//! network from its files, returning every query atom's value or probability and the report
//! `urbansem mln infer [--marginal] --json` prints, and weight learning as `mln learn`.

use crate::error::raise;
use mln::files::{
    learn_program, load_and_ground, query_probabilities, query_values, InferReport, LearnReport,
    MarginalReport, ProblemFiles, QuerySource,
};
use mln::ground::GroundOptions;
use mln::infer::{map_inference, InferOptions, Method, Representation};
use mln::learn::{Expectations, LearnMethod, LearnOptions};
use mln::marginal::{mc_sat, McSatOptions};
use pbo::quadratize::Quadratizer;
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::PyDict;
use std::path::PathBuf;
use std::time::Instant;

/// Adds the mln functions to the module.
pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(mln_infer, m)?)?;
    m.add_function(wrap_pyfunction!(mln_marginals, m)?)?;
    m.add_function(wrap_pyfunction!(mln_learn, m)?)
}

/// The query as predicates or a query file (exactly one of them).
fn query_source(
    queries: Option<Vec<String>>,
    query_file: Option<PathBuf>,
) -> PyResult<QuerySource> {
    match (queries, query_file) {
        (Some(_), Some(_)) => Err(PyValueError::new_err(
            "give the query as predicates or as a query file, not both",
        )),
        (Some(list), None) => Ok(QuerySource::Predicates(list.join(","))),
        (None, Some(f)) => Ok(QuerySource::File(f)),
        (None, None) => Err(PyValueError::new_err(
            "no query: give query predicates or query_file",
        )),
    }
}

/// MAP inference: `(values, report)`, values mapping each query atom (as written in
/// evidence files) to 0 or 1, report the dict of `urbansem mln infer --json`.
#[pyfunction]
#[pyo3(name = "mln_infer", signature = (program, evidence, queries = None, *, query_file = None,
    method = "qpbo", quadratize = "asm", representation = "auto", probe = false, improve = 0,
    tabu = 20_000, polish = 0, flips = 1_000_000, chains = 2, seed = 0))]
#[allow(clippy::too_many_arguments)]
fn mln_infer<'py>(
    py: Python<'py>,
    program: PathBuf,
    evidence: Vec<PathBuf>,
    queries: Option<Vec<String>>,
    query_file: Option<PathBuf>,
    method: &str,
    quadratize: &str,
    representation: &str,
    probe: bool,
    improve: usize,
    tabu: usize,
    polish: usize,
    flips: usize,
    chains: usize,
    seed: u64,
) -> PyResult<(Bound<'py, PyDict>, Bound<'py, PyAny>)> {
    let query = query_source(queries, query_file)?;
    let method: Method = method.parse().map_err(PyValueError::new_err)?;
    let quadratizer: Quadratizer = quadratize.parse().map_err(PyValueError::new_err)?;
    let representation: Representation = representation.parse().map_err(PyValueError::new_err)?;
    let mut options = InferOptions {
        method,
        quadratizer,
        representation,
        probe,
        improve_rounds: improve,
        polish_flips: polish,
        tabu_moves: tabu,
        ..InferOptions::default()
    };
    options.walksat.seed = seed;
    options.walksat.max_flips = flips;
    options.walksat.chains = chains;
    let files = ProblemFiles {
        program: program.clone(),
        evidence,
        query,
    };
    let (values, report) = py
        .detach(|| {
            let t0 = Instant::now();
            let loaded = load_and_ground(&files, &GroundOptions::map())?;
            let r = map_inference(&loaded.problem, &options);
            let report =
                InferReport::new(&loaded, &program, &options, &r, t0.elapsed().as_secs_f64());
            let values = query_values(
                &loaded.program,
                &loaded.problem,
                &loaded.query,
                &r.assignment,
            );
            Ok::<_, mln::files::FilesError>((values, report))
        })
        .map_err(raise!(MlnError))?;
    let d = PyDict::new(py);
    for (atom, value) in values {
        d.set_item(atom, u8::from(value))?;
    }
    Ok((d, pythonize::pythonize(py, &report)?))
}

/// Marginal inference (MC-SAT): `(probabilities, report)`, probabilities mapping each
/// unknown query atom to P(true), report the dict of `urbansem mln infer --marginal --json`.
#[pyfunction]
#[pyo3(name = "mln_marginals", signature = (program, evidence, queries = None, *,
    query_file = None, samples = 5000, burn_in = 500, chains = 2, seed = 0))]
#[allow(clippy::too_many_arguments)]
fn mln_marginals<'py>(
    py: Python<'py>,
    program: PathBuf,
    evidence: Vec<PathBuf>,
    queries: Option<Vec<String>>,
    query_file: Option<PathBuf>,
    samples: usize,
    burn_in: usize,
    chains: usize,
    seed: u64,
) -> PyResult<(Bound<'py, PyDict>, Bound<'py, PyAny>)> {
    if samples == 0 {
        return Err(PyValueError::new_err("samples must be at least 1"));
    }
    let files = ProblemFiles {
        program: program.clone(),
        evidence,
        query: query_source(queries, query_file)?,
    };
    let options = McSatOptions {
        samples,
        burn_in,
        chains: chains.max(1),
        seed,
        ..McSatOptions::default()
    };
    let (values, report) = py
        .detach(|| {
            let t0 = Instant::now();
            let loaded = load_and_ground(&files, &GroundOptions::default())
                .map_err(|e| crate::error::chain(&e))?;
            let m = mc_sat(&loaded.problem, &options).map_err(|e| crate::error::chain(&e))?;
            let report =
                MarginalReport::new(&loaded, &program, &options, &m, t0.elapsed().as_secs_f64());
            let values = query_probabilities(
                &loaded.program,
                &loaded.problem,
                &loaded.query,
                &m.probabilities,
            );
            Ok::<_, String>((values, report))
        })
        .map_err(crate::error::MlnError::new_err)?;
    let d = PyDict::new(py);
    for (atom, p) in values {
        d.set_item(atom, p)?;
    }
    Ok((d, pythonize::pythonize(py, &report)?))
}

/// Discriminative weight learning: `(text, report)`, text the program with the learnt
/// weights (also written to `output` when given), report the dict of `urbansem mln learn
/// --json`.
#[pyfunction]
#[pyo3(name = "mln_learn", signature = (program, training, queries = None, *,
    query_file = None, output = None, method = "perceptron", expectations = "map",
    samples = 500, epochs = 30, rate = 1.0, l2 = 0.0, warm_start = false, seed = 0))]
#[allow(clippy::too_many_arguments)]
fn mln_learn<'py>(
    py: Python<'py>,
    program: PathBuf,
    training: Vec<PathBuf>,
    queries: Option<Vec<String>>,
    query_file: Option<PathBuf>,
    output: Option<PathBuf>,
    method: &str,
    expectations: &str,
    samples: usize,
    epochs: usize,
    rate: f64,
    l2: f64,
    warm_start: bool,
    seed: u64,
) -> PyResult<(String, Bound<'py, PyAny>)> {
    let method: LearnMethod = method.parse().map_err(PyValueError::new_err)?;
    let expectations: Expectations = expectations.parse().map_err(PyValueError::new_err)?;
    let files = ProblemFiles {
        program: program.clone(),
        evidence: training,
        query: query_source(queries, query_file)?,
    };
    let mut options = LearnOptions {
        epochs,
        learning_rate: rate,
        l2,
        start_from_program: warm_start,
        method,
        expectations,
        ..LearnOptions::default()
    }
    .seeded(seed);
    options.mcsat.samples = samples;
    let (text, report) = py
        .detach(|| {
            let t0 = Instant::now();
            let learnt = learn_program(&files, &options).map_err(|e| crate::error::chain(&e))?;
            let out = output.clone().unwrap_or_default();
            if let Some(path) = &output {
                geodata::fsio::write_atomic(path, &learnt.text)
                    .map_err(|e| format!("writing {}: {e}", path.display()))?;
            }
            let report = LearnReport::new(&program, &out, &learnt, t0.elapsed().as_secs_f64());
            Ok::<_, String>((learnt.text, report))
        })
        .map_err(crate::error::MlnError::new_err)?;
    Ok((text, pythonize::pythonize(py, &report)?))
}
