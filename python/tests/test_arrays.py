"""numpy images: dtypes and shapes go through the same input conversion as image files."""

from pathlib import Path

import numpy as np
import pytest

import tubeloc


@pytest.fixture(scope="module")
def scene(demo_scene):
    rig, image, ground = demo_scene
    locator = tubeloc.Locator(str(rig))
    img = tubeloc.read_image(image)
    return locator, img, ground


def poses(locator, img, ground):
    return [t.to_dict() for t in locator.locate(img, ground=ground)]


def test_read_image_gives_the_file_pixels(demo_scene):
    _, image, _ = demo_scene
    img = tubeloc.read_image(image)
    assert img.dtype == np.uint8 and img.ndim == 3 and img.shape[2] in (3, 4)
    assert img.std() > 1.0


def test_sixteen_bit_full_range_equals_eight_bit(scene):
    locator, img, ground = scene
    assert poses(locator, img.astype(np.uint16) * 257, ground) == poses(locator, img, ground)


def test_twelve_bit_grey_equals_eight_bit_grey(scene):
    # A rover EDR's 12-bit data in a uint16 array: detection and refinement read them at their
    # real depth (16 v + 8 maps back to v), not divided by 257.
    locator, img, ground = scene
    grey = np.ascontiguousarray(img[..., 0])
    eight = poses(locator, grey, ground)
    assert any(t["converged"] for t in eight)
    assert poses(locator, grey.astype(np.uint16) * 16 + 8, ground) == eight


def test_rgba_with_opaque_alpha_equals_rgb(scene):
    locator, img, ground = scene
    rgb = img[..., :3]
    rgba = np.concatenate([rgb, np.full(rgb.shape[:2] + (1,), 255, np.uint8)], axis=2)
    assert poses(locator, rgba, ground) == poses(locator, np.ascontiguousarray(rgb), ground)


def test_grey_shapes_agree(scene):
    locator, img, ground = scene
    grey = np.ascontiguousarray(img[..., 1])
    assert poses(locator, grey[..., None], ground) == poses(locator, grey, ground)


def test_non_contiguous_arrays_equal_their_copies(scene):
    locator, img, ground = scene
    rgb = img[..., :3]
    fortran = np.asfortranarray(rgb)
    strided = np.repeat(rgb, 2, axis=1)[:, ::2]
    expected = poses(locator, np.ascontiguousarray(rgb), ground)
    assert poses(locator, fortran, ground) == expected
    assert poses(locator, strided, ground) == expected


@pytest.mark.parametrize(
    "array, described",
    [
        (np.zeros((8, 8), np.float64), "a float64 array of shape [8, 8]"),
        (np.zeros((8, 8, 5), np.uint8), "a uint8 array of shape [8, 8, 5]"),
        (np.zeros((2, 8, 8, 3), np.uint8), "a uint8 array of shape [2, 8, 8, 3]"),
        (np.zeros((8, 8, 3), np.int32), "a int32 array of shape [8, 8, 3]"),
    ],
)
def test_unsupported_arrays_are_refused_with_their_dtype_and_shape(scene, array, described):
    locator, _, _ = scene
    with pytest.raises(tubeloc.TubelocError) as e:
        locator.locate(array)
    assert str(e.value) == f"left: expected a uint8 or uint16 array of shape HxW, HxWx1, HxWx2, HxWx3 or HxWx4, got {described}"


def test_a_list_is_not_an_image(scene):
    locator, _, _ = scene
    with pytest.raises(tubeloc.TubelocError, match="left: expected a numpy array, got list"):
        locator.locate([[0, 1], [2, 3]])


def test_a_truncated_jpeg_is_refused_naming_the_file(tmp_path):
    # A JPEG cut short decodes to an image with blank rows; read_image refuses it instead.
    photos = Path(__file__).resolve().parents[2].parent / "shared/data/apriltag/apriltag_test_data"
    whole = sorted(photos.glob("*.jpg"))
    if not whole:
        pytest.skip(f"{photos} is absent")
    data = whole[0].read_bytes()
    assert tubeloc.read_image(whole[0]).std() > 1.0
    cut = tmp_path / "cut.jpg"
    cut.write_bytes(data[: len(data) // 2])
    with pytest.raises(tubeloc.TubelocError, match=r"cut\.jpg.*truncated"):
        tubeloc.read_image(cut)


def _grey16_tiff(path, a):
    """A baseline TIFF (little endian, one strip, no compression) of a uint16 HxW array."""
    import struct

    h, w = a.shape
    data = np.ascontiguousarray(a, dtype="<u2").tobytes()
    entries = [(256, 3, 1, w), (257, 3, 1, h), (258, 3, 1, 16), (259, 3, 1, 1), (262, 3, 1, 1),
               (273, 4, 1, 8), (277, 3, 1, 1), (278, 3, 1, h), (279, 4, 1, len(data))]
    ifd = struct.pack("<H", len(entries))
    for tag, kind, count, value in entries:
        ifd += struct.pack("<HHI", tag, kind, count) + (struct.pack("<HH", value, 0) if kind == 3 else struct.pack("<I", value))
    ifd += struct.pack("<I", 0)
    path.write_bytes(b"II*\x00" + struct.pack("<I", 8 + len(data)) + data + ifd)


def test_a_sixteen_bit_tiff_reads_as_its_pixels(tmp_path):
    # 12-bit data in a 16-bit TIFF, as rover products are often converted: read as stored.
    a = (np.arange(37 * 53, dtype=np.uint32).reshape(37, 53) * 7 % 4096).astype(np.uint16)
    path = tmp_path / "edr.tif"
    _grey16_tiff(path, a)
    img = tubeloc.read_image(str(path))
    assert img.dtype == np.uint16 and img.shape == a.shape
    assert np.array_equal(img, a)


def test_read_image_decodes_a_pds3_product(tmp_path):
    # A 3x2 product as the PDS archives a Navcam frame: the label at the head, 12-bit data in
    # big-endian 16-bit samples from record 3 (records of 256 bytes).
    label = ("PDS_VERSION_ID = PDS3\nRECORD_TYPE = FIXED_LENGTH\nRECORD_BYTES = 256\n^IMAGE = 3\n"
             "OBJECT = IMAGE\n  LINES = 2\n  LINE_SAMPLES = 3\n  SAMPLE_TYPE = MSB_INTEGER\n"
             "  SAMPLE_BITS = 16\nEND_OBJECT = IMAGE\nEND\n").encode().ljust(512, b" ")
    data = np.array([[0, 100, 4095], [7, 2048, 1]], dtype=">i2")
    path = tmp_path / "frame.IMG"
    path.write_bytes(label + data.tobytes())
    img = tubeloc.read_image(path)
    assert img.dtype == np.uint16 and img.shape == (2, 3)
    assert (img == data.astype(np.uint16)).all()
    path.write_bytes(label + data.tobytes()[:-1])
    with pytest.raises(tubeloc.TubelocError, match="frame.IMG.*cut short"):
        tubeloc.read_image(path)
