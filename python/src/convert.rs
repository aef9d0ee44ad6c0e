//! Rust values to fresh numpy arrays and Python dicts (never views of a buffer that is reused:
//! Gymnasium's checker and users rely on that).

use numpy::ndarray::{ArrayD, IxDyn};
use numpy::{Element, IntoPyArray, PyArray1, PyReadonlyArrayDyn};
use pyo3::exceptions::PyRuntimeError;
use pyo3::prelude::*;
use pyo3::types::PyDict;
use pyo3::IntoPyObjectExt;

use modesuite::gym::info::{Batch, ColumnData, Info, InfoValue};
use modesuite::gym::layout::{convert, ObsLayout, OutBuf};

/// Any array-like of numbers (float64, a strided view, a list) as a C-ordered float32 array:
/// `numpy.ascontiguousarray(a, dtype=float32)`, which copies only when it has to.
pub fn f32_array<'py>(a: &Bound<'py, PyAny>) -> PyResult<PyReadonlyArrayDyn<'py, f32>> {
    let py = a.py();
    let kwargs = PyDict::new(py);
    kwargs.set_item("dtype", "float32")?;
    py.import("numpy")?
        .call_method("ascontiguousarray", (a,), Some(&kwargs))?
        .extract()
}

/// A fresh array of `data` with `shape`.
pub fn array<T: Element>(py: Python<'_>, data: Vec<T>, shape: &[usize]) -> PyResult<Py<PyAny>> {
    let a = ArrayD::from_shape_vec(IxDyn(shape), data)
        .map_err(|e| PyRuntimeError::new_err(format!("array shape {shape:?}: {e}")))?;
    Ok(a.into_pyarray(py).into_any().unbind())
}

/// An observation: the flat per-env values `flat` of one env (`rows` None: no batch axis) or
/// of `rows` envs, as one float32 array or a dict of arrays.
pub fn obs(
    py: Python<'_>,
    layout: &ObsLayout,
    flat: &[f32],
    rows: Option<usize>,
) -> PyResult<Py<PyAny>> {
    let n = rows.unwrap_or(1);
    let bufs = convert(layout, flat, n);
    let keys = layout.out_keys();
    let mut arrays = Vec::with_capacity(keys.len());
    for (k, buf) in keys.iter().zip(bufs) {
        let shape: Vec<usize> = rows.into_iter().chain(k.shape.iter().copied()).collect();
        let a = match buf {
            OutBuf::F32(v) => array(py, v, &shape)?,
            OutBuf::U8(v) => array(py, v, &shape)?,
        };
        arrays.push((k.key.as_str(), a));
    }
    if let ObsLayout::Flat { .. } = layout {
        if let Some((_, a)) = arrays.pop() {
            return Ok(a);
        }
    }
    let d = PyDict::new(py);
    for (k, a) in arrays {
        d.set_item(k, a)?;
    }
    Ok(d.into_any().unbind())
}

fn value(py: Python<'_>, layout: &ObsLayout, v: InfoValue<Vec<f32>>) -> PyResult<Py<PyAny>> {
    match v {
        InfoValue::Bool(b) => b.into_py_any(py),
        InfoValue::F64(x) => x.into_py_any(py),
        InfoValue::Str(s) => s.into_py_any(py),
        InfoValue::None => Ok(py.None()),
        InfoValue::StrList(l) => l.into_py_any(py),
        InfoValue::Dict(d) => Ok(info(py, layout, d)?.into_any().unbind()),
        InfoValue::Obs(o) => obs(py, layout, &o, None),
    }
}

/// One env's info dict.
pub fn info<'py>(
    py: Python<'py>,
    layout: &ObsLayout,
    items: Info<Vec<f32>>,
) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    for (k, v) in items {
        d.set_item(k, value(py, layout, v)?)?;
    }
    Ok(d)
}

/// A batched info dict: each key's array with its `_key` mask beside it.
pub fn batch<'py>(
    py: Python<'py>,
    layout: &ObsLayout,
    b: Batch<Vec<f32>>,
) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    for (key, col) in b.cols {
        let n = col.mask.len();
        let data: Py<PyAny> = match col.data {
            ColumnData::Bool(a) => array(py, a, &[n])?,
            ColumnData::F64(a) => array(py, a, &[n])?,
            ColumnData::Dict(inner) => batch(py, layout, inner)?.into_any().unbind(),
            ColumnData::Object(a) => {
                let objects = a
                    .into_iter()
                    .map(|v| value(py, layout, v))
                    .collect::<PyResult<Vec<_>>>()?;
                PyArray1::from_vec(py, objects).into_any().unbind()
            }
        };
        d.set_item(&key, data)?;
        d.set_item(format!("_{key}"), array(py, col.mask, &[n])?)?;
    }
    Ok(d)
}
