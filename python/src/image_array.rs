//! numpy arrays as images: `uint8` or `uint16`, shape `HxW` (grey), `HxWx1`, `HxWx2` (grey and
//! alpha), `HxWx3` (RGB) or `HxWx4` (RGBA), in any memory order. The array becomes the image a
//! file of that type decodes to, so it goes through the same input conversion as files
//! (`tubeloc_detect::input`).

use crate::error::to_py;
use image::{DynamicImage, ImageBuffer};
use numpy::{PyArrayDyn, PyArrayMethods, PyUntypedArray, PyUntypedArrayMethods};
use pyo3::prelude::*;

/// The image of a numpy array (one copy: a memcpy for C-contiguous arrays, else element by element in row-major
/// order); `what` names the argument in errors.
pub fn image_of(obj: &Bound<'_, PyAny>, what: &str) -> PyResult<DynamicImage> {
    let shape_err = |shape: &[usize], dtype: &str| to_py(format!("{what}: expected a uint8 or uint16 array of shape HxW, HxWx1, HxWx2, HxWx3 or HxWx4, got a {dtype} array of shape {shape:?}"));
    let Ok(arr) = obj.cast::<PyUntypedArray>() else {
        return Err(to_py(format!("{what}: expected a numpy array, got {}", obj.get_type().name()?)));
    };
    let shape = arr.shape().to_vec();
    let dtype = arr.dtype().to_string();
    let (h, w, c) = match shape[..] {
        [h, w] => (h, w, 1),
        [h, w, c] if (1..=4).contains(&c) => (h, w, c),
        _ => return Err(shape_err(&shape, &dtype)),
    };
    if h == 0 || w == 0 || h > u32::MAX as usize || w > u32::MAX as usize {
        return Err(to_py(format!("{what}: the image is empty or too large (shape {shape:?})")));
    }
    let (w32, h32) = (w as u32, h as u32);
    if let Ok(a) = obj.cast::<PyArrayDyn<u8>>() {
        let ro = a.readonly();
        let data: Vec<u8> = if ro.is_c_contiguous() { ro.as_slice().map(<[u8]>::to_vec).ok() } else { None }.unwrap_or_else(|| ro.as_array().iter().copied().collect());
        return Ok(match c {
            1 => DynamicImage::ImageLuma8(ImageBuffer::from_raw(w32, h32, data).expect("size")),
            2 => DynamicImage::ImageLumaA8(ImageBuffer::from_raw(w32, h32, data).expect("size")),
            3 => DynamicImage::ImageRgb8(ImageBuffer::from_raw(w32, h32, data).expect("size")),
            _ => DynamicImage::ImageRgba8(ImageBuffer::from_raw(w32, h32, data).expect("size")),
        });
    }
    if let Ok(a) = obj.cast::<PyArrayDyn<u16>>() {
        let ro = a.readonly();
        let data: Vec<u16> = if ro.is_c_contiguous() { ro.as_slice().map(<[u16]>::to_vec).ok() } else { None }.unwrap_or_else(|| ro.as_array().iter().copied().collect());
        return Ok(match c {
            1 => DynamicImage::ImageLuma16(ImageBuffer::from_raw(w32, h32, data).expect("size")),
            2 => DynamicImage::ImageLumaA16(ImageBuffer::from_raw(w32, h32, data).expect("size")),
            3 => DynamicImage::ImageRgb16(ImageBuffer::from_raw(w32, h32, data).expect("size")),
            _ => DynamicImage::ImageRgba16(ImageBuffer::from_raw(w32, h32, data).expect("size")),
        });
    }
    Err(shape_err(&shape, &dtype))
}

/// The pixels of an image as a numpy array (uint8 or uint16; `HxW` grey, `HxWx2`, `HxWx3` or
/// `HxWx4`).
pub fn array_of<'py>(py: Python<'py>, img: &DynamicImage) -> Bound<'py, PyAny> {
    use DynamicImage as D;
    let (h, w) = (img.height() as usize, img.width() as usize);
    let c = img.color().channel_count() as usize;
    let dims: Vec<usize> = if c == 1 { vec![h, w] } else { vec![h, w, c] };
    let reshape = |a: Bound<'py, PyAny>| a.call_method1("reshape", (dims.clone(),)).expect("reshape to the image's own size");
    match img {
        D::ImageLuma16(_) | D::ImageLumaA16(_) | D::ImageRgb16(_) | D::ImageRgba16(_) => {
            let v: Vec<u16> = match img {
                D::ImageLuma16(b) => b.as_raw().clone(),
                D::ImageLumaA16(b) => b.as_raw().clone(),
                D::ImageRgb16(b) => b.as_raw().clone(),
                D::ImageRgba16(b) => b.as_raw().clone(),
                _ => unreachable!(),
            };
            reshape(numpy::PyArray1::from_vec(py, v).into_any())
        }
        D::ImageLuma8(b) => reshape(numpy::PyArray1::from_slice(py, b.as_raw()).into_any()),
        D::ImageLumaA8(b) => reshape(numpy::PyArray1::from_slice(py, b.as_raw()).into_any()),
        D::ImageRgba8(b) => reshape(numpy::PyArray1::from_slice(py, b.as_raw()).into_any()),
        _ => reshape(numpy::PyArray1::from_vec(py, img.to_rgb8().into_raw()).into_any()),
    }
}

/// read_image(path) -> numpy.ndarray
///
/// Decodes an image file (PNG, JPEG, TIFF, PGM / PPM / PNM, BMP, WebP, or a PDS3 product:
/// `.IMG`, or a `.LBL` beside its data) with the decoder `tubeloc` uses: uint8 or uint16, shape
/// HxW (grey), HxWx2, HxWx3 (RGB) or HxWx4 (RGBA), as stored in the file.
#[pyfunction]
pub fn read_image<'py>(py: Python<'py>, path: std::path::PathBuf) -> PyResult<Bound<'py, PyAny>> {
    let img = py.detach(|| tubeloc_detect::input::open_image(&path)).map_err(|e| to_py(format!("cannot read image {}: {e}", path.display())))?;
    Ok(array_of(py, &img))
}

/// A product as Python gets it: the image array, the rig and the ground `(nx, ny, nz, d)`.
pub type Product<'py> = (Bound<'py, PyAny>, crate::rig::PyRig, (f64, f64, f64, f64));

/// read_product(path) -> tuple[numpy.ndarray, Rig, tuple[float, float, float, float]]
///
/// Reads a PDS3 product (an `.IMG` with its label at the head, or a `.LBL` beside its data) as
/// `tubeloc locate --rig F --image F` reads it: the image as stored (uint8 or uint16), the
/// one-camera rig of its label (its CAHV / CAHVOR model linearized, named after PRODUCT_ID,
/// in the rover frame) and the ground under it (nx, ny, nz, d; camera frame, n up, n·X = d).
/// A fisheye (CAHVORE) product's image comes back resampled into the rig camera, the
/// model's linear part, so that the three go together into `Locator.locate`.
#[pyfunction]
pub fn read_product<'py>(py: Python<'py>, path: std::path::PathBuf) -> PyResult<Product<'py>> {
    use tubeloc_calib::interchange::{linearize::LinearResampling, pds, pds_label};
    let (cam, img) = py.detach(|| -> PyResult<_> {
        let (cam, fisheye) = pds_label::read_resampled_label_camera(&path).map_err(|e| crate::error::chain_to_py(&e))?.ok_or_else(|| to_py(format!("{}: not a PDS3 product (an .IMG with its label at the head, or a .LBL)", path.display())))?;
        let img = tubeloc_detect::input::open_image(&path).map_err(|e| to_py(format!("cannot read image {}: {e}", path.display())))?;
        let img = match fisheye {
            Some(m) => LinearResampling::new(&m, &cam.camera, (img.width(), img.height())).apply(&img),
            None => img,
        };
        Ok((cam, img))
    })?;
    let g = cam.ground;
    Ok((array_of(py, &img), crate::rig::PyRig { rig: pds::rig_of(std::slice::from_ref(&cam)) }, (g.normal.x, g.normal.y, g.normal.z, g.offset)))
}
