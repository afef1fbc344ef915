//! `pbo.solve` / `pbo.solve_file`: minimise a pseudo-Boolean polynomial by QSSR (quadratize,
//! QPBO, fix persistencies, repeat) from Python terms or an `.opb` file.

use crate::arrays::to_array;
use crate::error::raise;
use pbo::polynomial::{Literal, Polynomial};
use pbo::qssr::{solve, QssrOptions};
use pbo::quadratize::Quadratizer;
use pbo::report::solve_opb_file;
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::PyDict;
use std::path::PathBuf;

/// Adds the pbo functions to the module.
pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(pbo_solve, m)?)?;
    m.add_function(wrap_pyfunction!(pbo_solve_file, m)?)?;
    Ok(())
}

fn options(quadratize: &str, probe: bool, improve: usize, seed: u64) -> PyResult<QssrOptions> {
    let quadratizer: Quadratizer = quadratize.parse().map_err(PyValueError::new_err)?;
    Ok(QssrOptions {
        quadratizer,
        probe,
        improve_rounds: improve,
        seed,
        ..QssrOptions::default()
    })
}

/// The largest variable index a term may use (literals pack the variable into 31 bits).
const MAX_VAR: i64 = (1 << 30) - 1;

/// Minimises `constant + Σ coefficient · Π literal` over Boolean variables.
///
/// Each term is `(coefficient, literals)`; a literal is a variable index `i ≥ 0` for xᵢ or
/// `~i` (that is `-i - 1`) for 1 − xᵢ.
#[pyfunction]
#[pyo3(name = "pbo_solve", signature = (terms, *, constant = 0.0, num_vars = None,
    quadratize = "ish", probe = false, improve = 0, seed = 0))]
#[allow(clippy::too_many_arguments)]
fn pbo_solve<'py>(
    py: Python<'py>,
    terms: Vec<(f64, Vec<i64>)>,
    constant: f64,
    num_vars: Option<usize>,
    quadratize: &str,
    probe: bool,
    improve: usize,
    seed: u64,
) -> PyResult<Bound<'py, PyDict>> {
    let options = options(quadratize, probe, improve, seed)?;
    let mut max_var: i64 = -1;
    for (t, (coefficient, lits)) in terms.iter().enumerate() {
        if !coefficient.is_finite() {
            return Err(crate::error::PboError::new_err(format!(
                "term {t}: coefficient {coefficient} is not finite"
            )));
        }
        for &l in lits {
            let var = if l < 0 { -l - 1 } else { l };
            if var > MAX_VAR {
                return Err(crate::error::PboError::new_err(format!(
                    "term {t}: variable {var} is above the largest index {MAX_VAR}"
                )));
            }
            max_var = max_var.max(var);
        }
    }
    if !constant.is_finite() {
        return Err(crate::error::PboError::new_err("constant is not finite"));
    }
    let used = usize::try_from(max_var + 1).unwrap_or(0);
    let n = match num_vars {
        Some(n) if n < used => {
            return Err(crate::error::PboError::new_err(format!(
                "num_vars = {n}, but a term uses variable {max_var}"
            )))
        }
        Some(n) => n,
        None => used,
    };
    let result = py.detach(|| {
        let mut f = Polynomial::new(n);
        f.add_constant(constant);
        let mut literals = Vec::new();
        for (coefficient, lits) in &terms {
            literals.clear();
            // Indices are checked above: 0 ≤ var ≤ MAX_VAR < 2³¹.
            literals.extend(lits.iter().map(|&l| {
                if l < 0 {
                    Literal::neg((-l - 1) as u32)
                } else {
                    Literal::pos(l as u32)
                }
            }));
            f.add_term(*coefficient, &literals);
        }
        solve(&f, &options)
    });
    let d = PyDict::new(py);
    d.set_item("energy", result.energy)?;
    d.set_item("lower_bound", result.lower_bound)?;
    d.set_item("labelled_fraction", result.labelled_fraction)?;
    d.set_item("exact", result.exact)?;
    d.set_item(
        "assignment",
        to_array(py, result.assignment.iter().map(|&v| u8::from(v)).collect()),
    )?;
    d.set_item(
        "persistent",
        to_array(
            py,
            result
                .persistent
                .iter()
                .map(|v| v.map_or(-1i8, i8::from))
                .collect(),
        ),
    )?;
    d.set_item("rounds", pythonize::pythonize(py, &result.rounds)?)?;
    d.set_item("seconds", {
        let s = PyDict::new(py);
        s.set_item("quadratize", result.seconds.quadratize)?;
        s.set_item("solve", result.seconds.solve)?;
        s.set_item("improve", result.seconds.improve)?;
        s
    })?;
    Ok(d)
}

/// Reads an `.opb` objective and minimises it: the dict `urbansem pbo solve --json` prints.
#[pyfunction]
#[pyo3(name = "pbo_solve_file", signature = (path, *, quadratize = "ish", probe = false,
    improve = 0, seed = 0))]
fn pbo_solve_file<'py>(
    py: Python<'py>,
    path: PathBuf,
    quadratize: &str,
    probe: bool,
    improve: usize,
    seed: u64,
) -> PyResult<Bound<'py, PyAny>> {
    let options = options(quadratize, probe, improve, seed)?;
    let report = py
        .detach(|| solve_opb_file(&path, &options))
        .map_err(raise!(PboError))?;
    Ok(pythonize::pythonize(py, &report)?)
}
