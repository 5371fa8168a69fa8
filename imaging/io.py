"""Reading images as float arrays with clear errors (8/16-bit PNG, TIFF, JPEG; colour -> gray).

Before any pixel is decoded the header is read (Pillow for PNG/JPEG/BMP, tifffile for TIFF)
and the image's size checked against a pixel budget (:data:`DEFAULT_MAX_PIXELS`, settable with
``--max-pixels`` or the environment variable ``ALIGN_MAX_PIXELS``): a small file that declares
a huge image (a decompression bomb) is refused at once. The orientation a file declares (EXIF
in a JPEG, the TIFF Orientation tag) is applied, so the pixels are as the file shows them;
a planar-configuration TIFF is read as one colour image; signed integer data are offset to
unsigned. Whatever was done is said in :attr:`ImageRead.notes`.
"""

from __future__ import annotations

import os
import struct
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from imaging.errors import ImageInputError

DEFAULT_MAX_PIXELS = 100_000_000
"""Largest image read by default [pixels] (100 MP: any machine-vision sensor; 800 MB as
float64). A larger one is refused before decoding unless the budget is raised."""

MAX_PIXELS_ENV = "ALIGN_MAX_PIXELS"
"""Environment variable that sets the budget for this process and the processes it starts
(``--max-pixels`` sets it)."""

ORIENTATIONS = {1: "as stored", 2: "mirrored left-right", 3: "turned 180°",
                4: "mirrored top-bottom", 5: "transposed", 6: "turned 90° clockwise",
                7: "transversed", 8: "turned 90° counter-clockwise"}
"""The EXIF/TIFF Orientation values (TIFF 6.0 tag 274) and what applying them does."""


@dataclass(frozen=True)
class JpegTables:
    """What a JPEG file's header says of its encoder: the luminance quantisation table and
    where its 8x8 grid lies in the pixels as read.

    Attributes
    ----------
    luma : tuple of int
        The 64 steps of the luminance table (table 0), row-major (natural order) [DN of the
        orthonormal DCT].
    phase : tuple of int
        (x, y) of the grid's first block boundary in the pixels as read [px], 0-7: (0, 0)
        as stored; an orientation tag applied to a size not a multiple of 8 moves it.
    """

    luma: tuple[int, ...]
    phase: tuple[int, int] = (0, 0)

    def to_dict(self) -> dict:
        return {"luma": list(self.luma), "phase": list(self.phase)}

    @classmethod
    def from_dict(cls, d: dict) -> JpegTables:
        return cls(tuple(int(v) for v in d["luma"]), tuple(int(v) for v in d["phase"]))


@dataclass(frozen=True)
class ImageRead:
    """An image as read: ``pixels`` [DN] (float64, 2-D) and ``notes``, one sentence per
    thing the reader did to the stored data (orientation applied, signed data offset), and
    a JPEG's ``jpeg_tables`` from its header.

    Attributes
    ----------
    pixels : ndarray
        Grayscale pixels [DN], float64, 2-D.
    notes : tuple of str
        What was done to the stored data.
    jpeg_tables : JpegTables or None
        A JPEG file's quantisation (None: not a JPEG, or no table in its header).
    """

    pixels: np.ndarray
    notes: tuple[str, ...] = ()
    jpeg_tables: JpegTables | None = None


def max_pixels() -> int:
    """The pixel budget in force: ``ALIGN_MAX_PIXELS`` if set, else :data:`DEFAULT_MAX_PIXELS`."""
    raw = os.environ.get(MAX_PIXELS_ENV, "").strip()
    if not raw:
        return DEFAULT_MAX_PIXELS
    try:
        n = int(float(raw))
    except ValueError:
        raise ImageInputError(f"{MAX_PIXELS_ENV}={raw!r}: not a number of pixels") from None
    if n < 256:
        raise ImageInputError(f"{MAX_PIXELS_ENV}={raw!r}: at least 256 pixels")
    return n


def set_max_pixels(n: int | None) -> None:
    """Set the pixel budget for this process and the ones it starts (None: the default).

    Parameters
    ----------
    n : int or None
        Largest image [pixels]; None: :data:`DEFAULT_MAX_PIXELS`.
    """
    if n is None:
        os.environ.pop(MAX_PIXELS_ENV, None)
    else:
        os.environ[MAX_PIXELS_ENV] = str(int(n))


def read_image(path: str | Path) -> np.ndarray:
    """Read a grayscale image as float64 digital numbers (DN), keeping 16-bit depth.

    Colour images are converted with OpenCV's luminance weights. Raises
    :class:`ImageInputError` naming the file and the reason for anything unreadable. See
    :func:`read_image_notes` for what was done to the stored data.

    Parameters
    ----------
    path : str or Path
        The image file.

    Returns
    -------
    ndarray
        Grayscale pixels [DN], float64, 2-D.
    """
    return read_image_notes(path).pixels


def read_image_notes(path: str | Path, budget: int | None = None) -> ImageRead:
    """:func:`read_image` with the notes of what was done (orientation, signed offset).
    ``budget``: largest image [pixels] (default :func:`max_pixels`).

    Parameters
    ----------
    path : str or Path
        The image file.
    budget : int, optional
        Largest image [pixels].

    Returns
    -------
    ImageRead
        The pixels [DN] and the notes.

    Raises
    ------
    ImageInputError
        Naming the file and why it cannot be read (or is beyond the budget).
    """
    p = Path(path)
    if not p.exists():
        raise ImageInputError(f"{p}: no such file")
    if p.is_dir():
        raise ImageInputError(f"{p}: is a folder, not an image")
    budget = max_pixels() if budget is None else budget
    notes: list[str] = []
    luma = None
    if p.suffix.lower() in (".tif", ".tiff"):
        img, orientation, planar = _read_tiff(p, budget)
        if planar and img.ndim == 3 and img.shape[2] >= 3:
            # What tifffile.imwrite writes for a (3, H, W) array: one page, planar RGB, not
            # a stack of three frames; whoever meant three frames must hear it was one.
            notes.append(f"one planar RGB page ({img.shape[2]} planes of {img.shape[1]}x"
                         f"{img.shape[0]} px) read as a colour image and turned grey; if the "
                         "planes are separate frames, write them as pages of a stack or as "
                         "files")
    else:
        orientation, luma = _check_header(p, budget)
        data = np.fromfile(p, dtype=np.uint8)
        img = None
        if data.size:
            # IMREAD_UNCHANGED: the default flag silently turns 16-bit into 8-bit BGR (and it
            # ignores EXIF orientation, which is applied below, once, and said).
            img = cv2.imdecode(data, cv2.IMREAD_UNCHANGED)
    if img is None:
        raise ImageInputError(f"{p}: not an image, or truncated/corrupt (OpenCV cannot decode it)")
    img = np.asarray(img)
    if img.ndim == 3:
        if img.shape[2] == 4:
            img = img[..., :3]
        if img.shape[2] == 3:
            img = (cv2.cvtColor(img, cv2.COLOR_BGR2GRAY) if img.dtype in (np.uint8, np.uint16)
                   else img.astype(np.float64) @ np.array([0.114, 0.587, 0.299]))
        else:
            img = img[..., 0]
    if img.ndim != 2:
        raise ImageInputError(f"{p}: unsupported image layout {img.shape}")
    if min(img.shape) < 16:
        raise ImageInputError(f"{p}: image is only {img.shape[1]}x{img.shape[0]} px, too small")
    if img.dtype == bool:  # a bilevel TIFF (PNG's are refused from the header)
        raise ImageInputError(f"{p}: a 1-bit (bilevel) image: a mark's grey-level profile, "
                              "which the lines are fitted to, is not in it; give the camera's "
                              "grey-level image")
    out = img.astype(np.float64)
    wide = img.dtype.itemsize > 2 or img.dtype.kind == "f"
    # A signed 8/16-bit file is a sensor's range shifted by half; a wider signed container
    # holding a sensor's unsigned counts (a 12-bit camera's in int32) is read as it is.
    if np.issubdtype(img.dtype, np.signedinteger) and (not wide or float(out.min()) < 0):
        offset = float(-np.iinfo(img.dtype).min)
        out += offset
        notes.append(f"signed {img.dtype.itemsize * 8}-bit data offset by +{offset:.0f} DN "
                     "to unsigned")
    if wide:
        _within_16_bits(p, img.dtype, out)
    tables = None
    if luma is not None:
        tables = JpegTables(luma, _grid_phase_after(orientation, img.shape))
    if orientation not in (None, 1):
        out = _orient(out, orientation)
        notes.append(f"orientation tag {orientation} applied ({ORIENTATIONS[orientation]})")
    return ImageRead(out, tuple(notes), tables)


def _grid_phase_after(code: int | None, shape: tuple[int, ...]) -> tuple[int, int]:
    """(x, y) of the first 8x8 block boundary once orientation ``code`` is applied to a
    stored image of ``shape`` [px]: the stored grid starts at (0, 0); a mirror or a turn
    puts the far edge first, whose blocks start at the size modulo 8. Found by orienting
    the block labels of a small image with the same sizes modulo 8."""
    if code in (None, 1):
        return (0, 0)
    h, w = 16 + shape[0] % 8, 16 + shape[1] % 8
    yy, xx = np.mgrid[0:h, 0:w]
    lab = _orient((yy // 8 * 8 + xx // 8).astype(float), code)
    px = next((j for j in range(1, 9) if lab[0, j] != lab[0, j - 1]), 8) % 8
    py = next((i for i in range(1, 9) if lab[i, 0] != lab[i - 1, 0]), 8) % 8
    return (px, py)


def _within_16_bits(p: Path, dtype: np.dtype, out: np.ndarray) -> None:
    """Refuse data beyond 16 bits: the clipping level is the smallest sensor depth of
    :data:`BIT_DEPTHS` holding the data, and 32-bit or floating-point values past 65535 would
    all read as clipped (the file's depth named, not "over-exposed"). Data that fit, as a
    12-bit sensor's in a 32-bit container, are read as they are."""
    lo, hi = float(np.min(out)), float(np.max(out))
    if hi > 2.0**16 - 1 or lo < 0:
        kind = "floating-point" if dtype.kind == "f" else "integer"
        raise ImageInputError(
            f"{p}: {dtype.itemsize * 8}-bit {kind} data spanning {lo:.6g} to {hi:.6g}: beyond "
            "0-65535, the 8-16-bit sensor range the clipping level is read from; give the "
            "sensor's data (or scale it into 0-65535)")


def _orient(img: np.ndarray, code: int) -> np.ndarray:
    """``img`` as a viewer shows a file whose Orientation is ``code`` (TIFF 6.0 tag 274)."""
    return {2: lambda a: a[:, ::-1], 3: lambda a: a[::-1, ::-1], 4: lambda a: a[::-1, :],
            5: lambda a: a.T, 6: lambda a: np.rot90(a, -1), 7: lambda a: a[::-1, ::-1].T,
            8: lambda a: np.rot90(a, 1)}[code](img).copy()


def _budget(p: Path, w: int, h: int, budget: int) -> None:
    if w * h > budget:
        raise ImageInputError(
            f"{p}: declares {w}x{h} px ({w * h / 1e6:.3g} MP), over the pixel budget of "
            f"{budget / 1e6:g} MP; refused before decoding (raise it with --max-pixels if "
            "the image is genuine)")


def _check_header(p: Path, budget: int) -> tuple[int | None, tuple[int, ...] | None]:
    """Read only the header (Pillow opens lazily): size against ``budget``, the EXIF
    orientation (None when Pillow does not know the format: OpenCV then tries) and a JPEG's
    luminance quantisation table (64 steps, natural order; None: not a JPEG)."""
    from PIL import Image, UnidentifiedImageError

    # Pillow's own bomb guard (a warning, an error over twice 89 MP) gives way to ours,
    # which is settable and says so in one line.
    Image.MAX_IMAGE_PIXELS = None
    try:
        with Image.open(p) as im:
            w, h = im.size
            _budget(p, w, h, budget)
            # Pillow decodes a whole PNG to look for an eXIf chunk after the pixel data (as
            # long as OpenCV's decoding after it, at 5 MP): not when the chunks hold none.
            no_exif = im.format == "PNG" and "exif" not in im.info and not _png_has_exif(p)
            code = None if no_exif else im.getexif().get(0x0112)
            # Pillow gives the tables in natural (row-major) order; table 0 is the luma's.
            q = getattr(im, "quantization", None) if im.format == "JPEG" else None
            luma = tuple(int(v) for v in q[0]) if q and len(q.get(0, ())) == 64 else None
            if im.mode == "1":
                raise ImageInputError(
                    f"{p}: a 1-bit (bilevel) image: a mark's grey-level profile, which the "
                    "lines are fitted to, is not in it; give the camera's grey-level image")
    except UnidentifiedImageError:
        return None, None
    except OSError as exc:
        raise ImageInputError(f"{p}: unreadable image header ({exc})") from None
    if code is None:
        return None, luma
    if code not in ORIENTATIONS:
        raise ImageInputError(f"{p}: EXIF orientation {code} is not one of 1-8")
    return int(code), luma


def _png_has_exif(p: Path) -> bool:
    """Whether a PNG file may hold an eXIf chunk, from its chunk headers alone (the pixel data
    are skipped, not decompressed). Hand-written: Pillow reads chunks after the image data
    only by decoding it. A file that ends before IEND says "may" (Pillow then reads it and
    reports the truncation as before)."""
    with open(p, "rb") as f:
        f.seek(8)  # the signature (Pillow has identified the file as a PNG)
        while True:
            head = f.read(8)
            if len(head) < 8:
                return True
            size, kind = struct.unpack(">I4s", head)
            if kind == b"eXIf":
                return True
            if kind == b"IEND":
                return False
            f.seek(size + 4, os.SEEK_CUR)  # the data and the CRC


def _read_tiff(p: Path, budget: int) -> tuple[np.ndarray, int | None, bool]:
    """The single image of a TIFF file (compressed ones through imagecodecs) as rows x
    columns [x samples], its Orientation tag and whether its samples were stored as planes;
    a stack of several pages is refused rather than read as one odd-shaped image."""
    import tifffile

    try:
        with tifffile.TiffFile(p) as tf:
            pages = len(tf.pages)
            if pages != 1:
                raise ImageInputError(f"{p}: a TIFF with {pages} pages; give one image per "
                                      "file (e.g. split the stack)")
            page = tf.pages[0]
            axes, shape = page.axes, page.shape
            if "Y" in axes and "X" in axes:
                _budget(p, shape[axes.index("X")], shape[axes.index("Y")], budget)
            tag = page.tags.get(274)
            code = int(tag.value) if tag is not None else None
            img = page.asarray()
    except ImageInputError:
        raise
    except Exception as exc:  # tifffile raises many types for corrupt or exotic files
        raise ImageInputError(f"{p}: unreadable TIFF ({exc})") from None
    planar = axes == "SYX"
    if planar:  # planar configuration: one plane per sample -> rows x cols x samples
        img = np.moveaxis(img, 0, -1)
        axes = "YXS"
    if img.ndim == 3 and axes == "YXS" and img.shape[2] >= 3:
        img = img[..., 2::-1] if img.shape[2] == 3 else img[..., [2, 1, 0]]  # RGB -> OpenCV's BGR
    if code is not None and code not in ORIENTATIONS:
        raise ImageInputError(f"{p}: TIFF Orientation {code} is not one of 1-8")
    return img, code, planar


BIT_DEPTHS = (8, 10, 12, 14, 16)
"""Sensor bit depths: 10-, 12- and 14-bit data usually come in a 16-bit file."""


def full_scale(image: np.ndarray | float) -> float:
    """Full-scale DN guessed from the data range: the smallest 2^b - 1 of :data:`BIT_DEPTHS`
    that holds the maximum (255 for 8-bit data, 4095 for 12-bit data in a 16-bit file,
    65535 for 16-bit), so clipped pixels are recognised at any of these depths alike.
    ``image`` may also be its maximum already taken (a pass over 5 MP costs ~4 ms).

    (A 16-bit image that happens to peak exactly at 4095 loses only its pixels at that
    value, as if clipped: they say "at least this" either way.)
    """
    mx = float(np.max(image))
    return next((2.0**b - 1 for b in BIT_DEPTHS if mx <= 2**b - 1), 2.0**BIT_DEPTHS[-1] - 1)


def clipped_note(image: np.ndarray, top: float, least: float = 0.01) -> str:
    """Where the frame is clipped at full scale ``top`` [DN], when at least ``least`` of it
    is: the region (x0,y0–x1,y1, the box holding 98 % of the clipped pixels), the level and
    the share; '' otherwise. Said with "no mark found": an over-exposed background leaves a
    groove in it nothing to be read against, and the user must know it is the exposure."""
    hot = image >= top
    if float(hot.mean()) < least:
        return ""
    return clipped_region(hot, top) + ": over-exposed, expose less"


def clipped_region(hot: np.ndarray, top: float) -> str:
    """The clipped pixels ``hot`` (a mask with at least one True) of a frame whose full scale
    is ``top`` [DN], named: the box holding 98 % of them (x0,y0–x1,y1 [px]), the level, the
    share of the frame."""
    share = float(hot.mean())
    rows, cols = np.nonzero(hot)
    x0, x1 = np.percentile(cols, [1, 99]).astype(int)
    y0, y1 = np.percentile(rows, [1, 99]).astype(int)
    bits = int(np.log2(top + 1))
    return (f"region {x0},{y0}–{x1},{y1} is clipped at {top:.0f} (the {bits}-bit full scale; "
            f"{100 * share:.{0 if share >= 0.01 else 2}f} % of the frame)")
