//! NumPy arrays in and out: rows of floats borrowed in place where their layout allows,
//! checked with the command line's messages; results handed over without a copy.

use hytrace_trace::error::report;
use hytrace_trace::scan::{check_row_shape, not_float_rows, rays_from_rows, RayRow};
use numpy::{
    Element, PyArray1, PyArrayDescrMethods, PyArrayMethods, PyReadonlyArray2, PyUntypedArray,
    PyUntypedArrayMethods,
};
use pyo3::prelude::*;

use crate::errors::{type_error, value_error, Error};

/// `(N, W)` rows of f64: a C-contiguous, aligned float64 array borrowed in place, or the
/// rows converted (float32 arrays, other layouts).
pub enum Rows<'py, const W: usize> {
    /// Borrowed from the caller's array.
    Borrowed(PyReadonlyArray2<'py, f64>),
    /// Converted.
    Owned(Vec<[f64; W]>),
}

impl<const W: usize> Rows<'_, W> {
    /// The rows.
    pub fn rows(&self) -> &[[f64; W]] {
        match self {
            Rows::Borrowed(a) => {
                bytemuck::cast_slice(a.as_slice().expect("borrowed only in C order"))
            }
            Rows::Owned(v) => v,
        }
    }
}

/// The argument `what` (any array-like, as `numpy.asarray` reads it) as `(N, W)` rows of
/// f64; `columns` describes the columns in errors. A wrong shape raises
/// `HytraceValueError`, an element type other than float32 or float64 `HytraceTypeError`,
/// with the messages the command gives a file of such an array.
pub fn float_rows<'py, const W: usize>(
    value: &Bound<'py, PyAny>,
    what: &str,
    columns: &str,
) -> PyResult<Rows<'py, W>> {
    let py = value.py();
    let array = match value.cast::<PyUntypedArray>() {
        Ok(a) => a.clone(),
        Err(_) => py
            .import("numpy")?
            .call_method1("asarray", (value,))?
            .cast_into::<PyUntypedArray>()?,
    };
    // NumPy reads misaligned buffers (such as arrays unpickled from a byte stream); Rust
    // reads aligned ones only: those are copied into an aligned array first.
    let aligned: bool = array.getattr("flags")?.getattr("aligned")?.extract()?;
    let array = match aligned {
        true => array,
        false => py
            .import("numpy")?
            .call_method1("require", (array, py.None(), "A"))?
            .cast_into::<PyUntypedArray>()?,
    };
    let dtype = array.dtype();
    let not_float = || -> PyResult<PyErr> {
        let got = dtype.str()?.to_string();
        Ok(type_error(not_float_rows(what, what, &got).to_string()).into())
    };
    // Text or objects are of the wrong type whatever their shape.
    if !matches!(dtype.kind(), b'b' | b'i' | b'u' | b'f' | b'c') {
        return Err(not_float()?);
    }
    let shape: Vec<u64> = array.shape().iter().map(|&d| d as u64).collect();
    check_row_shape::<W>(&shape, what, what, columns).map_err(|e| value_error(e.to_string()))?;
    if let Ok(a) = array.extract::<PyReadonlyArray2<'py, f64>>() {
        // `as_slice` takes Fortran order too: only C order reads as rows.
        if array.is_c_contiguous() && a.as_slice().is_ok() {
            return Ok(Rows::Borrowed(a));
        }
        let a = a.as_array();
        return Ok(Rows::Owned(
            a.rows()
                .into_iter()
                .map(|r| std::array::from_fn(|k| r[k]))
                .collect(),
        ));
    }
    if let Ok(a) = array.extract::<PyReadonlyArray2<'py, f32>>() {
        let a = a.as_array();
        return Ok(Rows::Owned(
            a.rows()
                .into_iter()
                .map(|r| std::array::from_fn(|k| f64::from(r[k])))
                .collect(),
        ));
    }
    Err(not_float()?)
}

/// Validated rays (finite origins, non-zero finite directions, finite `tmin < tmax`),
/// errors naming the first bad ray as the command does.
pub fn ray_rows(rows: &[[f64; 8]]) -> Result<Vec<RayRow>, Error> {
    rays_from_rows(rows, "rays").map_err(|e| value_error(report(&e)))
}

/// `values` as an `(n, width)` array, without a copy.
pub fn matrix<'py, T: Element>(
    py: Python<'py>,
    values: Vec<T>,
    n: usize,
    width: usize,
) -> PyResult<Bound<'py, PyAny>> {
    Ok(PyArray1::from_vec(py, values)
        .reshape([n, width])?
        .into_any())
}
