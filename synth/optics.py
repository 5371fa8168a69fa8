"""Camera geometry for synthetic images: scene plane -> ideal pinhole image -> sensor pixels.

Conventions: pixel centres at integer coordinates, x to the right (columns), y down (rows),
principal point at the image centre ((W-1)/2, (H-1)/2). Scene coordinates are pixels of an
ideal square-pixel, unrolled camera, relative to the principal point.

The mapping (scene -> sensor) is

    p_img  = Rot(roll) . p_scene
    x_n    = p_img / f                           (normalised, OpenCV convention)
    x_d    = x_n (1 + k1 r^2 + k2 r^4) + tangential(p1, p2)   (Brown-Conrady, OpenCV's)
    p_sens = S f x_d + c + pp_offset             (S = diag(1, aspect): non-square pixels)

Non-square pixels scale the sensor's rows after the lens (fy = aspect fx, as OpenCV's camera
matrix); the principal point may sit ``pp_offset_px`` from the image centre.

This module is independent of the measurement packages on purpose: it is the "truth" side.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from axisbase.fixedpoint import iterate_elementwise


@dataclass(frozen=True)
class CameraGeometry:
    """Geometry of the synthetic camera.

    Attributes
    ----------
    focal_px : float
        Focal length in pixels (used only to normalise the distortion model).
    k1, k2, k3 : float
        OpenCV radial distortion coefficients (dimensionless, normalised coordinates; k3
        the r^6 term of a real wide lens's calibration).
    roll_rad : float
        Rotation of the sensor about the optical axis [rad]; positive turns scene features
        counter-clockwise as displayed.
    aspect : float
        Pixel aspect ratio: image y scale / image x scale (1 = square pixels).
    p1, p2 : float
        OpenCV tangential (decentring) distortion coefficients.
    pp_offset_px : (float, float)
        Principal point minus image centre (x, y) [px].
    """

    focal_px: float = 2000.0
    k1: float = 0.0
    k2: float = 0.0
    roll_rad: float = 0.0
    aspect: float = 1.0
    p1: float = 0.0
    p2: float = 0.0
    pp_offset_px: tuple[float, float] = (0.0, 0.0)
    k3: float = 0.0

    @property
    def is_identity(self) -> bool:
        return (self.k1 == 0 and self.k2 == 0 and self.roll_rad == 0 and self.aspect == 1
                and self.p1 == 0 and self.p2 == 0 and tuple(self.pp_offset_px) == (0.0, 0.0)
                and self.k3 == 0)

    @property
    def _lens_free(self) -> bool:
        return (self.k1 == 0 and self.k2 == 0 and self.p1 == 0 and self.p2 == 0
                and self.k3 == 0)

    def scene_to_ideal(self, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Scene plane -> undistorted (pinhole) pixel coordinates, both relative to centre."""
        # Displayed counter-clockwise is a negative rotation in the y-down frame.
        c, s = np.cos(self.roll_rad), np.sin(self.roll_rad)
        xi = c * x + s * y
        yi = -s * x + c * y
        return xi, yi

    def ideal_to_scene(self, xi: np.ndarray, yi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        c, s = np.cos(self.roll_rad), np.sin(self.roll_rad)
        return c * xi - s * yi, s * xi + c * yi

    def _lens(self, xn: np.ndarray, yn: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Brown-Conrady in normalised coordinates (OpenCV's k1, k2, p1, p2, k3)."""
        r2 = xn * xn + yn * yn
        g = 1.0 + self.k1 * r2 + self.k2 * r2 * r2
        if self.k3:  # (the same bits without it)
            g = g + self.k3 * r2 * r2 * r2
        return (xn * g + 2 * self.p1 * xn * yn + self.p2 * (r2 + 2 * xn * xn),
                yn * g + self.p1 * (r2 + 2 * yn * yn) + 2 * self.p2 * xn * yn)

    def distort(self, xi: np.ndarray, yi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Ideal pixel (relative to the principal point) -> sensor pixel (relative to the
        image centre)."""
        f = self.focal_px
        xd, yd = self._lens(xi / f, yi / f)
        ox, oy = self.pp_offset_px
        return f * xd + ox, f * self.aspect * yd + oy

    def undistort(self, xd: np.ndarray, yd: np.ndarray, iters: int = 12
                  ) -> tuple[np.ndarray, np.ndarray]:
        """Sensor pixel -> ideal pixel: exact to 1e-12 px (Newton on the radius for a radial
        lens; with tangential terms, Newton on both coordinates with the analytic Jacobian,
        as the inverse has no closed form)."""
        f = self.focal_px
        ox, oy = self.pp_offset_px
        xn, yn = (xd - ox) / f, (yd - oy) / (f * self.aspect)
        if self._lens_free:
            return f * xn, f * yn
        if self.p1 == 0 and self.p2 == 0:
            rd = np.hypot(xn, yn)
            rd_flat = rd.ravel()

            def radial(at: np.ndarray, ru: np.ndarray) -> tuple[np.ndarray]:
                r2 = ru * ru
                g = ru * (1 + self.k1 * r2 + self.k2 * r2 * r2) - rd_flat[at]
                dg = 1 + 3 * self.k1 * r2 + 5 * self.k2 * r2 * r2
                if self.k3:  # (the same bits without it)
                    g = g + self.k3 * ru * r2 * r2 * r2
                    dg = dg + 7 * self.k3 * r2 * r2 * r2
                return (ru - g / dg,)

            (ru,) = iterate_elementwise(radial, (rd,), iters)
            scale = np.where(rd > 0, ru / np.where(rd > 0, rd, 1.0), 1.0)
            return f * xn * scale, f * yn * scale
        xn, yn = np.broadcast_arrays(xn, yn)
        xn_flat, yn_flat = xn.ravel(), yn.ravel()
        h = 1e-7

        def both(at: np.ndarray, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, ...]:
            fx, fy = self._lens(x, y)
            ex, ey = fx - xn_flat[at], fy - yn_flat[at]
            ax, ay = self._lens(x + h, y)
            bx, by = self._lens(x, y + h)
            j11, j21 = (ax - fx) / h, (ay - fy) / h
            j12, j22 = (bx - fx) / h, (by - fy) / h
            det = j11 * j22 - j12 * j21
            return x - (j22 * ex - j12 * ey) / det, y - (-j21 * ex + j11 * ey) / det

        x, y = iterate_elementwise(both, (xn, yn), iters + 8)
        return f * x, f * y

    def sensor_to_scene(self, xd: np.ndarray, yd: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return self.ideal_to_scene(*self.undistort(xd, yd))

    def image_angle(self, scene_angle_rad: float) -> float:
        """Angle in the ideal pinhole image of a scene line at ``scene_angle_rad``.

        Angles are measured from +x towards -y (counter-clockwise as displayed), in (-pi/2, pi/2].
        Non-square pixels do not enter: they scale the sensor's rows after the lens, and the
        physical angle is the pinhole image's (square pixels), not the pixel grid's.
        """
        ux, uy = np.cos(scene_angle_rad), -np.sin(scene_angle_rad)
        xi, yi = self.scene_to_ideal(np.array(ux), np.array(uy))
        return wrap_half_turn(float(np.arctan2(-yi, xi)))


def wrap_half_turn(angle_rad: float) -> float:
    """Wrap a line direction to (-pi/2, pi/2].

    Parameters
    ----------
    angle_rad : float
        A line's direction [rad].

    Returns
    -------
    float
        The same line's direction in (-pi/2, pi/2] [rad].
    """
    a = (angle_rad + np.pi / 2) % np.pi - np.pi / 2
    return float(np.pi / 2 if a == -np.pi / 2 else a)
