"""What a synthetic scribe-mark image shows (:mod:`synth.marks` renders it): the marks and
the scene, camera and sensor settings (:class:`MarkSpec`, :class:`ImageSpec`), and the truth
that comes with each render (:class:`MarkTruth`, :class:`ImageTruth`, :class:`SynthImage`).

Units: lengths in pixels, angles in radians, signal in electrons (e-) or digital numbers (DN).
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass, field, replace

import numpy as np

from synth.optics import CameraGeometry

PROFILES = ("box", "v", "round")


@dataclass(frozen=True)
class MarkSpec:
    """One scribe mark in the scene plane (pixels of the ideal camera, relative to centre).

    Attributes
    ----------
    angle_rad : float
        Direction of the mark from +x towards -y (counter-clockwise as displayed) [rad].
    offset_px : float
        Signed distance of the mark's line from the image centre along the normal
        (sin a, cos a) in (x right, y down) coordinates [px].
    length_px : float
        Length of the groove [px].
    width_px : float
        Width of the groove at the surface [px].
    centre_t_px : float
        Position of the mark's middle along its direction (cos a, -sin a), measured from the
        foot of the perpendicular from the image centre [px].
    profile : str
        Depth profile across the groove: ``box``, ``v`` or ``round``.
    contrast : float
        Change of reflectance at full depth, relative to the surface (-0.6: a groove that
        reflects 40 % of the surface's light; +1.0: a bright groove twice as bright).
    bow_px : float
        A physically bent mark: sagitta of the groove's centre line from the chord between
        its ends, at the middle, along +normal [px] (0: straight). The chord keeps
        ``angle_rad`` and ``offset_px``, so the truth of a bent mark is its end-to-end
        direction.
    bow_shape : str
        ``parabola`` (sagitta x (1 - (2t/L)^2)), ``arc`` (a circular arc through the ends) or
        ``s`` (one sine period along the mark, amplitude the sagitta: an S whose ends and
        middle lie on the chord).
    """

    angle_rad: float
    offset_px: float
    length_px: float
    width_px: float = 4.0
    centre_t_px: float = 0.0
    profile: str = "round"
    contrast: float = -0.6
    bow_px: float = 0.0
    bow_shape: str = "parabola"

    def bow(self, t: np.ndarray) -> np.ndarray:
        """The centre line's displacement from the chord along the normal at ``t`` (from the
        mark's middle along it) [px]; 0 beyond the ends' reach is irrelevant (the along
        profile ends the groove there)."""
        s, half = self.bow_px, self.length_px / 2
        if s == 0:
            return np.zeros_like(t)
        tc = np.clip(t, -half, half)
        if self.bow_shape == "parabola":
            return s * (1 - (tc / half) ** 2)
        if self.bow_shape == "s":
            return s * np.sin(np.pi * tc / half)
        if self.bow_shape != "arc":
            raise ValueError(f"unknown bow shape {self.bow_shape!r}; use parabola, arc or s")
        rho = (half**2 + s**2) / (2 * abs(s))  # radius of the arc through both ends
        return np.sign(s) * (np.sqrt(rho**2 - tc**2) - (rho - abs(s)))

    def centre_xy(self) -> tuple[float, float]:
        a = self.angle_rad
        return (self.offset_px * np.sin(a) + self.centre_t_px * np.cos(a),
                self.offset_px * np.cos(a) - self.centre_t_px * np.sin(a))


@dataclass(frozen=True)
class ImageSpec:
    """Everything that makes one synthetic image (all randomness from ``seed``).

    Signal: the bare surface at full illumination collects ``exposure * full_well_e``
    electrons; ``bits`` (8, 12 or 16; 12-bit data in 16-bit words) sets the ADC (full scale
    = full well). Clutter: ``dust`` specks, ``scratches`` (thin, up to ``scratch_max_px`` long;
    0: 15 % of the smaller side), ``text`` printed labels of 2-4 numeral-like glyphs, and
    ``padding_px`` rows/columns of zeros along the frame edges (a driver's padding).

    Imaging effects: ``blur_gradient`` (gx, gy) the change of the PSF's sigma [px] per px of
    image x / y from the centre (defocus across the field; the local sigma is ``blur_px`` +
    gx x + gy y, at least 0.2 px); ``column_fpn``, ``row_fpn`` the standard deviation of the
    per-column / per-row read-out offsets, as a fraction of the bare surface's signal
    (``exposure * full_well_e``), drawn once from the seed's own stream; ``jpeg_quality``
    (1-100, 0: none) encodes the 8-bit image as a baseline JPEG and decodes it.

    Oriented stripes (a turned, ground or milled surface's lay; a woven or knurled one):
    the surface's reflectance, groove included, times 1 + ``stripes`` sin(2 pi q / P + phase)
    + ``stripes`` ``stripes_second`` sin(4 pi q / P + 2 phase), q the distance across the
    crests, which run at ``stripes_angle_rad`` (the marks' convention), P
    ``stripes_period_px``; ``stripes_phase`` [rad].

    Attributes
    ----------
    marks : tuple of MarkSpec
        The scribe marks in the scene.
    width, height : int
        Image size [px].
    blur_px : float
        Sigma of the optics' Gaussian PSF [px].
    exposure : float
        Bare surface's signal as a fraction of the full well — dimensionless.
    full_well_e : float
        Full well [e-] (the ADC's full scale).
    read_noise_e : float
        Read noise [e-] RMS.
    bits : int
        ADC bits: 8, 12 or 16.
    supersample : int
        Sub-samples per pixel side for the area integral of the groove.
    texture : float
        RMS of the machining streaks' relative reflectance — dimensionless (0: none).
    texture_angle_rad : float
        Direction of the streaks (the lay) [rad].
    texture_scale_px : float
        Correlation length of the streaks across the lay [px].
    gradient : tuple of float
        Illumination gradient (gx, gy): relative change from the centre to the right / bottom
        edge — dimensionless.
    vignetting : float
        Relative fall-off of the illumination at the corners — dimensionless.
    dust : int
        Dust specks anywhere in the frame.
    dust_on_mark : int
        Dust specks placed on the marks.
    scratches : int
        Thin short scratches.
    scratch_max_px : float
        Longest scratch [px] (0: 15 % of the smaller side).
    text : int
        Printed labels of 2-4 numeral-like glyphs.
    padding_px : int
        Rows / columns of zeros along the frame edges [px].
    camera : CameraGeometry
        Distortion, roll, aspect and principal point of the camera.
    seed : int
        Seed of every random draw.
    blur_gradient : tuple of float
        Change of the PSF's sigma per px of image x / y from the centre [px/px].
    column_fpn, row_fpn : float
        RMS of the per-column / per-row offsets, relative to the bare surface's signal.
    jpeg_quality : int
        Baseline JPEG quality 1-100 of an 8-bit image (0: no JPEG).
    stripes : float
        Relative amplitude of the oriented stripes — dimensionless (0: none).
    stripes_period_px : float
        Their period P [px].
    stripes_angle_rad : float
        Direction of their crests [rad].
    stripes_phase : float
        Their phase [rad].
    stripes_second : float
        Relative amplitude of their second harmonic — dimensionless.
    shadow : tuple of float
        A shadow's edge across the face (angle [rad], offset [px], width [px], depth): the edge
        runs along (cos a, -sin a) at ``offset`` from the centre along its normal
        (sin a, cos a); beyond it the light is multiplied by 1 - depth; the penumbra is an
        error function of sigma ``width`` (depth 0: no shadow).
    """

    marks: tuple[MarkSpec, ...]
    width: int = 1024
    height: int = 768
    blur_px: float = 1.2
    exposure: float = 0.5
    full_well_e: float = 20000.0
    read_noise_e: float = 10.0
    bits: int = 16
    supersample: int = 6
    texture: float = 0.0
    texture_angle_rad: float = 0.3
    texture_scale_px: float = 1.5
    gradient: tuple[float, float] = (0.0, 0.0)
    vignetting: float = 0.0
    dust: int = 0
    dust_on_mark: int = 0
    scratches: int = 0
    scratch_max_px: float = 0.0
    text: int = 0
    padding_px: int = 0
    camera: CameraGeometry = field(default_factory=CameraGeometry)
    seed: int = 0
    blur_gradient: tuple[float, float] = (0.0, 0.0)
    column_fpn: float = 0.0
    row_fpn: float = 0.0
    jpeg_quality: int = 0
    stripes: float = 0.0
    stripes_period_px: float = 30.0
    stripes_angle_rad: float = 0.0
    stripes_phase: float = 0.0
    stripes_second: float = 0.0
    shadow: tuple[float, float, float, float] = (0.0, 0.0, 1.0, 0.0)

    def blur_at(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """The PSF's sigma [px] at sensor pixel (x, y) relative to the image centre."""
        gx, gy = self.blur_gradient
        return np.maximum(self.blur_px + gx * x + gy * y, 0.2)

    def with_marks(self, *marks: MarkSpec) -> ImageSpec:
        return replace(self, marks=tuple(marks))


@dataclass(frozen=True)
class MarkTruth:
    """Truth of one mark as the camera sees it.

    ``angle_rad``/``offset_px``: in the scene; ``image_angle_rad``/``image_offset_px``: the
    same line in the ideal (undistorted) pinhole image, i.e. after roll and non-square pixels
    (what a single image can reveal). ``crlb_angle_rad``: Cramér–Rao bound on the angle.

    Attributes
    ----------
    angle_rad : float
        Direction of the mark in the scene, wrapped to (-pi/2, pi/2] [rad].
    offset_px : float
        Signed distance of the line from the image centre in the scene [px].
    image_angle_rad : float
        Direction of the same line in the ideal pinhole image [rad].
    image_offset_px : float
        Its signed distance from the image centre there [px].
    length_px, width_px : float
        Length and width of the groove [px].
    centre_xy_px : tuple of float
        The mark's middle (x, y) relative to the image centre [px].
    profile : str
        Shape of the groove across it ('box', 'v', 'round').
    contrast : float
        Relative depth of the groove (negative: darker than the surface) — dimensionless.
    crlb_angle_rad : float
        Cramér–Rao bound on the angle [rad] (NaN when not computed).
    crlb_offset_px : float
        Cramér–Rao bound on the offset [px] (NaN when not computed).
    """

    angle_rad: float
    offset_px: float
    image_angle_rad: float
    image_offset_px: float
    length_px: float
    width_px: float
    centre_xy_px: tuple[float, float]
    profile: str
    contrast: float
    crlb_angle_rad: float
    crlb_offset_px: float


@dataclass(frozen=True)
class ImageTruth:
    """Truth of a synthetic image (what ``<stem>.truth.json`` holds).

    Attributes
    ----------
    width, height : int
        Image size [px].
    blur_px : float
        Sigma of the PSF [px].
    bits : int
        ADC bits.
    noise_dn_background : float
        Noise of the bare surface (shot + read) [DN].
    contrast_dn : tuple of float
        Each mark's contrast [DN].
    snr : tuple of float
        Each mark's contrast / background noise — dimensionless.
    marks : tuple of MarkTruth
        Each mark's truth.
    camera : dict
        The camera geometry (:class:`CameraGeometry` as a dict).
    seed : int
        The image's seed.
    """

    width: int
    height: int
    blur_px: float
    bits: int
    noise_dn_background: float
    contrast_dn: tuple[float, ...]
    snr: tuple[float, ...]
    marks: tuple[MarkTruth, ...]
    camera: dict
    seed: int

    def to_json(self) -> str:
        return json.dumps(asdict(self), indent=2)


@dataclass(frozen=True)
class SynthImage:
    """A rendered image with its truth.

    Attributes
    ----------
    image : ndarray
        The digitised image (height, width) [DN]: uint8 or uint16.
    truth : ImageTruth
        What it shows.
    mean_e : ndarray
        The noise-free expected signal per pixel [e-].
    """

    image: np.ndarray
    truth: ImageTruth
    mean_e: np.ndarray
