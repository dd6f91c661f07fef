//! The Python module `tubeloc`: tubeloc's pipeline on numpy images.
//!
//! Everything goes through the same library calls as the `tubeloc` command line (the
//! [`tubeloc_pipeline::Locator`], built with the CLI's defaults by
//! [`tubeloc_pipeline::shipped`]), so that `Locator.locate` returns the poses `tubeloc locate`
//! writes for the same inputs, to the bit. Errors are raised as `tubeloc.TubelocError` (a
//! `ValueError`) with the CLI's messages.
//!
//! Frames and units as everywhere in tubeloc: camera frame OpenCV (x right, y down, z
//! forward), metres; pixel centres at integer coordinates.
#![warn(missing_docs)]

use pyo3::prelude::*;

mod coco;
mod error;
mod image_array;
mod locator;
mod poses;
mod rig;

pub use error::TubelocError;

/// keep_freed_memory() -> bool
///
/// Sets this process's C allocator (glibc) to keep freed memory for reuse, as the `tubeloc`
/// command does at start (`tubeloc_core::heap::keep_freed_memory`): large blocks come from
/// the heap and freed heap tops are kept rather than returned to the kernel. The learned
/// detector's layers then reuse their buffers instead of faulting in fresh zeroed pages: on
/// full-resolution Navcam frames it runs about 2.5 times faster. It changes the policy of the
/// whole Python process (memory freed by other libraries is kept too), so it is not done on
/// import; call it once, early, in a process that runs tubeloc on large frames. Returns False
/// where it does not apply (not glibc).
#[pyfunction]
fn keep_freed_memory() -> bool {
    tubeloc_core::heap::keep_freed_memory()
}

/// The `tubeloc` Python module.
#[pymodule]
fn tubeloc(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    m.add("TubelocError", m.py().get_type::<TubelocError>())?;
    m.add_class::<rig::PyRig>()?;
    m.add_class::<poses::PyTube>()?;
    m.add_class::<locator::PyLocator>()?;
    m.add_function(wrap_pyfunction!(rig::read_rig, m)?)?;
    m.add_function(wrap_pyfunction!(rig::read_pds_grounds, m)?)?;
    m.add_function(wrap_pyfunction!(rig::write_rig, m)?)?;
    m.add_function(wrap_pyfunction!(rig::assumed_view, m)?)?;
    m.add_function(wrap_pyfunction!(rig::view_of_product, m)?)?;
    m.add_function(wrap_pyfunction!(image_array::read_image, m)?)?;
    m.add_function(wrap_pyfunction!(image_array::read_product, m)?)?;
    m.add_function(wrap_pyfunction!(locator::detect, m)?)?;
    m.add_function(wrap_pyfunction!(locator::refine, m)?)?;
    m.add_function(wrap_pyfunction!(coco::coco_eval, m)?)?;
    m.add_function(wrap_pyfunction!(poses::pose_evidence, m)?)?;
    m.add_function(wrap_pyfunction!(keep_freed_memory, m)?)?;
    Ok(())
}
