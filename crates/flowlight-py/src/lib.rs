//! `flowlight._native`: the host's API for Python (the `flowlight` package wraps it; its
//! documentation is docs/python.md). A scene is loaded and its intersector built once
//! (`scene::Scene`, over the host's [`LoadedScene`](flowlight_host::renderer::LoadedScene));
//! each render creates only the integrator, with the GIL released while it runs, and hands
//! back an `image::Image` of numpy arrays. Errors are `flowlight.Error` subclasses carrying
//! the command line's one-line messages (module `errors`).

use pyo3::prelude::*;

mod convert;
mod errors;
mod image;
mod render_loop;
mod scene;
mod tools;

/// The extension module.
#[pymodule]
#[pyo3(name = "_native")]
fn native(m: &Bound<'_, PyModule>) -> PyResult<()> {
    errors::register(m)?;
    m.add_class::<scene::Scene>()?;
    m.add_class::<image::Image>()?;
    m.add_function(wrap_pyfunction!(scene::load_path, m)?)?;
    m.add_function(wrap_pyfunction!(scene::load_table, m)?)?;
    m.add_function(wrap_pyfunction!(tools::plugins, m)?)?;
    m.add_function(wrap_pyfunction!(tools::search_path, m)?)?;
    m.add_function(wrap_pyfunction!(tools::compare, m)?)?;
    m.add_function(wrap_pyfunction!(tools::combine_halves, m)?)?;
    m.add_function(wrap_pyfunction!(tools::read_exr, m)?)?;
    m.add_function(wrap_pyfunction!(tools::bench, m)?)?;
    m.add_function(wrap_pyfunction!(tools::loads_so_far, m)?)?;
    m.add_function(wrap_pyfunction!(tools::set_package_dir, m)?)?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    Ok(())
}
