"""A complete synthetic alignment session with known truth: images, counter log, tumble and
platform static data, ``session.toml`` and ``truth.json``.

The physics, written here independently of the pipeline:

* Mounting: accelerometer i's sensing axis in the platform frame P (X, Y horizontal, Z up) is
  s_i = normalise(e_i + sum_j E_ij e_j), E_ij drawn 1-5 arc-minutes with random signs.
* Scribe marks run along s_i. A camera view is given by the platform directions of image right
  and image up; a mark's scene angle is atan2(s.up, s.right), wrapped to (-90, 90] deg, and the
  camera's roll (the same physical camera for a view and its reversal) adds to it.
* Goniometer: the table turns counter-clockwise seen from above; a face whose outward normal has
  azimuth psi (from X towards Y) passes the fixed autocollimator at table angle alpha - psi.
  Faces: the platform's reference mirror (normal -X, azimuth 180 deg, plus an optional offset),
  housing y (normal along s_y), housing x (along s_x), housing z (normal -Y, its own mounting
  rotation). Passing order ref, y, x, z.
* Tumble: the triad in its cube fixture, 14 poses (seed paper); outputs
  u_i = k_i (x_i + K2_i x_i^2), x = S (a + b), S the rows s_i.
* Platform static readings: the same triad on the levelled platform at four table angles (a
  tilt of the table axis, fixed in the room, turns with the table angle in P), and the platform
  commanded to X up/down and Y up/down by its gimbals.

Effects (``EFFECTS``) can be put into the data and declared in ``session.toml`` (the pipeline
is told) or left undeclared (it is not).
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from synth.gonio import GonioSpec, simulate, write_log
from synth.marks import ImageSpec, MarkSpec, full_well_for_snr, render_marks, write_synth
from synth.optics import CameraGeometry, wrap_half_turn
from synth.tumble import (
    TABLE1_BIAS,
    TABLE1_K,
    Triad,
    TumbleSpec,
    pose_directions,
    tumble,
    write_tumble_csv,
)

ARCSEC = np.pi / 180 / 3600
AXES = {"X": np.array([1.0, 0, 0]), "Y": np.array([0, 1.0, 0]), "Z": np.array([0, 0, 1.0])}
HOUSINGS = ("x", "y", "z")
# Camera views: (camera, platform direction of image right, of image up). A is the camera
# looking along +Y, B along -X; "r" views are the same camera after the platform is turned
# 180 deg on the table (reversal: cancels what is fixed to the camera).
VIEWS = {"A": ("A", "+X", "+Z"), "Ar": ("A", "-X", "+Z"),
         "B": ("B", "+Y", "+Z"), "Br": ("B", "-Y", "+Z")}
# Which housings each view shows, and their nominal orientation in that view.
VIEW_MARKS = {"A": (("x", "horizontal"), ("z", "vertical")),
              "Ar": (("x", "horizontal"), ("z", "vertical")),
              "B": (("y", "horizontal"), ("z", "vertical")),
              "Br": (("y", "horizontal"), ("z", "vertical"))}
FACES = ("ref", "y", "x", "z")
PLATFORM_POSES = (("L000", "+Z", 0.0), ("L090", "+Z", 90.0), ("L180", "+Z", 180.0),
                  ("L270", "+Z", 270.0), ("Xup", "+X", 0.0), ("Xdn", "-X", 0.0),
                  ("Yup", "+Y", 0.0), ("Ydn", "-Y", 0.0))
# name -> (unit of the VALUE given on the command line, what it does)
EFFECTS = {
    "camera_roll_A": ("arcsec", "roll of camera A about its optical axis"),
    "camera_roll_B": ("arcsec", "roll of camera B about its optical axis"),
    "reference_offset": ("arcsec", "azimuth of the reference mirror's normal off nominal"),
    "table_tilt_x": ("arcsec", "tilt of the table axis towards the room's x (platform X at 0)"),
    "table_tilt_y": ("arcsec", "tilt of the table axis towards the room's y"),
    "k2": ("ug/g^2", "second-order nonlinearity of every accelerometer"),
    "platform_level_x": ("arcsec", "the platform out of level: its levelled poses' 'up' "
                         "tilted towards platform X (fixed on the platform, turns with it)"),
    "platform_level_y": ("arcsec", "the platform out of level towards platform Y"),
    "gimbal_tilt_x": ("arcsec", "the base under the gimbal (X/Y up/down) poses tilted towards "
                      "the room's x (fixed in the room: each pose sees it turned by its gimbal)"),
    "gimbal_tilt_y": ("arcsec", "the base under the gimbal poses tilted towards the room's y"),
    "creep_x": ("arcsec", "the triad turned about platform X between the camera images and "
                "goniometer log and the platform static readings (creep)"),
    "creep_y": ("arcsec", "creep about platform Y (see creep_x)"),
    "creep_z": ("arcsec", "creep about platform Z (see creep_x)"),
    "lens_k1": ("", "OpenCV radial distortion k1 of both cameras"),
    "lens_k1_A": ("", "OpenCV radial distortion k1 of camera A only (overrides lens_k1)"),
    "lens_k1_B": ("", "OpenCV radial distortion k1 of camera B only (overrides lens_k1)"),
}
# The rest of the lens, each for both cameras or one (``_A``/``_B`` overrides the shared key):
# OpenCV's k2, k3, p1, p2 and the pixel aspect fy/fx minus 1 (non-square pixels).
_LENS_MORE = {"lens_k2": "OpenCV radial distortion k2", "lens_k3": "OpenCV radial distortion k3",
              "lens_p1": "OpenCV tangential p1",
              "lens_p2": "OpenCV tangential p2",
              "lens_aspect": "pixel aspect fy/fx minus 1 (non-square pixels)"}
# The principal point's offset from the image centre [px] (a real lens's: the chessboard
# camera's is 13 px in x), as the lens keys.
_LENS_PP = {"lens_pp_x": "principal point minus image centre, x (columns)",
            "lens_pp_y": "principal point minus image centre, y (rows down)"}
for _key, _what in (*_LENS_MORE.items(), *_LENS_PP.items()):
    _unit = "px" if _key in _LENS_PP else ""
    EFFECTS[_key] = (_unit, f"{_what} of both cameras")
    for _cam in "AB":
        EFFECTS[f"{_key}_{_cam}"] = (_unit, f"{_what} of camera {_cam} only (overrides {_key})")
_LENS_MORE.update(_LENS_PP)
LENSES = ("lens_k1", "lens_k1_A", "lens_k1_B",
          *(f"{k}{c}" for k in _LENS_MORE for c in ("", "_A", "_B")))


def parse_direction(text: str) -> np.ndarray:
    """'+X', '-Z', ... -> unit vector in P."""
    sign = -1.0 if text.strip().startswith("-") else 1.0
    return sign * AXES[text.strip().lstrip("+-").upper()]


@dataclass(frozen=True)
class SessionSpec:
    """What to synthesise. ``effects``: name -> value (units in ``EFFECTS``); ``undeclared``:
    the names that go into the data but not into session.toml."""

    seed: int = 0
    effects: dict[str, float] = field(default_factory=dict)
    undeclared: frozenset[str] = frozenset()
    image_size: tuple[int, int] = (640, 480)
    mark_length_px: float = 380.0
    snr: float = 40.0
    revolutions: int = 100
    latitude_deg: float = 50.45
    noise_v: float = 4.8e-5
    samples_per_pose: int = 200
    views: tuple[str, ...] = tuple(VIEWS)
    reverse_run: bool = False  # also a clockwise counter log (gonio_cw.csv)
    platform_poses: tuple[str, ...] = tuple(p[0] for p in PLATFORM_POSES)
    # (housing, view) pairs photographed once more (a new exposure of the same mark: new
    # placement in the frame, new noise), as <housing>_<view>_2.png, _3.png, ...
    repeat_images: tuple[tuple[str, str], ...] = ()
    # Views photographed after the others (a reversal added to a session). These and the
    # repeated images draw from their own random stream: the rest of the session (its other
    # images, log, tumble, static readings) is the same to the bit with or without them.
    added_views: tuple[str, ...] = ()
    platform_static: bool = True  # False: no platform static readings at all
    tumble_repeats: int = 1  # the tumble's 14 poses held this many times over (a second tumble)
    # camera -> (min, max) distance [px] of its marks' middles from the image centre (issue 18:
    # marks 400-800 px out, where a lens bows them most). Drawn from their own random stream
    # after the usual placement, so every other draw of the session is unchanged.
    far_marks_px: dict[str, tuple[float, float]] = field(default_factory=dict)


def true_axes(E: np.ndarray) -> np.ndarray:
    """Rows: unit sensing axes s_i in P from the 3x3 matrix of small angles (zero diagonal)."""
    S = np.eye(3) + E
    return S / np.linalg.norm(S, axis=1, keepdims=True)


def _draw_E(rng: np.random.Generator) -> np.ndarray:
    E = rng.uniform(1, 5, (3, 3)) * 60 * ARCSEC * rng.choice([-1, 1], (3, 3))
    np.fill_diagonal(E, 0.0)
    return E


def _scene_angle(s: np.ndarray, right: np.ndarray, up: np.ndarray) -> float:
    return float(wrap_half_turn(np.arctan2(s @ up, s @ right)))


def _azimuth(v: np.ndarray) -> float:
    return float(np.arctan2(v[1], v[0]))


def write_session(out: str | Path, spec: SessionSpec) -> dict:
    """Write a complete session folder ``out`` (must not exist or be empty) and its truth."""
    out = Path(out)
    if out.exists() and any(out.iterdir()):
        raise FileExistsError(f"{out}: exists and is not empty; synth never overwrites")
    for name in spec.effects:
        if name not in EFFECTS:
            raise ValueError(f"unknown effect {name!r}; known: {', '.join(EFFECTS)}")
    for lens in LENSES:
        if lens in spec.effects and lens not in spec.undeclared:
            raise ValueError(f"{lens} can only be undeclared: session.toml describes a lens by "
                             "a camera model file, which synth does not write")
    out.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(spec.seed)
    eff = {k: float(v) for k, v in spec.effects.items()}
    E = _draw_E(rng)
    S = true_axes(E)
    declared = {k: v for k, v in eff.items() if k not in spec.undeclared}

    images = _images(out, spec, S, eff, rng)
    gonio = _gonio(out, spec, S, eff, rng)
    bias_p = np.asarray(TABLE1_BIAS) * rng.uniform(0.5, 1.5, 3)
    k2 = eff.get("k2", 0.0) * 1e-6
    triad = Triad(k=TABLE1_K, bias=tuple(bias_p), k2=(k2, k2, k2), noise_v=spec.noise_v,
                  axes=tuple(map(tuple, S)))
    up = np.tile(pose_directions("cube14"), (spec.tumble_repeats, 1))
    td = tumble(TumbleSpec(triad=triad, seed=int(rng.integers(1 << 30)), check_poses=0,
                           up=tuple(map(tuple, up))))
    write_tumble_csv(td, out / "tumble.csv")
    # Creep: the static readings see the triad turned by a small rotation (Rodrigues) after
    # the images and the log were taken; the tumble (angles between axes) cannot see it.
    w = np.array([eff.get(f"creep_{a}", 0.0) for a in "xyz"]) * ARCSEC
    th = float(np.linalg.norm(w))
    R = np.eye(3)
    if th > 0:
        k = np.array([[0, -w[2], w[1]], [w[2], 0, -w[0]], [-w[1], w[0], 0]]) / th
        R = np.eye(3) + np.sin(th) * k + (1 - np.cos(th)) * k @ k
    triad_p = replace(triad, axes=tuple(map(tuple, S @ R.T)))
    platform = (_platform(out, spec, triad_p, eff, rng) if spec.platform_static
                else None)

    toml = _session_toml(spec, declared, images, platform)
    (out / "session.toml").write_text(toml)
    truth = {
        "misalignment_rad": E.tolist(), "axes": S.tolist(), "seed": spec.seed,
        "effects": eff, "undeclared": sorted(spec.undeclared),
        "scale_factors_v_per_g": list(TABLE1_K), "bias_platform_g": bias_p.tolist(),
        "gonio_angles_deg": gonio, "images": images,
    }
    (out / "truth.json").write_text(json.dumps(truth, indent=2))
    return truth


def _images(out: Path, spec: SessionSpec, S: np.ndarray, eff: dict[str, float],
            rng: np.random.Generator) -> list[dict]:
    w, h = spec.image_size
    rows = []
    shots = [(view, housing, nominal, "", rng) for view in spec.views
             for housing, nominal in VIEW_MARKS[view]]
    later = np.random.default_rng([spec.seed, 1])
    shots += [(view, housing, nominal, "", later) for view in spec.added_views
              for housing, nominal in VIEW_MARKS[view]]
    for k, (housing, view) in enumerate(spec.repeat_images):
        if view not in (*spec.views, *spec.added_views) or housing not in dict(VIEW_MARKS[view]):
            raise ValueError(f"repeat_images: housing {housing} is not in view {view}")
        n = sum(1 for hv in spec.repeat_images[:k + 1] if hv == (housing, view)) + 1
        shots.append((view, housing, dict(VIEW_MARKS[view])[housing], f"_{n}", later))
    far_rng = np.random.default_rng([spec.seed, 2])
    for view, housing, nominal, suffix, draw in shots:
        cam, right, up = VIEWS[view]
        def lens(key: str, cam: str = cam) -> float:
            return eff.get(f"{key}_{cam}", eff.get(key, 0.0))

        # The lens acts on the scene points before the pixels integrate them (synth/optics.py).
        geom = CameraGeometry(focal_px=1.6 * w, k1=lens("lens_k1"), k2=lens("lens_k2"),
                              p1=lens("lens_p1"), p2=lens("lens_p2"),
                              aspect=1.0 + lens("lens_aspect"), k3=lens("lens_k3"),
                              pp_offset_px=(lens("lens_pp_x"), lens("lens_pp_y")),
                              roll_rad=eff.get(f"camera_roll_{cam}", 0.0) * ARCSEC)
        s = S[HOUSINGS.index(housing)]
        ang = _scene_angle(s, parse_direction(right), parse_direction(up))
        mark = MarkSpec(ang, offset_px=float(draw.uniform(-40, 40)),
                        length_px=spec.mark_length_px, width_px=4.0,
                        centre_t_px=float(draw.uniform(-30, 30)))
        if cam in spec.far_marks_px:
            mark = _far(mark, spec, spec.far_marks_px[cam], far_rng)
        img = ImageSpec(marks=(mark,), width=w, height=h, seed=int(draw.integers(1 << 30)),
                        full_well_e=full_well_for_snr(spec.snr, -0.6), texture=0.01,
                        dust=4, scratches=2, gradient=(0.04, -0.02), camera=geom)
        sample = render_marks(img, with_crlb=False)
        name = f"{housing}_{view}{suffix}.png"
        write_synth(sample, out / name)
        rows.append({"file": name, "housing": housing, "view": view, "nominal": nominal,
                     "image_angle_rad": sample.truth.marks[0].image_angle_rad,
                     })
        if cam in spec.far_marks_px:
            rows[-1].update(centre_xy_px=list(mark.centre_xy()),
                            sagitta_px=_sagitta(mark, geom))
    return rows


def _far(mark: MarkSpec, spec: SessionSpec, span: tuple[float, float],
         rng: np.random.Generator, margin: float = 30.0) -> MarkSpec:
    """``mark`` moved so that its middle lies ``span`` [px] from the image centre, in a
    random direction, with the whole mark (and ``margin`` px) inside the frame."""
    w, h = spec.image_size
    a, half = mark.angle_rad, mark.length_px / 2
    along, normal = np.array([np.cos(a), -np.sin(a)]), np.array([np.sin(a), np.cos(a)])
    for _ in range(2000):
        d, phi = rng.uniform(*span), rng.uniform(0, 2 * np.pi)
        mid = d * np.array([np.cos(phi), np.sin(phi)])
        ends = np.abs([mid + half * along, mid - half * along])
        if np.all(ends[:, 0] < w / 2 - margin) and np.all(ends[:, 1] < h / 2 - margin):
            return replace(mark, offset_px=float(mid @ normal), centre_t_px=float(mid @ along))
    raise ValueError(f"far_marks_px {span}: a {mark.length_px:.0f} px mark does not fit that "
                     f"far out in a {w}x{h} frame")


def _sagitta(mark: MarkSpec, geom: CameraGeometry) -> float:
    """The largest distance [px] of the mark's imaged centre line from its chord."""
    t = np.linspace(-mark.length_px / 2, mark.length_px / 2, 201)
    a = mark.angle_rad
    sx = mark.offset_px * np.sin(a) + (mark.centre_t_px + t) * np.cos(a)
    sy = mark.offset_px * np.cos(a) - (mark.centre_t_px + t) * np.sin(a)
    x, y = geom.distort(*geom.scene_to_ideal(sx, sy))
    chord = np.array([x[-1] - x[0], y[-1] - y[0]]) / np.hypot(x[-1] - x[0], y[-1] - y[0])
    return float(np.max(np.abs((x - x[0]) * chord[1] - (y - y[0]) * chord[0])))


def _gonio(out: Path, spec: SessionSpec, S: np.ndarray, eff: dict[str, float],
           rng: np.random.Generator) -> list[float]:
    psi = {"ref": np.pi + eff.get("reference_offset", 0.0) * ARCSEC,
           "y": _azimuth(S[1]), "x": _azimuth(S[0]),
           "z": 1.5 * np.pi + rng.uniform(-300, 300) * ARCSEC}
    # Counter-clockwise table: face k passes at alpha - psi_k; angles from the reference.
    table = np.array([(psi["ref"] - psi[f]) % (2 * np.pi) for f in FACES])
    offsets = table[1:] - np.pi / 2 * np.arange(1, 4)
    gs = GonioSpec(revolutions=spec.revolutions, face_offsets_rad=tuple(offsets),
                   latitude_deg=spec.latitude_deg, seed=int(rng.integers(1 << 30)))
    sim = simulate(gs)
    write_log(sim, out / "gonio.csv")
    if spec.reverse_run:
        write_log(simulate(replace(gs, direction=-1, seed=int(rng.integers(1 << 30)))),
                  out / "gonio_cw.csv")
    return sim["truth"]["angles_deg"]


def _platform(out: Path, spec: SessionSpec, triad: Triad, eff: dict[str, float],
              rng: np.random.Generator) -> list[tuple[str, str, float]]:
    tilt = np.array([eff.get("table_tilt_x", 0.0), eff.get("table_tilt_y", 0.0)]) * ARCSEC
    level = np.array([eff.get("platform_level_x", 0.0), eff.get("platform_level_y", 0.0),
                      0.0]) * ARCSEC
    gimbal = np.array([eff.get("gimbal_tilt_x", 0.0), eff.get("gimbal_tilt_y", 0.0)]) * ARCSEC
    rows = []
    n = spec.samples_per_pose
    t0 = 0.0
    chosen = [p for p in PLATFORM_POSES if p[0] in spec.platform_poses]
    for _label, up, table_deg in chosen:
        g = parse_direction(up)
        if up == "+Z":
            # Gravity ("up" specific force) in the room tilted by the table axis, seen in P
            # after the table has turned by table_deg.
            c, s_ = np.cos(np.deg2rad(table_deg)), np.sin(np.deg2rad(table_deg))
            room = np.array([tilt[0], tilt[1], 1.0])
            g = np.array([c * room[0] + s_ * room[1], -s_ * room[0] + c * room[1], room[2]])
            g = g / np.linalg.norm(g) + level  # (the platform's own tilt turns with it)
            g = g / np.linalg.norm(g)
        else:
            g = g + _gimbal_tilt(up, gimbal)
            g = g / np.linalg.norm(g)
        t = t0 + np.arange(n) / 20.0
        u = triad.outputs(np.repeat(g[None], n, 0), np.zeros(n), np.zeros(n), rng)
        rows.append(np.column_stack([np.full(n, len(rows)), u, t]))
        t0 = t[-1] + 5.0
    data = np.vstack(rows)
    labels = [p[0] for p in chosen]
    with open(out / "platform.csv", "x") as fh:
        fh.write("pose,ux,uy,uz,t\n")
        for r in data:
            fh.write(f"{labels[int(r[0])]},{r[1]:.9e},{r[2]:.9e},{r[3]:.9e},{r[4]:.3f}\n")
    return chosen


def _gimbal_tilt(up: str, tilt: np.ndarray) -> np.ndarray:
    """The room's tilt (tx, ty) [rad] of the base under a gimbal pose, seen in P: the gimbal
    turns the platform 90° about its Y axis (X up/down) or its X axis (Y up/down), so the
    room's x and y lie along these P directions (room z along the pose's up):
    X up: room x = -Z, y = Y; X down: x = Z, y = Y; Y up: x = X, y = -Z; Y down: x = X,
    y = Z. Up and down see the one tilt along their shared axis alike (their readings move
    together, which no E does) and along the turned one oppositely."""
    tx, ty = tilt
    return {"+X": np.array([0.0, ty, -tx]), "-X": np.array([0.0, ty, tx]),
            "+Y": np.array([tx, 0.0, -ty]), "-Y": np.array([tx, 0.0, ty])}[up]


def _session_toml(spec: SessionSpec, declared: dict[str, float], images: list[dict],
                  platform: list[tuple[str, str, float]] | None) -> str:
    lines = ["# Synthetic alignment session (align synth session)", "",
             f"latitude_deg = {spec.latitude_deg}", "", "[calibration]",
             'static = "tumble.csv"', 'scale_sign = "-"', "", "[goniometer]",
             'log = "gonio.csv"', f"faces = {json.dumps(list(FACES))}",
             "nominal_deg = [90.0, 90.0, 90.0, 90.0]", 'direction = "ccw"']
    if spec.reverse_run:
        lines.append('reverse_log = "gonio_cw.csv"')
    if "reference_offset" in declared:
        lines.append(f"reference_offset_arcsec = {declared['reference_offset']}")
    for cam, looks in (("A", "+Y"), ("B", "-X")):
        lines += ["", f"[cameras.{cam}]", f"# looks along {looks}"]
        if f"camera_roll_{cam}" in declared:
            lines.append(f"roll_arcsec = {declared[f'camera_roll_{cam}']}")
        if not any(k in spec.effects for k in LENSES if k[-2:] not in ("_A", "_B")
                   or k.endswith(f"_{cam}")):
            # The rendered camera has no lens distortion and square pixels, and the file
            # says so (a corrected optic); an undeclared lens leaves the keys out, and the
            # pipeline carries its default plausible lens.
            lines += ["# distortion-free optics, square pixels, principal point at the centre",
                      "lens_k1 = 0.0", "lens_k2 = 0.0", "lens_p = 0.0", "lens_aspect = 0.0",
                      "lens_pp_px = 0.0"]
    for view in (*spec.views, *spec.added_views):
        cam, right, up = VIEWS[view]
        lines += ["", f"[views.{view}]", f'camera = "{cam}"', f'right = "{right}"',
                  f'up = "{up}"']
    for im in images:
        lines += ["", "[[images]]", f'file = "{im["file"]}"', f'housing = "{im["housing"]}"',
                  f'view = "{im["view"]}"', f'nominal = "{im["nominal"]}"']
    if platform is None:
        return "\n".join(lines) + "\n"
    lines += ["", "[platform]", 'static = "platform.csv"']
    tilt = [declared.get("table_tilt_x"), declared.get("table_tilt_y")]
    if any(v is not None for v in tilt):
        lines.append(f"table_tilt_arcsec = [{tilt[0] or 0.0}, {tilt[1] or 0.0}]")
    lines += ["", "[platform.poses]"]
    for label, up, table_deg in platform:
        lines.append(f'{label} = {{ up = "{up}", table_deg = {table_deg} }}')
    return "\n".join(lines) + "\n"
