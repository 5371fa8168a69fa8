"""Clean sessions as a newcomer writes them from the docs alone (issue 19, point 5): counts
from a triad at 25,000 counts/g, 20 samples a pose (the poses' u is their scatter), 14
random tumble attitudes, 8 platform poses (four levelled at table 0/90/180/270°, four on
their sides), a 4-face goniometer log of 60 revolutions with the counter's quantisation at a
fixed phase and 0.15″ autocollimator jitter. Physics only (nothing from the pipeline): the
sensing axes are the rows of I + E normalised; a table axis tilted by (tx, ty) turns the
levelled poses' gravity with the table angle."""

from __future__ import annotations

from pathlib import Path

import numpy as np

AS = np.pi / 180 / 3600  # [rad] per arc-second (written out: nothing from the pipeline)
LEVELLED = {"L000": 0.0, "L090": 90.0, "L180": 180.0, "L270": 270.0}
SIDES = {"Xup": (1, 0, 0, "+X"), "Xdn": (-1, 0, 0, "-X"), "Yup": (0, 1, 0, "+Y"),
         "Ydn": (0, -1, 0, "-Y")}


def write_session(folder: Path, seed: int, tilt_arcsec: tuple[float, float] = (0.0, 0.0),
                  samples: int = 20, revs: int = 60) -> np.ndarray:
    """Write tumble.csv, platform.csv, gonio.csv and session.toml into ``folder``; returns
    the true E [rad]."""
    rng = np.random.default_rng([seed, 19])
    folder.mkdir(parents=True, exist_ok=True)
    E = rng.uniform(-200, 200, (3, 3)) * AS
    np.fill_diagonal(E, 0.0)
    S = np.eye(3) + E
    S /= np.linalg.norm(S, axis=1, keepdims=True)
    k = 25000.0 * (1 + rng.uniform(-0.02, 0.02, 3))
    b = rng.uniform(-150, 150, 3)
    noise = 2.0  # [counts] a sample

    def rows(label: str, f: np.ndarray) -> list[str]:
        r = k * (S @ f) + b + rng.normal(0, noise, (samples, 3))
        return [f"{label},{x:.2f},{y:.2f},{z:.2f}" for x, y, z in r]

    lines = ["pose,ux,uy,uz"]
    for p in range(14):
        g = rng.normal(size=3)
        lines += rows(f"P{p:02d}", g / np.linalg.norm(g))
    (folder / "tumble.csv").write_text("\n".join(lines) + "\n")
    tx, ty = np.asarray(tilt_arcsec) * AS
    lines = ["pose,ux,uy,uz"]
    for name, deg in LEVELLED.items():
        c, s = np.cos(np.deg2rad(deg)), np.sin(np.deg2rad(deg))
        g = np.array([c * tx + s * ty, -s * tx + c * ty, 1.0])  # table frame -> platform
        lines += rows(name, g / np.linalg.norm(g))
    for name, (x, y, z, _) in SIDES.items():
        lines += rows(name, np.array([x, y, z], float))
    (folder / "platform.csv").write_text("\n".join(lines) + "\n")
    # goniometer: faces ref, y, x, z (ccw); A0 = 90° + E_yX, A1 = 90° - E_xY - E_yX
    A = np.deg2rad([90.0] * 4) + np.array([E[1, 0], -E[0, 1] - E[1, 0],
                                           rng.uniform(-60, 60) * AS, 0.0])
    A[3] = 2 * np.pi - A[:3].sum()
    C, T = 764355.84, 12.0
    pos = np.concatenate([[0.0], np.cumsum(np.tile(A, revs))])
    pos = pos + rng.normal(0, 0.15 * AS, pos.size)
    cnt = np.diff(np.floor(pos * C / (2 * np.pi) + rng.uniform()))
    t = pos[1:] / (2 * np.pi) * T
    lines = ["count,counter,ref,t"] + [f"{int(c)},{1 + i % 2},{int((i + 1) % 4 == 0)},"
                                       f"{t[i]:.6f}" for i, c in enumerate(cnt)]
    (folder / "gonio.csv").write_text("\n".join(lines) + "\n")
    poses = "\n".join([f'{n} = {{ up = "+Z", table_deg = {d} }}' for n, d in LEVELLED.items()]
                      + [f'{n} = {{ up = "{v[3]}", table_deg = 0.0 }}'
                         for n, v in SIDES.items()])
    (folder / "session.toml").write_text(f"""[metadata]
serial = "NC{seed}"
operator = "newcomer"

[calibration]
static = "tumble.csv"
scale_sign = "+"
units = "counts"

[goniometer]
log = "gonio.csv"
faces = ["ref", "y", "x", "z"]
nominal_deg = [90.0, 90.0, 90.0, 90.0]
direction = "ccw"

[platform]
static = "platform.csv"

[platform.poses]
{poses}
""")
    return E
