//! `clevrtex._native`: the Rust half of the Python package `clevrtex` (the Python half, in
//! `python/clevrtex/`, turns torch tensors into numpy arrays, brings other dtypes and layouts
//! to ones read here, and keeps the running statistics). Numpy arrays are read in place, not
//! copied; scoring and decoding run with the GIL released, in parallel over images.
//!
//! The modules by job: `evaluator` (the scoring of `Evaluator` and `evaluate`), `dataset` (a
//! dataset's samples, names and files), `items` (one sample decoded as the `Dataset`'s item),
//! `errors` (Rust errors as Python exceptions).

use pyo3::prelude::*;

mod dataset;
mod errors;
mod evaluator;
mod items;

/// The extension module.
#[pymodule]
fn _native(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(evaluator::score, m)?)?;
    m.add_function(wrap_pyfunction!(evaluator::metric_names, m)?)?;
    m.add_function(wrap_pyfunction!(evaluator::protocol_metrics, m)?)?;
    m.add_function(wrap_pyfunction!(dataset::discover, m)?)?;
    m.add_function(wrap_pyfunction!(dataset::colour_breakdown, m)?)?;
    m.add_function(wrap_pyfunction!(items::load_sample, m)?)?;
    m.add_function(wrap_pyfunction!(dataset::read_metadata, m)?)?;
    m.add_function(wrap_pyfunction!(items::load_item, m)?)?;
    m.add_function(wrap_pyfunction!(dataset::pass_files, m)?)?;
    m.add_function(wrap_pyfunction!(dataset::variant_names, m)?)?;
    m.add_function(wrap_pyfunction!(dataset::id_tables, m)?)?;
    Ok(())
}
