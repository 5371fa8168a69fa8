"""Camera geometry for synthetic images: scene plane -> ideal pinhole image -> sensor pixels.

Conventions: pixel centres at integer coordinates, x to the right (columns), y down (rows),
principal point at the image centre ((W-1)/2, (H-1)/2). Scene coordinates are pixels of an
ideal square-pixel, unrolled camera, relative to the principal point.

The mapping (scene -> sensor) is

    p_img  = S . Rot(roll) . p_scene            (S = diag(1, aspect): non-square pixels)
    x_n    = p_img / f                           (normalised, OpenCV convention)
    x_d    = x_n (1 + k1 r^2 + k2 r^4)           (OpenCV's radial model)
    p_sens = f x_d + c

This module is independent of the measurement packages on purpose: it is the "truth" side.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class CameraGeometry:
    """Geometry of the synthetic camera.

    Attributes
    ----------
    focal_px : float
        Focal length in pixels (used only to normalise the distortion model).
    k1, k2 : float
        OpenCV radial distortion coefficients (dimensionless, normalised coordinates).
    roll_rad : float
        Rotation of the sensor about the optical axis [rad]; positive turns scene features
        counter-clockwise as displayed.
    aspect : float
        Pixel aspect ratio: image y scale / image x scale (1 = square pixels).
    """

    focal_px: float = 2000.0
    k1: float = 0.0
    k2: float = 0.0
    roll_rad: float = 0.0
    aspect: float = 1.0

    @property
    def is_identity(self) -> bool:
        return self.k1 == 0 and self.k2 == 0 and self.roll_rad == 0 and self.aspect == 1

    def scene_to_ideal(self, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Scene plane -> undistorted (pinhole) pixel coordinates, both relative to centre."""
        # Displayed counter-clockwise is a negative rotation in the y-down frame.
        c, s = np.cos(self.roll_rad), np.sin(self.roll_rad)
        xi = c * x + s * y
        yi = -s * x + c * y
        return xi, yi * self.aspect

    def ideal_to_scene(self, xi: np.ndarray, yi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        c, s = np.cos(self.roll_rad), np.sin(self.roll_rad)
        yi = yi / self.aspect
        return c * xi - s * yi, s * xi + c * yi

    def distort(self, xi: np.ndarray, yi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Ideal pixel -> sensor pixel (relative to centre)."""
        f = self.focal_px
        r2 = (xi * xi + yi * yi) / (f * f)
        g = 1.0 + self.k1 * r2 + self.k2 * r2 * r2
        return xi * g, yi * g

    def undistort(self, xd: np.ndarray, yd: np.ndarray, iters: int = 12
                  ) -> tuple[np.ndarray, np.ndarray]:
        """Sensor pixel -> ideal pixel by Newton iteration on the radius (exact to 1e-12 px)."""
        if self.k1 == 0 and self.k2 == 0:
            return xd, yd
        f = self.focal_px
        rd = np.hypot(xd, yd) / f
        ru = rd.copy()
        for _ in range(iters):
            r2 = ru * ru
            g = ru * (1 + self.k1 * r2 + self.k2 * r2 * r2) - rd
            dg = 1 + 3 * self.k1 * r2 + 5 * self.k2 * r2 * r2
            ru = ru - g / dg
        scale = np.where(rd > 0, ru / np.where(rd > 0, rd, 1.0), 1.0)
        return xd * scale, yd * scale

    def sensor_to_scene(self, xd: np.ndarray, yd: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return self.ideal_to_scene(*self.undistort(xd, yd))

    def image_angle(self, scene_angle_rad: float) -> float:
        """Angle in the ideal pinhole image of a scene line at ``scene_angle_rad``.

        Angles are measured from +x towards -y (counter-clockwise as displayed), in (-pi/2, pi/2].
        """
        ux, uy = np.cos(scene_angle_rad), -np.sin(scene_angle_rad)
        xi, yi = self.scene_to_ideal(np.array(ux), np.array(uy))
        return wrap_half_turn(float(np.arctan2(-yi, xi)))


def wrap_half_turn(angle_rad: float) -> float:
    """Wrap a line direction to (-pi/2, pi/2]."""
    a = (angle_rad + np.pi / 2) % np.pi - np.pi / 2
    return float(np.pi / 2 if a == -np.pi / 2 else a)
