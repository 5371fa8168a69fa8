"""The commented ``session.toml`` that ``align init`` writes for the instruments a user names:
every key of those sections with its unit and default, in the standard layout (camera 1
looks along +Y and sees housings x and z, camera 2 looks along −X and sees y and z, each
also from the reversed side), so that filling in the file names and the values marked
``FILL IN`` makes a session ``align check`` and ``align run`` accept. The keys and their
ranges are those of :mod:`align.session.config` and ``align/schemas/session-toml.schema.json``.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

from align.errors import InputError
from axisbase.output import write_atomic

LAYOUT = (("+X", "x"), ("+Y", "y"))
"""Camera k of the standard layout: the platform axis pointing right in its image and the
housing seen horizontally (each camera also sees z vertically)."""

POSES = (("L000", "+Z", 0), ("L090", "+Z", 90), ("L180", "+Z", 180), ("L270", "+Z", 270),
         ("Xup", "+X", 0), ("Xdn", "-X", 0), ("Yup", "+Y", 0), ("Ydn", "-Y", 0))
"""The platform poses of the template: four table angles level, then each axis up and down."""


LENS = ("# without a model, the lens's plausible ranges (Type B, carried in u; all 0: a "
        "distortion-free camera)\n"
        "# lens_k1 = 0.3                 # |k1| at the image half-diagonal (default 0.3)\n"
        "# lens_k2 = 0.05                # |k2| at the half-diagonal (default 0.05)\n"
        "# lens_p = 0.001                # |p1|, |p2| at the half-diagonal (default 0.001)\n"
        "# lens_aspect = 0.005           # |fy/fx - 1| (default 0.005)\n"
        "# lens_pp_px = 40.0             # [px] principal point from the centre (default 40)\n"
        "# lens_max_u_arcsec = 60.0      # [″] above this lens-limited u an angle is not ok "
        "(default 60)\n"
        "# lens_pp_stability_px = 0.5    # [px] with a model: its principal point's move since "
        "calibration (default 0.5)\n")
"""The lens keys of a camera without a model (:class:`align.lens.LensRanges`)."""


AFTER = ("# blur_after_pixels = false       # true: images filtered on the pixel grid "
         "(demosaiced, sharpened)\n")


ROLL_U = ("# roll_u_arcsec = 34.6            # [″] the roll's standard uncertainty, "
          "carried where no reversal view or static pose determines it (default ±60″ "
          "uniform: 34.6)\n")


def _camera_block(name: str, k: int) -> str:
    if k >= len(LAYOUT):
        return (f"\n[cameras.{name}]\n# model = \"{name}.camera.json\"   # lens model from "
                "'align camera' (default: none; then the ranges below)\n"
                "# roll_arcsec = 0.0              # [″] known roll about the optical axis "
                "(default 0)\n" + ROLL_U + AFTER + LENS +
                f"# FILL IN its views and [[images]] as for the cameras above: [views.{name}] "
                "camera, right, up\n")
    right, housing = LAYOUT[k]
    rev = "-" + right[1]
    looks = "+Y" if k == 0 else "-X"
    out = (f"\n[cameras.{name}]\n# looks along {looks} (standard layout; change the views if "
           "yours differs)\n"
           f"# model = \"{name}.camera.json\"   # lens model from 'align camera' (default: "
           "none; then the ranges below)\n"
           "# roll_arcsec = 0.0              # [″] known roll about the optical axis "
           "(default 0)\n" + ROLL_U + AFTER + LENS)
    for view, r in ((name, right), (f"{name}r", rev)):
        out += (f"\n[views.{view}]\ncamera = \"{name}\"\nright = \"{r}\"      # platform axis "
                "pointing right in the image (+X, -X, +Y, -Y, +Z, -Z)\n"
                "up = \"+Z\"         # platform axis pointing up in the image\n")
    for view in (name, f"{name}r"):
        for h, nominal in ((housing, "horizontal"), ("z", "vertical")):
            out += (f"\n[[images]]\nfile = \"{h}_{view}.png\"     # FILL IN: the image (PNG, "
                    "TIFF, JPEG)\n"
                    f"housing = \"{h}\"           # x, y or z: whose scribe mark\n"
                    f"view = \"{view}\"\n"
                    f"nominal = \"{nominal}\"   # horizontal or vertical in the image\n"
                    "# roi = [0, 0, 640, 480]   # [px] x, y, w, h: search only there "
                    "(default: the whole image)\n")
    return out


def schema_uri() -> str:
    """The shipped JSON Schema of session.toml as a file URI (editors that read a
    ``#:schema`` line, e.g. Taplo / Even Better TOML, then complete and check the keys)."""
    from importlib import resources

    return Path(str(resources.files("align").joinpath("schemas",
                                                      "session-toml.schema.json"))).as_uri()


def session_template(cameras: Sequence[str] = (), gonio: bool = False, tumble: bool = False,
                     static: bool = False) -> str:
    """The commented ``session.toml`` for these instruments (``InputError`` for none, a
    camera named twice or a platform without the tumble calibration it needs)."""
    if not (cameras or gonio or tumble or static):
        raise InputError("align init: name at least one instrument (--cameras A,B, --gonio, "
                         "--tumble, --static)")
    if len(set(cameras)) != len(cameras) or any(not c.strip() for c in cameras):
        raise InputError(f"--cameras {','.join(cameras)}: each camera once, by a name")
    if static and not tumble:
        raise InputError("--static: the platform's static readings need the triad's "
                         "calibration (--tumble)")
    out = [f"#:schema {schema_uri()}",
           "# session.toml written by 'align init': FILL IN the values so marked, then",
           "#   align check THIS_FOLDER && align run THIS_FOLDER --json result.json "
           "--report report.html",
           "# Paths are relative to this folder. Units: _deg degrees, _arcsec arc-seconds.",
           "",
           "# name = \"unit-0001\"          # the session's name (default: the folder's name)",
           "# latitude_deg = 50.45        # [°] site latitude, -90..90: the goniometer's "
           "Earth-rate correction",
           "#                             # (default: none; its effect is then bounded and "
           "carried in u)",
           "# latitude_range_deg = [45, 55]   # [°] instead of latitude_deg, when only a range "
           "is known",
           "",
           "[metadata]                    # free keys, carried into the result and the "
           "reports",
           "serial = \"FILL IN\"            # the unit's serial number (heads the report)",
           "operator = \"FILL IN\"",
           "# date = 2026-11-20T08:30:00Z   # when measured (orders the units of a lot)",
           "# lot = \"L-2026-47\"             # the production lot (names the lot report)"]
    if tumble:
        out += ["", "[calibration]                 # the triad's ellipsoid calibration",
                "static = \"tumble.csv\"         # FILL IN: static poses, "
                "pose,ux,uy,uz[,t][,temp] (CSV)",
                "scale_sign = \"+\"              # FILL IN: sign of each scale factor: +, - "
                "or \"-,-,-\" (default: from face labels +x,... when given, else +)",
                "# check = \"check.csv\"        # more poses kept out of the fit, to check it",
                "# units = \"V\"                # g, m/s2, counts or V (default: the header's "
                "[unit], else V)",
                "# rate_hz = 100.0             # [Hz] when the file has no time column",
                "# time_unit = \"us\"            # the time column's unit when its header "
                "says none",
                "# columns = \"ux=ax,uy=ay,uz=az\"  # when the headers are not ux, uy, uz",
                "# adc_range = [-5.0, 5.0]     # the ADC's rails (readings' unit): a pose at "
                "one is left out",
                "# scale_stability_ppm = 20.0  # ± [ppm] the scale factors' stability over "
                "the run (not set: from the poses' slopes, else assumed stable, stated; as "
                "--scale-stability-ppm)",
                "# k2_bound_ug_per_g2 = 50.0   # ± [µg/g²] the datasheet's K2 (as "
                "--nonlinearity-bound K2,K3; not set: the physical prior, nothing carried)",
                "# k3_bound_ug_per_g3 = 100.0  # ± [µg/g³] the datasheet's K3: refused beyond, "
                "carried in u where the poses do not fit it (six faces: always)",
                "# window_s = 0.25             # [s] static detection window of a recording "
                "(as --window)",
                "# threshold = 3.0             # static below this x the recording's noise "
                "(as --threshold)",
                "# min_static_s = 0.5          # [s] shortest static interval kept "
                "(as --min-static)",
                "# margin_s = 0.1              # [s] cut from each end of an interval "
                "(as --margin)",
                "# split_sigma = 8.0           # split an interval whose mean moves by more "
                "standard errors than this ...",
                "# split_deg = 1.0             # ... and by more than this tilt [°] "
                "(as --split-sigma, --split-deg)"]
    if gonio:
        out += ["", "[goniometer]                  # ring-laser goniometer",
                "log = \"gonio.csv\"             # FILL IN: counter log, count,counter,ref[,t] "
                "(CSV)",
                "faces = [\"ref\", \"y\", \"x\", \"z\"]   # passing order, the reference face "
                "first",
                "nominal_deg = [90.0, 90.0, 90.0, 90.0]   # [°] face to next face, summing to "
                "360 (default: equal)",
                "direction = \"ccw\"             # ccw or cw, seen from above (default ccw)",
                "# reference_offset_arcsec = 0.0   # [″] known offset of the reference face "
                "(default 0)",
                "# reference_offset_u_arcsec = 34.6  # [″] its standard uncertainty, carried "
                "where no X/Y-up poses determine it (default ±60″ uniform: 34.6)",
                "# reverse_log = \"gonio_cw.csv\"   # a log turning the other way (cancels the "
                "Earth rate)",
                "# steady_table = false         # the table turned at a steady rate (default "
                "false)",
                "# columns = \"count=N,counter=C,ref=R\"   # when the headers differ",
                "# time_unit = \"us\"            # the t column's unit when its header says "
                "none",
                "# latency_max_us = 5.0         # [µs] the autocollimator's latency bound "
                "(its specification; 0: none), carried in u",
                "# counters_sound = false       # the counters verified (dead time measured): "
                "no counters' part in u"]
    for k, name in enumerate(cameras):
        out.append(_camera_block(name, k).rstrip("\n"))
    if static:
        out += ["", "[platform]                    # static readings on the platform",
                "static = \"platform.csv\"       # FILL IN: pose,ux,uy,uz[,t] (CSV)",
                "# table_tilt_arcsec = [0.0, 0.0]   # [″] known tilt of the table (default "
                "0, 0)",
                "# units = \"V\"                # as [calibration] units (one triad, one unit)",
                "", "[platform.poses]              # every pose label in the file: up "
                "(+X ... -Z) and table_deg [°]"]
        out += [f"{lab} = {{ up = \"{up}\", table_deg = {deg:.1f} }}" for lab, up, deg in POSES]
    out += ["", "# [tolerance]                 # the specification the verdict is taken "
            "against (ISO 14253-1)",
            "# arcsec = 60                 # [″] one symmetric tolerance ±T for every angle",
            "# E_xZ = [-30, 90]            # [″] per angle: T (±) or [lower, upper], "
            "relative to the nominal",
            "# nominal_arcsec = { E_xY = 10.0 }   # [″] nominal value of an angle (default 0)",
            "# decision = \"guarded\"        # simple or guarded (default guarded)",
            "# k = 2.0                     # guard band w = k·u (default 2)", ""]
    return "\n".join(out)


def write_template(folder: str | Path, text: str, force: bool = False) -> Path:
    """``folder/session.toml`` (the folder made if absent); an existing one is replaced only
    with ``force`` (``InputError`` otherwise)."""

    path = Path(folder) / "session.toml"
    if path.exists() and not force:
        raise InputError(f"{path}: exists; pass --force to replace it")
    path.parent.mkdir(parents=True, exist_ok=True)
    return write_atomic(path, text, force)
