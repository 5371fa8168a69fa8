"""A step within a pose: the bias jumped (or the unit was knocked) while it was held.

A bias random walk goes on in every pose; a step is one event. The poses whose samples'
low frequencies are beyond what the other poses show (:func:`align.calibration.walk.
walk_outliers`) are left out of the walk's level, and the step in each is located here
(the split of its samples that best separates two means). A calibration whose bias moved
during the run by more than its stated u is not a calibration of one bias: the result is
then not ok (:func:`step_problem`)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from align.calibration.walk import walk_outliers

STEP_Z = 3.0
"""The least size of a step, in its standard uncertainty, that counts as one."""
AXES = "xyz"


@dataclass(frozen=True)
class PoseStep:
    """The step located within one pose's samples.

    Attributes
    ----------
    pose : int
        The pose's index (dimensionless).
    label : str
        Its label (dimensionless).
    t_s : float
        The time of the step [s] (between the two samples it falls between).
    size : numpy.ndarray
        The change of the output, after less before (3,) [output unit].
    size_u : numpy.ndarray
        Its standard uncertainty (3,) [output unit].
    level : numpy.ndarray
        The pose's mean (3,) [output unit]: a step along it changes |a|, one across it is
        also a tilt (the tail of the turn at the edge of a static interval).
    """

    pose: int
    label: str
    t_s: float
    size: np.ndarray
    size_u: np.ndarray
    level: np.ndarray

    def to_dict(self) -> dict:
        return {"pose": self.pose, "label": self.label, "t_s": self.t_s,
                "size": self.size.tolist(), "size_u": self.size_u.tolist(),
                "level": self.level.tolist()}

    @classmethod
    def from_dict(cls, d: dict) -> PoseStep:
        return cls(int(d["pose"]), str(d["label"]), float(d["t_s"]),
                   np.asarray(d["size"], float), np.asarray(d["size_u"], float),
                   np.asarray(d["level"], float))


def locate_step(x: np.ndarray, t: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
    """The split of one pose's samples ``x`` (n, 3) [output unit] at times ``t`` [s] whose two
    means differ most (the sum over axes of the squared difference in its u): its time [s],
    the difference (3,) and its u (3,) [output unit]. The sample noise from successive
    differences (a step is one of them)."""
    n = len(x)
    s = np.median(np.abs(np.diff(x, axis=0)), 0) / (0.6745 * np.sqrt(2))
    s = np.maximum(s, np.finfo(float).eps * np.max(np.abs(x)))  # (noise-free data)
    c = np.cumsum(x, 0)
    m = np.arange(2, n - 1)
    d = (c[-1] - c[m - 1]) / (n - m)[:, None] - c[m - 1] / m[:, None]
    u = s[None, :] * np.sqrt(1.0 / m + 1.0 / (n - m))[:, None]
    j = int(np.argmax(np.sum((d / np.maximum(u, 1e-300)) ** 2, 1)))
    return float((t[m[j] - 1] + t[m[j]]) / 2), d[j], u[j]


def pose_steps(samples: Sequence[np.ndarray], times: Sequence[np.ndarray],
               labels: Sequence[str]) -> tuple[PoseStep, ...]:
    """The steps within the poses that are outliers of the walk (:func:`walk_outliers`)."""
    return tuple(PoseStep(i, labels[i], *locate_step(np.asarray(samples[i], float),
                                                      np.asarray(times[i], float)),
                          np.asarray(samples[i], float).mean(0))
                 for i in walk_outliers(samples, times))


EDGE_S = 0.5
"""A step located within this of either end of a static interval the tool detected [s], or
within a tenth of the interval, is not judged: the edge may hold the tail of the turn."""


def interior_steps(steps: Sequence[PoseStep], times: Sequence[np.ndarray]
                   ) -> tuple[PoseStep, ...]:
    """The ``steps`` of detected static intervals (``times`` [s] each interval's samples')
    located away from both its ends (:data:`EDGE_S`): a bias that jumps while the unit is
    held, not the end of the turn at the interval's edge."""
    out = []
    for s in steps:
        t = np.asarray(times[s.pose], float)
        edge = max(EDGE_S, 0.1 * float(np.ptp(t)))
        if s.t_s - t[0] >= edge and t[-1] - s.t_s >= edge:
            out.append(s)
    return tuple(out)


def step_problem(steps: Sequence[PoseStep], k: np.ndarray, cov: np.ndarray
                 ) -> tuple[str, ...]:
    """Why the result is not ok (none or one line) when a pose's bias stepped by more than
    the bias's u: ``k`` (3,) [output unit/g], ``cov`` the model's covariance (its names 6-8
    the biases [g]). Only a step that changes |a| beyond :data:`STEP_Z` of its u counts:
    one across gravity is also a tilt."""
    bias_u_g = np.sqrt(np.diag(cov)[6:9])
    for s in steps:
        g = np.abs(s.size / k)
        n = s.level / k / np.linalg.norm(s.level / k)
        radial, radial_u = n @ (s.size / k), np.linalg.norm(n * s.size_u / k)
        big = (g > STEP_Z * s.size_u / np.abs(k)) & (g > bias_u_g)
        if big.any() and abs(radial) > STEP_Z * radial_u:
            ax = int(np.argmax(np.where(big, g / bias_u_g, 0.0)))
            return (f"the {AXES[ax]} bias stepped by {s.size[ax] / k[ax] * 1e6:+.4g} µg "
                    f"within pose {s.label} (t ≈ {s.t_s:.1f} s; u of the bias "
                    f"{bias_u_g[ax] * 1e6:.3g} µg): the bias is not one value over the run "
                    "(a bias jump or a knock): recalibrate",)
    return ()
