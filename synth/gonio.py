"""Synthetic laser-goniometer counter logs (the patent's angle-measuring device), with truth.

Physics, not the pipeline's model: a rotary table turns at a mean rate with a speed ripple
locked to the table angle (once per revolution) and a slow random wander; four faces (a
reference mirror and three housings) sit at azimuths a few arc-minutes off 90-degree steps;
a photoelectric autocollimator fires when a face normal passes (latency, timing jitter); a
ring laser on the table produces a continuous phase

    Phi(t) = K / 2 pi * integral of (1 + kappa s) d(theta(s) + d Omega_E sin(lat) s) + phi0

(K pulses per revolution, d = +1 counter-clockwise seen from above, -1 clockwise: the Earth's
rotation adds to a ccw table in the northern hemisphere); each counter holds
floor(Phi(t_end)) - floor(Phi(t_start)), so quantisation does not accumulate. Missing and
spurious autocollimator pulses and failed reference signals can be injected.

The log (design.md): one row per pulse after the arming reference pulse: count, counter (1/2
alternating), ref (1 if the binding signal marked this pulse as the first face), t [s].
Angles in radians, times in seconds.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
from scipy.ndimage import gaussian_filter1d

OMEGA_EARTH = 7.2921150e-5  # rad/s
K_DEFAULT = 764349.0  # pulses per revolution (0.40 m triangular He-Ne ring: 1.70" a pulse)
ARCSEC = np.pi / 180 / 3600


@dataclass(frozen=True)
class GonioSpec:
    """One run of the goniometer.

    ``face_offsets_rad``: deviation of faces 1..3 from 90/180/270 deg (face 0 at 0);
    ``ripple``: once-per-rev relative speed ripple; ``wander``: RMS of the slow random relative
    speed variation; ``jitter_rad``: autocollimator timing jitter as an angle;
    ``latency_s``: autocollimator delay; ``kappa_per_s``: ring-laser scale-factor drift;
    ``p_missing``/``p_spurious``: per-pulse probabilities; ``failed_refs``: number of
    reference signals that fail. ``faults``: explicit instrument faults, each
    ``(kind, pulse, value)`` with ``pulse`` the index of a face pulse counted from the first:

    * ``("double", i, dt)``: the autocollimator fires again ``dt`` seconds after (dt > 0) or
      before (dt < 0) face pulse i (the binding signal marks only the face pulse);
    * ``("double_ref", i, dt)``: the same, the binding window marking both pulses;
    * ``("glint", i, f)``: a stray pulse at fraction f of the time from pulse i to i+1;
    * ``("missing", i, 0)``: face pulse i not fired (a reference pulse too, if face 0);
    * ``("ref_fail", i, 0)``: the binding signal misses face pulse i (a face-0 pulse);
    * ``("lost_row", i, 0)``: the interface drops the row of pulse i from the log;
    * ``("counter_swap", i, 0)``: the row of pulse i carries the other counter's id.

    ``arm_face``: the face whose pulse arms the counters (the log's rows start after it);
    ``stop_pulses``: drop this many pulses from the end (a log that stops anywhere);
    ``time_resolution_s``: the time stamps are floored to this (e.g. 1e-7 for 10 MHz).
    """

    revolutions: int = 200
    rev_per_s: float = 1.0
    direction: int = 1
    face_offsets_rad: tuple[float, float, float] = (150 * ARCSEC, -220 * ARCSEC, 95 * ARCSEC)
    ripple: float = 0.0
    ripple_phase: float = 0.3
    wander: float = 0.0
    wander_revs: float = 20.0
    latitude_deg: float = 50.45
    k_per_rev: float = K_DEFAULT
    kappa_per_s: float = 0.0
    jitter_rad: float = 0.1 * ARCSEC
    latency_s: float = 5e-6
    p_missing: float = 0.0
    p_spurious: float = 0.0
    failed_refs: int = 0
    with_time: bool = True
    pyramidal_rad: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 0.0)
    slit_tilt_rad: float = 0.0
    faults: tuple = ()
    arm_face: int = 0
    stop_pulses: int = 0
    time_resolution_s: float = 0.0
    seed: int = 0

    @property
    def azimuths(self) -> np.ndarray:
        """Table angle of each face from face 0, counter-clockwise [rad] (the order in which a
        ccw table brings faces 0, 1, 2, 3 to the autocollimator)."""
        return np.array([0.0, *(np.pi / 2 * np.arange(1, 4) + np.array(self.face_offsets_rad))])

    @property
    def trigger_azimuths(self) -> np.ndarray:
        """Table angles at which the autocollimator fires for each face [rad]: a face normal
        tilted out of the horizontal plane by p (pyramidal error) returns the slit image
        displaced vertically by 2p; with the detector slit tilted by e from vertical that is a
        horizontal shift 2p tan e, i.e. the pulse comes p tan e of table angle late, in either
        direction of rotation. An instrument error the angles between normals do not contain."""
        return self.azimuths + np.asarray(self.pyramidal_rad) * np.tan(self.slit_tilt_rad)

    def _passing(self, az: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        if self.direction > 0:
            return np.arange(4), az - az[0]
        ids = np.array([0, 3, 2, 1])
        return ids, np.append(0.0, 2 * np.pi - (az[ids[1:]] - az[0]))

    @property
    def angles(self) -> np.ndarray:
        """True table angles from face k to face k+1 (cyclic, ccw order) [rad]; sum 2 pi."""
        az = self.azimuths
        return np.diff(np.append(az, 2 * np.pi))

    def passing(self) -> tuple[np.ndarray, np.ndarray]:
        """Faces in the order this run's direction brings them past the autocollimator, and
        their distances travelled from face 0 within a revolution [rad]. Clockwise, the same
        faces come in reverse order: 0, 3, 2, 1. (Where the pulses come: trigger azimuths.)"""
        return self._passing(self.trigger_azimuths)

    @property
    def passing_angles(self) -> np.ndarray:
        """True angles between consecutive face normals in this run's passing order [rad]."""
        return np.diff(np.append(self._passing(self.azimuths)[1], 2 * np.pi))


def _pulse_times(spec: GonioSpec, rng: np.random.Generator
                 ) -> tuple[np.ndarray, np.ndarray | None, np.ndarray | None]:
    """Times [s] at which the table angle reaches each face, for every revolution, and the
    fine (time, angle) grid of the table's motion (None at constant speed)."""
    n_faces = 4
    theta_targets = (np.arange(spec.revolutions + 1)[:, None] * 2 * np.pi
                     + spec.passing()[1][None, :]).ravel()[: spec.revolutions * n_faces + 1]
    omega0 = 2 * np.pi * spec.rev_per_s
    if spec.ripple == 0 and spec.wander == 0:
        return theta_targets / omega0, None, None
    # Speed as a function of table angle; time = integral of d theta / omega(theta).
    per_rev = 4096
    grid = np.linspace(0, theta_targets[-1] + 2 * np.pi, (spec.revolutions + 2) * per_rev)
    # Distance travelled -> the table's own angle: the ripple is locked to the table.
    rel = 1 + spec.ripple * np.sin(spec.direction * grid + spec.ripple_phase)
    if spec.wander:
        # Slow: made on a grid of 8 points a revolution, then interpolated.
        coarse = np.linspace(0, grid[-1], (spec.revolutions + 2) * 8)
        w = gaussian_filter1d(rng.standard_normal(coarse.size), spec.wander_revs * 8 / 4)
        rel = rel + spec.wander * np.interp(grid, coarse, w / max(w.std(), 1e-300))
    inv = 1 / (omega0 * rel)
    t_grid = np.concatenate([[0.0], np.cumsum((inv[1:] + inv[:-1]) / 2 * np.diff(grid))])
    return np.interp(theta_targets, grid, t_grid), t_grid, grid


def _int_t_dtheta(t: np.ndarray, omega0: float, t_grid: np.ndarray | None,
                  grid: np.ndarray | None) -> np.ndarray:
    """The integral of s d(theta(s)) from 0 to each t [rad s]: exact for the table's angle,
    which is linear in time (``t_grid`` None: omega0 t) or piecewise linear on ``t_grid``."""
    if t_grid is None:
        return omega0 * t**2 / 2
    rate = np.diff(grid) / np.diff(t_grid)
    at_nodes = np.concatenate([[0.0], np.cumsum(rate * (t_grid[1:]**2 - t_grid[:-1]**2) / 2)])
    k = np.clip(np.searchsorted(t_grid, t, side="right") - 1, 0, len(rate) - 1)
    return at_nodes[k] + rate[k] * (t**2 - t_grid[k]**2) / 2


def simulate(spec: GonioSpec) -> dict:
    """Simulate the run; returns the log columns and the truth."""
    rng = np.random.default_rng(spec.seed)
    t_face, t_grid, grid = _pulse_times(spec, rng)
    n = t_face.size
    face = spec.passing()[0][np.arange(n) % 4]
    omega0 = 2 * np.pi * spec.rev_per_s
    # Autocollimator: fires latency after the face passes, with timing jitter.
    t_pulse = t_face + spec.latency_s + rng.normal(0, spec.jitter_rad / omega0, n)
    keep = np.ones(n, bool)
    if spec.p_missing:
        keep[1:] = rng.random(n - 1) >= spec.p_missing
    t_pulse, face = t_pulse[keep], face[keep]
    is_ref = face == 0
    if spec.p_spurious:
        k = rng.random(t_pulse.size - 1) < spec.p_spurious
        extra = t_pulse[:-1][k] + rng.random(k.sum()) * np.diff(t_pulse)[k]
        t_pulse = np.concatenate([t_pulse, extra])
        is_ref = np.concatenate([is_ref, np.zeros(extra.size, bool)])
        face = np.concatenate([face, np.full(extra.size, -1)])
        order = np.argsort(t_pulse, kind="stable")
        t_pulse, is_ref, face = t_pulse[order], is_ref[order], face[order]
    if spec.failed_refs:
        refs = np.flatnonzero(is_ref[1:]) + 1
        is_ref[rng.choice(refs, size=min(spec.failed_refs, refs.size), replace=False)] = False
    tag = np.full(t_pulse.size, -1)
    lost: list[int] = []
    swapped: list[int] = []
    missing_t: list[tuple[int, float]] = []
    if spec.faults:
        drop = np.zeros(t_pulse.size, bool)
        ex_t, ex_ref, ex_tag = [], [], []
        for k, (kind, i, v) in enumerate(spec.faults):
            if kind in ("double", "double_ref"):
                ex_t.append(t_pulse[i] + v)
                ex_ref.append(kind == "double_ref" and is_ref[i])
                ex_tag.append(k)
            elif kind == "glint":
                ex_t.append(t_pulse[i] + v * (t_pulse[i + 1] - t_pulse[i]))
                ex_ref.append(False)
                ex_tag.append(k)
            elif kind == "missing":
                drop[i] = True
                missing_t.append((k, t_pulse[i]))
            elif kind == "ref_fail":
                is_ref[i] = False
                tag[i] = k
            elif kind == "lost_row":
                lost.append(k)
                tag[i] = k
            elif kind == "counter_swap":
                swapped.append(k)
                tag[i] = k
            else:
                raise ValueError(f"unknown fault kind {kind!r}")
        keep = ~drop
        t_pulse = np.concatenate([t_pulse[keep], ex_t])
        is_ref = np.concatenate([is_ref[keep], np.asarray(ex_ref, bool)])
        face = np.concatenate([face[keep], np.full(len(ex_t), -1)])
        tag = np.concatenate([tag[keep], np.asarray(ex_tag, int)])
        order = np.argsort(t_pulse, kind="stable")
        t_pulse, is_ref, face, tag = t_pulse[order], is_ref[order], face[order], tag[order]
    # Armed on the first pulse of ``arm_face`` (a face pulse, in the first revolution).
    a = int(np.flatnonzero(face == spec.arm_face)[0]) if spec.arm_face else 0
    end = t_pulse.size - spec.stop_pulses
    t_pulse, is_ref, face, tag = (x[a:end] for x in (t_pulse, is_ref, face, tag))
    theta = (omega0 * t_pulse if t_grid is None else np.interp(t_pulse, t_grid, grid))
    earth_rate = spec.direction * OMEGA_EARTH * np.sin(np.deg2rad(spec.latitude_deg))
    # The laser counts K (1 + kappa s) / 2 pi per radian turned at time s: the phase is the
    # integral of that over the inertial angle, theta + earth + kappa * int s d(theta + earth).
    drift = spec.kappa_per_s * (_int_t_dtheta(t_pulse, omega0, t_grid, grid)
                                + earth_rate * t_pulse**2 / 2)
    phi = (spec.k_per_rev * (theta + earth_rate * t_pulse + drift) / (2 * np.pi)
           + rng.random())
    cum = np.floor(phi)
    counts = np.diff(cum).astype(np.int64)
    t_log = t_pulse[1:] - t_pulse[0]
    if spec.time_resolution_s:
        t_log = np.floor(t_log / spec.time_resolution_s) * spec.time_resolution_s
    counter = (np.arange(counts.size) % 2 + 1).astype(np.int8)
    ref = is_ref[1:].astype(np.int8)
    rtag = tag[1:]
    # Where each fault shows in the log: the row of the pulse (extra pulses, marks, swaps),
    # the row whose interval spans a missing pulse, the row after a lost one.
    fault_rows = {int(k): int(r) for r, k in enumerate(rtag) if k >= 0}
    for k, tm in missing_t:
        r = int(np.searchsorted(t_pulse[1:], tm))
        if 0 <= r < counts.size and t_pulse[0] < tm:
            fault_rows[k] = r
    for k in swapped:
        r = fault_rows.get(k)
        if r is not None:
            counter[r] = 3 - counter[r]
    keep_rows = np.ones(counts.size, bool)
    for k in lost:
        r = fault_rows.get(k)
        if r is not None:
            keep_rows[r] = False
    shift = np.cumsum(~keep_rows)
    for k in list(fault_rows):
        r = fault_rows[k]
        fault_rows[k] = int(r - shift[r] + (0 if keep_rows[r] else 1))
    counts, counter, ref, t_log, face_rows = (x[keep_rows] for x in (
        counts, counter, ref, t_log, face[1:]))
    rows = {"count": counts, "counter": counter, "ref": ref, "t": t_log}
    faults = [{"kind": spec.faults[k][0], "row": r} for k, r in sorted(fault_rows.items())
              if r < counts.size]
    truth = {"angles_rad": spec.passing_angles.tolist(),
             "angles_deg": np.rad2deg(spec.passing_angles).tolist(),
             "passing_faces": spec.passing()[0].tolist(),
             "angles_ccw_order_rad": spec.angles.tolist(),
             "azimuths_rad": spec.azimuths.tolist(), "spec": asdict(spec),
             "faults": faults,
             "faces_of_rows": face_rows.tolist() if n < 200000 else None}
    return {"rows": rows, "truth": truth}


def write_log(sim: dict, path: str | Path) -> Path:
    """Write the counter log CSV (count,counter,ref[,t]) and <stem>.truth.json; never
    overwrite."""
    path = Path(path)
    if path.exists():
        raise FileExistsError(f"{path}: exists; synth never overwrites files")
    r = sim["rows"]
    with_t = sim["truth"]["spec"]["with_time"]
    cols = [r["count"], r["counter"], r["ref"]] + ([r["t"]] if with_t else [])
    fmt = ["%d", "%d", "%d"] + (["%.9f"] if with_t else [])
    head = "count,counter,ref" + (",t" if with_t else "")
    np.savetxt(path, np.column_stack(cols), fmt=fmt, delimiter=",", header=head, comments="")
    truth = dict(sim["truth"])
    truth.pop("faces_of_rows", None)
    path.with_suffix(".truth.json").write_text(json.dumps(truth, indent=2))
    return path


def drop_out(sim: dict, row: int, rows: int) -> dict:
    """The log of ``sim`` with a communication drop-out: ``rows`` consecutive rows from
    ``row`` never reached the log. The interface loses the rows whole — their counts, counter
    ids and times — so the counters' ids do not alternate across an odd number of lost rows,
    and the row after the gap holds one face interval's counts with the time of all of them.
    The truth's ``faults`` gains ``{"kind": "dropout", "row": row, "rows": rows}`` (``row``:
    the first row after the gap, in the new log)."""
    r = sim["rows"]
    if not 0 <= row < row + rows <= len(r["count"]):
        raise ValueError(f"drop-out rows {row}..{row + rows - 1}: outside the log")
    keep = np.ones(len(r["count"]), bool)
    keep[row:row + rows] = False
    truth = dict(sim["truth"])
    truth["faults"] = [*truth["faults"], {"kind": "dropout", "row": row, "rows": rows}]
    if truth.get("faces_of_rows") is not None:
        truth["faces_of_rows"] = np.asarray(truth["faces_of_rows"])[keep].tolist()
    return {"rows": {k: v[keep] for k, v in r.items()}, "truth": truth}
