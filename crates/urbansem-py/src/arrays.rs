//! NumPy ↔ Rust conversions shared by the bindings: `(n, k)` arrays of points in, owned
//! vectors handed to NumPy out (no copy: the array takes the vector's buffer).

use numpy::ndarray::Array2;
use numpy::{
    Element, IntoPyArray, PyArray1, PyArray2, PyReadonlyArray1, PyReadonlyArray2,
    PyUntypedArrayMethods,
};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use std::borrow::Cow;

/// An `(n, K)` array's rows as `[T; K]`: borrowed when the array is C-contiguous, copied
/// otherwise (Fortran order and strided views included). `what` names the argument in the error.
pub fn rows<'a, T: Element + Copy, const K: usize>(
    array: &'a PyReadonlyArray2<'_, T>,
    what: &str,
) -> PyResult<Cow<'a, [[T; K]]>> {
    let shape = array.shape();
    if shape[1] != K {
        return Err(PyValueError::new_err(format!(
            "{what} must have shape (n, {K}); got ({}, {})",
            shape[0], shape[1]
        )));
    }
    // `as_slice` also accepts Fortran-ordered arrays, whose flat order is column by column.
    if let Ok(flat) = array.as_slice().map_err(drop).and_then(|f| {
        if array.is_c_contiguous() {
            Ok(f)
        } else {
            Err(())
        }
    }) {
        let n = flat.len() / K;
        // SAFETY: `[T; K]` has the size of K consecutive `T`s and the alignment of `T`;
        // `flat` holds exactly n·K initialised elements (C order, K columns), borrowed for 'a.
        let rows = unsafe { std::slice::from_raw_parts(flat.as_ptr().cast::<[T; K]>(), n) };
        return Ok(Cow::Borrowed(rows));
    }
    let view = array.as_array();
    Ok(Cow::Owned(
        view.rows()
            .into_iter()
            .map(|r| std::array::from_fn(|j| r[j]))
            .collect(),
    ))
}

/// A 1-D array's values: borrowed when contiguous, copied otherwise.
pub fn values<'a, T: Element + Copy>(array: &'a PyReadonlyArray1<'_, T>) -> Cow<'a, [T]> {
    match array.as_slice() {
        Ok(s) => Cow::Borrowed(s),
        Err(_) => Cow::Owned(array.as_array().iter().copied().collect()),
    }
}

/// Rows `[T; K]` as an `(n, K)` NumPy array that owns the vector's buffer.
pub fn to_rows<'py, T: Element, const K: usize>(
    py: Python<'py>,
    rows: Vec<[T; K]>,
) -> Bound<'py, PyArray2<T>> {
    let n = rows.len();
    let flat: Vec<T> = rows.into_flattened();
    match Array2::from_shape_vec((n, K), flat) {
        Ok(a) => a.into_pyarray(py),
        // The shape is n × K by construction of `flat`.
        Err(_) => unreachable!("n·K elements always form an (n, K) array"),
    }
}

/// A vector as a 1-D NumPy array that owns its buffer.
pub fn to_array<T: Element>(py: Python<'_>, v: Vec<T>) -> Bound<'_, PyArray1<T>> {
    v.into_pyarray(py)
}
