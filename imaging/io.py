"""Reading images as float arrays with clear errors (8/16-bit PNG, TIFF, JPEG; colour -> gray)."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from imaging.errors import ImageInputError


def read_image(path: str | Path) -> np.ndarray:
    """Read a grayscale image as float64 digital numbers (DN), keeping 16-bit depth.

    Colour images are converted with OpenCV's luminance weights. Raises
    :class:`ImageInputError` naming the file and the reason for anything unreadable.
    """
    p = Path(path)
    if not p.exists():
        raise ImageInputError(f"{p}: no such file")
    if p.is_dir():
        raise ImageInputError(f"{p}: is a folder, not an image")
    img = None
    if p.suffix.lower() in (".tif", ".tiff"):
        img = _read_tiff(p)
    else:
        data = np.fromfile(p, dtype=np.uint8)
        if data.size:
            # IMREAD_UNCHANGED: the default flag silently turns 16-bit into 8-bit BGR.
            img = cv2.imdecode(data, cv2.IMREAD_UNCHANGED)
    if img is None:
        raise ImageInputError(f"{p}: not an image, or truncated/corrupt (OpenCV cannot decode it)")
    img = np.asarray(img)
    if img.ndim == 3:
        if img.shape[2] == 4:
            img = img[..., :3]
        if img.shape[2] == 3:
            img = cv2.cvtColor(img, cv2.COLOR_BGR2GRAY) if img.dtype != np.float64 else img.mean(2)
        else:
            img = img[..., 0]
    if img.ndim != 2:
        raise ImageInputError(f"{p}: unsupported image layout {img.shape}")
    if min(img.shape) < 16:
        raise ImageInputError(f"{p}: image is only {img.shape[1]}x{img.shape[0]} px, too small")
    return img.astype(np.float64)


def _read_tiff(p: Path) -> np.ndarray:
    """The single image of a TIFF file (compressed ones through imagecodecs); a stack of
    several pages is refused rather than read as one odd-shaped image."""
    import tifffile

    try:
        with tifffile.TiffFile(p) as tf:
            pages = len(tf.pages)
            if pages != 1:
                raise ImageInputError(f"{p}: a TIFF with {pages} pages; give one image per "
                                      "file (e.g. split the stack)")
            return tf.pages[0].asarray()
    except ImageInputError:
        raise
    except Exception as exc:  # tifffile raises many types for corrupt or exotic files
        raise ImageInputError(f"{p}: unreadable TIFF ({exc})") from None


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
