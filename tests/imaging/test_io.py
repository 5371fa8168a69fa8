"""Reading images: a PNG's EXIF orientation wherever its eXIf chunk lies, found without
decoding the pixels twice when it has none."""

from __future__ import annotations

import io
import struct
from pathlib import Path

import numpy as np
import pytest
from PIL import Image, ImageFile

from imaging import ImageInputError, read_image_notes


def _chunks(data: bytes) -> list[bytes]:
    """A PNG's chunks, each whole (length, type, data, CRC), after the signature."""
    out, k = [], 8
    while k < len(data):
        size = struct.unpack(">I", data[k:k + 4])[0]
        out.append(data[k:k + 12 + size])
        k += 12 + size
    return out


def _png(path: Path, pixels: np.ndarray, orientation: int | None, where: str) -> Path:
    """A 16-bit gray PNG, with an eXIf chunk holding ``orientation`` before the pixel data
    (as Pillow writes it) or moved after it (``where`` = "after", allowed by the PNG spec)."""
    buf = io.BytesIO()
    exif = Image.Exif()
    if orientation is not None:
        exif[0x0112] = orientation
    Image.fromarray(pixels.astype(np.uint16)).save(
        buf, format="PNG", **({"exif": exif} if orientation is not None else {}))
    data = buf.getvalue()
    chunks = _chunks(data)
    if where == "after":
        ex = [c for c in chunks if c[4:8] == b"eXIf"]
        assert len(ex) == 1
        rest = [c for c in chunks if c[4:8] != b"eXIf"]
        chunks = rest[:-1] + ex + rest[-1:]  # just before IEND
    path.write_bytes(data[:8] + b"".join(chunks))
    return path


@pytest.fixture
def pixels() -> np.ndarray:
    return np.arange(40 * 24, dtype=float).reshape(24, 40) * 50


@pytest.mark.parametrize("where", ["before", "after"])
def test_png_exif_orientation_applied_wherever_its_chunk_lies(tmp_path, pixels, where):
    path = _png(tmp_path / "turned.png", pixels, 6, where)
    kinds = [c[4:8] for c in _chunks(path.read_bytes())]
    assert (kinds.index(b"eXIf") < kinds.index(b"IDAT")) == (where == "before")
    read = read_image_notes(path)
    np.testing.assert_array_equal(read.pixels, np.rot90(pixels, -1))
    assert any("orientation tag 6" in n for n in read.notes)


def test_png_without_exif_is_decoded_once(tmp_path, pixels, monkeypatch):
    """Pillow reads the header only: the pixels are decoded by OpenCV alone (Pillow used to
    decode every PNG in full looking for a trailing eXIf chunk: +90 ms per 5 MP image)."""
    path = _png(tmp_path / "plain.png", pixels, None, "before")

    def no_load(self):
        raise AssertionError("Pillow decoded the pixels")

    monkeypatch.setattr(ImageFile.ImageFile, "load", no_load)
    read = read_image_notes(path)
    np.testing.assert_array_equal(read.pixels, pixels)
    assert read.notes == ()


def test_truncated_png_is_one_line_error(tmp_path, pixels):
    """A PNG cut inside its pixel data: the chunk walk cannot tell, Pillow reads it and the
    truncation is reported in one line, as before."""
    path = _png(tmp_path / "cut.png", pixels, None, "before")
    path.write_bytes(path.read_bytes()[:-40])
    with pytest.raises(ImageInputError, match="cut.png"):
        read_image_notes(path)


def _frame(exposure: float) -> np.ndarray:
    from synth import ImageSpec, MarkSpec, render_marks
    spec = ImageSpec(marks=(MarkSpec(0.002, 3.0, 300.0, 4.0, contrast=-0.55),), width=480,
                     height=360, bits=12, exposure=exposure, vignetting=0.35, seed=2)
    return render_marks(spec, with_crlb=False).image


def test_over_exposed_frame_names_its_clipped_region_and_a_normal_one_does_not():
    """synth at 2.3x the usual exposure (the background clipped at 4095 over most of the
    frame, the groove's floor not): 'no mark found' names the clipping and where. The
    normal exposure: nothing said of clipping (clipped_note '' below 1 % at full scale)."""
    from imaging import measure_frame
    from imaging.io import clipped_note
    over = _frame(1.15)
    assert (over >= 4095).mean() > 0.3
    note = clipped_note(over, 4095.0)
    assert "clipped at 4095" in note and "12-bit" in note and "region" in note
    with pytest.raises(ImageInputError, match="no mark found") as exc:
        measure_frame(over)
    assert note in str(exc.value), exc.value
    assert clipped_note(_frame(0.5), 4095.0) == ""


def test_bit_depths_beyond_16_bits_and_bilevel_images_are_named(tmp_path, pixels):
    """A 32-bit integer or float image is read when its values fit a sensor's 0-65535 (a
    12-bit camera's counts in an int32 container) and refused by its depth when they do not
    (they would all read as clipped: "over-exposed"); a 1-bit image is refused as bilevel."""
    import tifffile

    fits = tmp_path / "i32_12bit.tif"
    tifffile.imwrite(fits, (pixels % 4096).astype(np.int32))
    read = read_image_notes(fits)
    assert np.array_equal(read.pixels, pixels % 4096) and read.notes == ()
    for dtype, scale in ((np.int32, 1000.0), (np.float32, 100.0)):
        wide = tmp_path / f"{np.dtype(dtype).name}.tif"
        tifffile.imwrite(wide, (pixels * scale).astype(dtype))
        with pytest.raises(ImageInputError, match=rf"{wide.name}: 32-bit .*beyond 0-65535"):
            read_image_notes(wide)
    bilevel_png = tmp_path / "bilevel.png"
    Image.fromarray(pixels > 20000).save(bilevel_png)
    bilevel_tif = tmp_path / "bilevel.tif"
    tifffile.imwrite(bilevel_tif, pixels > 20000)
    for f in (bilevel_png, bilevel_tif):
        with pytest.raises(ImageInputError, match=rf"{f.name}: a 1-bit \(bilevel\) image"):
            read_image_notes(f)


def test_planar_rgb_tiff_is_said_to_be_one_colour_page(tmp_path):
    """tifffile.imwrite of a (3, H, W) array writes one planar RGB page, not three frames:
    read as colour and turned grey, with a note saying so; a chunky RGB TIFF and a grey one
    get no such note."""
    tifffile = pytest.importorskip("tifffile")
    a = np.random.default_rng(0).integers(0, 255, (3, 24, 40), dtype=np.uint8)
    tifffile.imwrite(tmp_path / "planes.tif", a, photometric="rgb", planarconfig="separate")
    tifffile.imwrite(tmp_path / "chunky.tif", a.transpose(1, 2, 0))
    tifffile.imwrite(tmp_path / "grey.tif", a[0])
    got = read_image_notes(tmp_path / "planes.tif")
    assert got.pixels.shape == (24, 40)
    assert len(got.notes) == 1 and "planar RGB page" in got.notes[0], got.notes
    assert "turned grey" in got.notes[0]
    np.testing.assert_array_equal(got.pixels, read_image_notes(tmp_path / "chunky.tif").pixels)
    assert read_image_notes(tmp_path / "chunky.tif").notes == ()
    assert read_image_notes(tmp_path / "grey.tif").notes == ()


def test_a_jpegs_quantisation_table_is_read_from_its_header(tmp_path):
    """The luminance table (natural order) comes with the pixels; a PNG has none; a JPEG
    mirrored by its EXIF tag (100 px wide: 4 px of a block at the far edge) has its grid
    starting 4 px in."""
    from imaging.jpeg import ijg_table

    a = (np.random.default_rng(0).random((40, 100)) * 255).astype(np.uint8)
    Image.fromarray(a).save(tmp_path / "q60.jpg", quality=60)
    got = read_image_notes(tmp_path / "q60.jpg")
    assert got.jpeg_tables.luma == tuple(int(v) for v in ijg_table(60).ravel())
    assert got.jpeg_tables.phase == (0, 0)
    Image.fromarray(a).save(tmp_path / "a.png")
    assert read_image_notes(tmp_path / "a.png").jpeg_tables is None
    exif = Image.Exif()
    exif[0x0112] = 2  # mirrored left-right
    Image.fromarray(a).save(tmp_path / "m.jpg", quality=60, exif=exif)
    assert read_image_notes(tmp_path / "m.jpg").jpeg_tables.phase == (4, 0)
