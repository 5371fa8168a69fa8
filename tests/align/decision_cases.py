"""Clean inputs for each stage run alone, and inputs with a real effect (positive controls),
for the statistics of the decisions (issue 19, point 5).

Every case is rendered by ``synth`` (physics, seeded) and run through the stage as a user's
file would be; each returns the stage's decisions (:mod:`align.session.decisions`). A
*clean* case has no effect the stage's declared model lacks: whatever it flags is a false
alarm. ``Tally`` counts them and prints the rows of the table in ``docs/decisions.md``.
The fusion's clean cases are whole synthetic sessions, and draws of the observations those
sessions' stages produced around what the declared model predicts, with each source's
stated covariance (the fusion's decisions when every input's u is right, at the cost of a
fit instead of a session).
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from align.calibration import calibrate, read_poses
from align.fusion import fuse
from align.gonio import measure_log
from align.lens import LensRanges
from align.marks import BEND, measure_image
from align.session import load_session, observation_blocks, run_session
from align.session.decisions import (
    alarm_limit,
    calibration_decisions,
    fusion_decisions,
    gonio_decisions,
    mark_decisions,
    upper95,
)
from axisbase.units import DEG
from synth import CameraGeometry, ImageSpec, MarkSpec, full_well_for_snr, render_marks
from synth.gonio import GonioSpec, drop_out, simulate, write_log
from synth.session import SessionSpec, write_session
from synth.tumble import Triad, TumbleSpec, recording, tumble, write_tumble_csv
from tests.align.effects_cases import NOISE_V, plan28, poses_of, triad_of
from tests.align.test_lens import _camera_model

TARGET = 0.01
"""The false-alarm rate each decision must stay within (issue 19, point 5)."""
FALSE_FAIL = 1e-3
"""Probability that a decision whose true rate is exactly TARGET fails its test."""


@dataclass
class Tally:
    """Counts of each decision over the cases of one stage's input kind."""

    stage: str
    inputs: str
    n: int = 0
    counts: dict[str, int] = field(default_factory=dict)

    def add(self, got: dict[str, bool]) -> None:
        self.n += 1
        for k, v in got.items():
            self.counts[k] = self.counts.get(k, 0) + int(v)

    def rows(self) -> list[str]:
        """The table's rows: stage, inputs, decision, count/N, rate, 95 % upper bound."""
        return [f"| {self.stage} | {self.inputs} | {k} | {c}/{self.n} | "
                f"{100 * c / self.n:.2f} % | {100 * upper95(c, self.n):.2f} % |"
                for k, c in self.counts.items()]

    def over(self, exempt: Iterable[str] = ()) -> dict[str, int]:
        """The decisions whose count says their rate exceeds TARGET (one-sided binomial at
        FALSE_FAIL), other than ``exempt`` (decisions that are not tests on the data)."""
        lim = alarm_limit(self.n, TARGET, FALSE_FAIL)
        return {k: c for k, c in self.counts.items() if c > lim and k not in exempt}


def tally(stage: str, inputs: str, run: Callable[[int], dict[str, bool]],
          seeds: Iterable[int]) -> Tally:
    t = Tally(stage, inputs)
    for s in seeds:
        t.add(run(s))
    print("\n".join(t.rows()))
    return t


# ------------------------------------------------------------------------------ calibration
PLAN28 = tuple(map(tuple, plan28()))


def calibration_poses(seed: int, poses: str = "cube14", effect: str = "clean") -> dict:
    """Pose means of a static tumble of the seed paper's triad (``cube14``: its 14 cube
    poses; ``plan28``: ``align calibrate --plan 28``'s order), with ``effect`` (a class of
    :mod:`tests.align.effects_cases`)."""
    tr = triad_of(effect)
    d = tumble(TumbleSpec(triad=tr, seed=seed, up=PLAN28 if poses == "plan28" else None))
    return calibration_decisions(calibrate(poses_of(d), np.sign(tr.k)))


def calibration_samples(seed: int, folder: Path) -> dict:
    """The 14 poses' samples written per sample (``pose,ux,uy,uz,t``) and read as a user's
    file (the samples' scatter and the within-pose walk check enter)."""
    tr = Triad(noise_v=NOISE_V)
    d = tumble(TumbleSpec(triad=tr, seed=seed))
    poses, _ = read_poses(write_tumble_csv(d, folder / f"tumble{seed}.csv"))
    # As `align calibrate` runs it: nothing declared, no temperature column.
    return calibration_decisions(calibrate(poses, np.sign(tr.k), stability_default=True))


def calibration_recording(seed: int, folder: Path) -> dict:
    """A continuous recording (turns and shaking between the 14 poses, 50 Hz) whose static
    intervals the detection finds."""
    tr = Triad(noise_v=NOISE_V)
    t, u, _ = recording(TumbleSpec(triad=tr, seed=seed, rate_hz=50.0, dwell_s=8.0,
                                   move_s=3.0, check_poses=0))
    path = folder / f"rec{seed}.csv"
    np.savetxt(path, np.column_stack([t, u]), fmt=["%.4f"] + ["%.9e"] * 3, delimiter=",",
               header="t,ux,uy,uz", comments="")
    poses, _ = read_poses(path)
    return calibration_decisions(calibrate(poses, np.sign(tr.k), stability_default=True))


# ------------------------------------------------------------------------------ goniometer
def gonio_spec(seed: int) -> GonioSpec:
    """A 4-face table, 120 revolutions at 0.5-2 rev/s with a 2 % speed ripple and 1 % wander,
    no autocollimator latency. (One direction cannot tell a latency on that table: undeclared,
    the result is not ok, ``run.problems``, until the autocollimator's latency bound is
    declared or the other direction measured — a statement about the set-up, not one of the
    data's decisions counted here; the angles and their u, ``z_max``, are the counts'.)"""
    rng = np.random.default_rng([seed, 19])
    return GonioSpec(revolutions=120, rev_per_s=float(rng.uniform(0.5, 2.0)), ripple=0.02,
                     wander=0.01, latency_s=0.0, seed=seed)


def gonio_log(seed: int, folder: Path, latitude: bool, dropout: int = 0) -> dict:
    """Decisions on a clean log (``dropout``: that many rows lost at a random place), with or
    without ``--latitude`` (with it the revolution loop does not run: no structure or effect
    decision to count); ``z_max``: the largest |error|/u of the four face angles."""
    spec = gonio_spec(seed)
    sim = simulate(spec)
    if dropout:
        rng = np.random.default_rng([seed, dropout])
        sim = drop_out(sim, int(rng.integers(0, len(sim["rows"]["count"]) - dropout)),
                       dropout)
    p = write_log(sim, folder / f"log{seed}_{int(latitude)}_{dropout}.csv")
    run = measure_log(p, 4, spec.latitude_deg * DEG if latitude else None,
                      direction=spec.direction)
    z = (run.angles.angles_rad - np.array(sim["truth"]["angles_rad"])) / run.angles.u_rad
    got = gonio_decisions(run)
    if run.loop is None:
        got = {"fault found": got["fault found"]}
    return {**got, "z_max": float(np.max(np.abs(z)))}


# ------------------------------------------------------------------------------ marks
W, H = 640, 480
NO_LENS = CameraGeometry()
LENS = CameraGeometry(focal_px=700.0, k1=-0.12, k2=0.05, p1=3e-4, p2=-2e-4)
"""The declared lens of the 'declared lens' cases (an ordinary wide-angle lens)."""


def mark_spec(seed: int, camera: CameraGeometry = NO_LENS, bow_px: float = 0.0
              ) -> ImageSpec:
    """One mark at a random angle (any, near 0° or near 90°), 150-450 px long, 2-8 px wide,
    any profile, SNR 10-100, 8 or 16 bits, blur 0.8-2 px, anywhere near the centre."""
    rng = np.random.default_rng([seed, 1919])
    band = seed % 3
    ang = (rng.uniform(-90, 90), rng.uniform(-1, 1), 90 + rng.uniform(-1, 1))[band]
    mark = MarkSpec(np.deg2rad(ang), rng.uniform(-60, 60), rng.uniform(150, 450),
                    rng.uniform(2, 8), profile=str(rng.choice(["box", "v", "round"])),
                    bow_px=bow_px)
    return ImageSpec(marks=(mark,), width=W, height=H, blur_px=rng.uniform(0.8, 2.0),
                     bits=int(rng.choice([8, 16])), supersample=3,
                     full_well_e=full_well_for_snr(rng.uniform(10, 100), -0.6), seed=seed,
                     camera=camera)


def mark_image(seed: int, lens: bool = False, bow_px: float = 0.0) -> dict:
    """Decisions on one image: no lens (declared distortion-free) or the declared ``LENS``
    (its model as ``align camera`` saves it); ``bend``: the loop called the mark bent."""
    cam = LENS if lens else NO_LENS
    img = render_marks(mark_spec(seed, cam, bow_px), with_crlb=False).image.astype(float)
    kw = {"camera": _camera_model(cam, W, H)} if lens else {"ranges": LensRanges.none()}
    res = measure_image(img, expect_one=True, **kw)
    bend = any(r.found and r.loop is not None and BEND in [e.name for e in r.loop.effects]
               for r in res)
    return {**mark_decisions(res), "bend": bend}


# ------------------------------------------------------------------------------ fusion
@dataclass(frozen=True)
class FusionCase:
    """A session's observation blocks and what the fusion's declared model predicts for
    them (its fit without effects)."""

    blocks: tuple
    predicted: tuple


def session(seed: int, folder: Path, effects: dict | None = None):
    """A synthetic session (``effects`` undeclared), run: (session, result)."""
    d = folder / f"s{seed}_{len(effects or {})}"
    write_session(d, SessionSpec(seed=seed, effects=dict(effects or {}),
                                 undeclared=frozenset(effects or {})))
    s = load_session(d)
    return s, run_session(s)


def fusion_case(s, res) -> FusionCase:
    blocks = tuple(observation_blocks(s, res))
    return FusionCase(blocks, tuple(res.fusion.loop.before.payload.predicted))


def fusion_draw(case: FusionCase, seed: int) -> dict:
    """The fusion's decisions on the case's blocks with values drawn around the declared
    model's prediction with each block's stated covariance."""
    rng = np.random.default_rng([seed, 55])
    blocks = [replace(b, values=p + np.linalg.cholesky(b.cov) @ rng.normal(size=len(p)))
              for b, p in zip(case.blocks, case.predicted, strict=True)]
    return fusion_decisions(fuse(blocks))
