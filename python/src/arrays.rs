//! Reading numpy arrays (and plain sequences) with the shape and dtype checks the Python API
//! promises: a wrong shape or dtype is a `ValueError` that names the expected shape.

use numpy::{
    PyArray1, PyArray2, PyArrayDescrMethods, PyArrayDyn, PyArrayMethods, PyUntypedArray,
    PyUntypedArrayMethods,
};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::sync::PyOnceLock;

/// `"(3,)"`, `"(N, 3)"` from a shape.
fn shape_text(shape: &[usize]) -> String {
    match shape {
        [n] => format!("({n},)"),
        _ => format!(
            "({})",
            shape
                .iter()
                .map(|d| d.to_string())
                .collect::<Vec<_>>()
                .join(", ")
        ),
    }
}

fn bad_input(name: &str, expected: &[usize], got: String) -> PyErr {
    PyValueError::new_err(format!(
        "{name}: expected a float or integer array of shape {}, got {got}",
        shape_text(expected)
    ))
}

/// numpy.asarray(obj, "float64") (for plain sequences), the function looked up once.
fn asarray<'py>(py: Python<'py>, obj: &Bound<'py, PyAny>) -> PyResult<Bound<'py, PyAny>> {
    static ASARRAY: PyOnceLock<Py<PyAny>> = PyOnceLock::new();
    let f = ASARRAY.get_or_try_init(py, || -> PyResult<Py<PyAny>> {
        Ok(py.import("numpy")?.getattr("asarray")?.unbind())
    })?;
    f.bind(py).call1((obj, "float64"))
}

/// Copies `obj` (a float64, float32 or integer ndarray of exactly `shape`, or a nested sequence of numbers
/// of that shape) into `out` in C order. `out.len()` is the product of `shape`.
pub fn read_into(
    obj: &Bound<'_, PyAny>,
    name: &str,
    shape: &[usize],
    out: &mut [f64],
) -> PyResult<()> {
    // Fast paths: contiguous float64 arrays of one or two dimensions (the per-step case).
    if shape.len() == 1 {
        if let Ok(a) = obj.cast::<PyArray1<f64>>() {
            if a.len() == shape[0] {
                // SAFETY: read under the GIL, no Rust reference to this array is live.
                if let Ok(s) = unsafe { a.as_slice() } {
                    out.copy_from_slice(s);
                    return Ok(());
                }
            }
        }
    } else if shape.len() == 2 {
        if let Ok(a) = obj.cast::<PyArray2<f64>>() {
            if a.shape() == shape {
                // SAFETY: as above.
                if let Ok(s) = unsafe { a.as_slice() } {
                    out.copy_from_slice(s);
                    return Ok(());
                }
            }
        }
    }
    let arr = untyped(obj).map_err(|_| bad_input(name, shape, format!("a {}", type_name(obj))))?;
    let arr = &arr;
    let dtype = arr.dtype();
    let got_shape = arr.shape().to_vec();
    let describe = || {
        let dt = dtype
            .str()
            .map(|s| s.to_string())
            .unwrap_or_else(|_| "?".into());
        format!("a {dt} array of shape {}", shape_text(&got_shape))
    };
    if got_shape != shape {
        return Err(bad_input(name, shape, describe()));
    }
    if let Ok(a) = arr.cast::<PyArrayDyn<f64>>() {
        // SAFETY: as above.
        let v = unsafe { a.as_array() };
        for (o, x) in out.iter_mut().zip(v.iter()) {
            *o = *x;
        }
        return Ok(());
    }
    if let Ok(a) = arr.cast::<PyArrayDyn<f32>>() {
        // SAFETY: as above.
        let v = unsafe { a.as_array() };
        for (o, x) in out.iter_mut().zip(v.iter()) {
            *o = f64::from(*x);
        }
        return Ok(());
    }
    // Integer arrays are numbers too, as a list of ints is: numpy's float64 of them.
    if matches!(dtype.kind(), b'i' | b'u') {
        let converted = asarray(obj.py(), arr.as_any())?;
        if let Ok(a) = converted.cast::<PyArrayDyn<f64>>() {
            // SAFETY: as above (a new array, only here).
            let v = unsafe { a.as_array() };
            for (o, x) in out.iter_mut().zip(v.iter()) {
                *o = *x;
            }
            return Ok(());
        }
    }
    Err(bad_input(name, shape, describe()))
}

/// `obj` as an ndarray, converting sequences with numpy.asarray.
fn untyped<'py>(obj: &Bound<'py, PyAny>) -> PyResult<Bound<'py, PyUntypedArray>> {
    if let Ok(a) = obj.cast::<PyUntypedArray>() {
        return Ok(a.clone());
    }
    let converted = asarray(obj.py(), obj)?;
    Ok(converted.cast_into::<PyUntypedArray>()?)
}

fn type_name(obj: &Bound<'_, PyAny>) -> String {
    obj.get_type()
        .name()
        .map(|n| n.to_string())
        .unwrap_or_else(|_| "?".into())
}

/// A fixed-size vector.
pub fn read3(obj: &Bound<'_, PyAny>, name: &str) -> PyResult<[f64; 3]> {
    let mut out = [0.0; 3];
    read_into(obj, name, &[3], &mut out)?;
    Ok(out)
}

/// A 3×3 matrix, row-major.
pub fn read33(obj: &Bound<'_, PyAny>, name: &str) -> PyResult<[f64; 9]> {
    let mut out = [0.0; 9];
    read_into(obj, name, &[3, 3], &mut out)?;
    Ok(out)
}

/// An array of `shape`, C order.
pub fn read_vec(obj: &Bound<'_, PyAny>, name: &str, shape: &[usize]) -> PyResult<Vec<f64>> {
    let mut out = vec![0.0; shape.iter().product()];
    read_into(obj, name, shape, &mut out)?;
    Ok(out)
}

/// The leading dimension of an array-like (for batches), or a ValueError naming the shape.
pub fn leading_dim(obj: &Bound<'_, PyAny>, name: &str, rest: &[usize]) -> PyResult<usize> {
    let arr = untyped(obj)?;
    let s = arr.shape();
    if s.len() == rest.len() + 1 && s[1..] == *rest {
        Ok(s[0])
    } else {
        let mut want = vec!["N".to_string()];
        want.extend(rest.iter().map(|d| d.to_string()));
        Err(PyValueError::new_err(format!(
            "{name}: expected a float or integer array of shape ({}), got shape {}",
            want.join(", "),
            shape_text(s)
        )))
    }
}
