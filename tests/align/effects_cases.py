"""Static tumbles with the effects a real accelerometer has and the model may lack (issue 19).

Each *class* is a triad of the seed paper's Table 1 with one effect rendered in the sensor's
physics by :mod:`synth.tumble` (not the calibration model run backwards), held on the paper's
14 cube poses in that order. :func:`run` calibrates one seed and returns the normalised errors
of the nine parameters (scale factors, non-orthogonality angles, biases) against the truth at
the calibration's reference time, and what the loop reported. The benchmark
``benchmarks/calibration_effects.py`` and the tests share these cases.
"""

from __future__ import annotations

import functools
from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np

from align.calibration import Poses, calibrate, poses_from_samples
from align.calibration.plan import plan
from synth.tumble import Triad, TumbleSpec, r_matrix, tumble


@functools.cache
def plan28() -> np.ndarray:
    """The 28-pose plan's attitudes (``plan(28).up``, deterministic): searched once per test
    run (each search is ~1 s of CPU; four modules use it). Read-only."""
    up = plan(28).up
    up.setflags(write=False)
    return up

NOISE_V = 2.4e-5
"""Per-sample noise [V] (1e-5 g; 200 samples a pose: 0.7 µg per pose mean)."""
RUN_S = 14 * 15.0
"""Duration of the 14 calibration poses [s] (10 s dwell + 5 s turn each)."""

CLASSES: dict[str, dict] = {
    "clean": {},
    # The cases: K_xy a_x a_y = 300 µg/g² on the x axis; 50 µg hysteresis on each
    # axis; the scale factor drifting by 100 ppm over the run.
    "cross": {"cross": ((300e-6, 0.0, 0.0), (0.0,) * 3, (0.0,) * 3)},
    "hysteresis": {"hysteresis_g": (50e-6, 50e-6, 50e-6)},
    "scale_drift": {"scale_drift": (100e-6 / RUN_S,) * 3},
    "scale_warmup": {"scale_warmup": (100e-6,) * 3, "warmup_tau_s": 60.0},
    # user8's cases (IEEE Std 1293's K3 and scale-factor asymmetry): K3 = ±100 µg/g³,
    # (k+ - k-)/(k+ + k-) = ±300 ppm.
    "k3": {"k3": (100e-6, -100e-6, 100e-6)},
    "asymmetry": {"asymmetry": (300e-6, -300e-6, 300e-6)},
}


@dataclass(frozen=True)
class Outcome:
    """One calibration of one seed: ``z`` the nine normalised errors (err / u) of the scale
    factors, beta and biases; ``effects`` the names the loop added; ``structure`` whether
    unexplained structure was reported; ``widened`` whether u was widened for it;
    ``u_ratio`` the nine parameters' u over their u from the noise alone (1 when not
    widened)."""

    z: np.ndarray
    effects: tuple[str, ...]
    structure: bool
    widened: bool
    u_ratio: np.ndarray


def triad_of(name: str, noise_v: float = NOISE_V) -> Triad:
    return replace(Triad(noise_v=noise_v), **CLASSES[name])


def poses_of(d, check: bool = False) -> Poses:
    sel = (d.pose >= d.n_cal) if check else (d.pose < d.n_cal)
    return poses_from_samples(d.pose[sel], d.u[sel], d.t[sel])


def truth_at(tr: Triad, t_ref: float) -> np.ndarray:
    """The nine true parameters at time ``t_ref`` [s]: scale factors along the sensing axes
    [V/g] (k_i s_i(t_ref) |r_i|), beta [rad], bias [g]."""
    s = (1.0 + np.asarray(tr.scale_drift) * t_ref
         + np.asarray(tr.scale_warmup) * np.exp(-t_ref / tr.warmup_tau_s))
    rows = np.linalg.norm(r_matrix(np.asarray(tr.beta)), axis=1)
    return np.concatenate([np.asarray(tr.k) * s * rows, tr.beta, tr.bias])


def run(name: str, seed: int, candidates: Sequence | None = None, poses: str = "cube14",
        up: np.ndarray | None = None, stability: float | None = None) -> Outcome:
    """One seed of class ``name`` on the pose set ``poses`` of synth, or on the up directions
    ``up`` in their order (a plan); ``stability``: the scale stability declared [ppm] (None:
    the library's, no term)."""
    tr = triad_of(name)
    d = tumble(TumbleSpec(triad=tr, poses=poses, seed=seed,
                          up=None if up is None else tuple(map(tuple, up))))
    kw = {} if candidates is None else {"candidates": candidates}
    if stability is not None:
        kw["scale_stability_ppm"] = stability
    cal = calibrate(poses_of(d), np.sign(tr.k), **kw)
    m = cal.model
    est = np.concatenate([m.sensitivity(), m.beta, m.bias])
    u = np.concatenate([m.sensitivity_u(), [m.u_of(f"{p}_{a}") for p in ("beta", "bias")
                                            for a in "xyz"]])
    z = (est - truth_at(tr, m.t_ref)) / u
    w = getattr(cal, "widening", None)
    if w is None:
        ratio = np.ones(9)
    else:  # the scale factors along the sensing axes, beta, biases (as z)
        i = [w.names.index(n) for n in (*(f"scale_factor_{a}" for a in "xyz"),
                                        *(f"{p}_{a}" for p in ("beta", "bias") for a in "xyz"))]
        ratio = w.factor[i]
    return Outcome(z, tuple(e.name for e in cal.loop.effects), cal.loop.unexplained_structure,
                   w is not None, ratio)


EXPECTED = {"cross": "cross_x_xy", "hysteresis": "bias_hysteresis",
            "scale_drift": "scale_drift", "scale_warmup": "scale_warmup",
            "k3": "nonlinearity_k3", "asymmetry": "scale_asymmetry"}
"""The effect each class is: what 'found' means."""


def sweep(name: str, seeds: Sequence[int], candidates: Sequence | None = None,
          poses: str = "cube14", up: np.ndarray | None = None,
          stability: float | None = None) -> dict:
    """Over seeds: |z| RMS and max over the nine parameters, the fraction of seeds where the
    loop added the class's effect (``found``), any effect (``any_effect``: on clean data,
    false effects), reported unexplained structure, and widened u; the median and max of u
    over its noise-only value (``u_ratio_median``, ``u_ratio_max``)."""
    out = [run(name, s, candidates, poses, up, stability) for s in seeds]
    z = np.array([o.z for o in out])
    return {"rms": float(np.sqrt(np.mean(z**2))), "max": float(np.max(np.abs(z))),
            "any_effect": float(np.mean([bool(o.effects) for o in out])),
            "found": float(np.mean([EXPECTED.get(name) in o.effects for o in out])),
            "structure": float(np.mean([o.structure for o in out])),
            "widened": float(np.mean([o.widened for o in out])),
            "u_ratio_median": float(np.median([o.u_ratio for o in out])),
            "u_ratio_max": float(np.max([o.u_ratio for o in out])),
            "effects": [o.effects for o in out]}
