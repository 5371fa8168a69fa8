"""What reaches a mark's warnings: a handled crossing is a note, not a warning; what the
fusion's set-up warnings say of a declared set-up and a vector effect."""

from __future__ import annotations

import numpy as np

from align import LensRanges, measure_image
from align.loop import EffectReport
from align.present import mark_lines
from align.warnings import handled_crossing, is_information, mark_warnings, p_is, setup_notice
from axisbase.units import ARCSEC
from synth import render_marks
from tests.align.test_marks_crossing import crossing_scene


def test_a_handled_crossing_is_a_note_not_a_warning():
    # Two marks crossing at 20 deg in their middles (seeded): each is measured with the
    # other's groove left out of its fit (tests/align/test_marks_crossing.py checks their
    # angles against the truth over seeds), so nothing about them is less to be trusted.
    img = render_marks(crossing_scene(20.0, "middle", 1), with_crlb=False).image.astype(float)
    res = measure_image(img, "x.png", ranges=LensRanges.none())
    found = [r for r in res if r.found]
    assert len(found) == 2
    crossings = [n for r in found for n in r.notes if handled_crossing(n)]
    assert len(crossings) == 2  # one per mark, in its notes (and so in the JSON's)
    assert all("crossing with mark" in n and "px excluded" in n for n in crossings)
    warnings = mark_warnings(res)
    assert not any("crossing" in w for w in warnings)
    text = "\n".join(line for r in found for line in mark_lines(r))
    assert text.count("    note: crossing with mark") == 2


def test_other_notes_still_warn():
    assert not handled_crossing("x.png mark 0: NOT OK: the angle is lens-limited")
    assert not handled_crossing("x.png mark 0: crossing with mark 1: refused")
    assert handled_crossing("a b.png mark 3: crossing with a groove not found as a mark: 12 px "
                            "excluded (the other groove lies in its profile window there)")


# What the lens and the background stages write (align/lens.py, align/camera_lens.py,
# imaging/stripes.py), as they write it: which of them is a note, which a warning.
INFO_NOTES = [
    "camera A: lens k1 = -0.00326 ± 0.0033 from the lines: sign not determined; not applied, "
    "carried in u",
    "camera B: lens k2, aspect, cx, cy not determined by these 4 line(s): carried in u over "
    "their plausible range",
    "camera: lens k1, p2 applied: the lines need it (their bows without it chi2 40.1 on 6 dof, "
    "with it 5.2 on 4), with the same sign wherever the principal point is in its range; that "
    "range is carried in u",
    "/d/z_A.png: column stripes in the background (column fixed-pattern noise, or a surface lay "
    "along the columns; rms 23.2 DN, 0.13 % of the marks' contrast, p = 4.7e-06): removed: each "
    "offset estimated from the background away from the marks",
    "/d/a.tif: orientation tag 6 applied (rotated 90° clockwise)",
]
WARNING_NOTES = [
    "camera A: lens k1 = 0.41 ± 0.02 from the lines: beyond any lens (|k1| <= 0.3): not a lens; "
    "not applied, carried in u",
    "camera A: the bow of 2 line(s) fits 2 lens parameter(s) with no line to spare: a lens and "
    "a bent mark are the same bow here; u covers both (add marks elsewhere in the frame, or "
    "calibrate the camera)",
    "camera A: the lines' bows disagree with one lens (chi2 31.0 on 3 dof; mark 1 worst, +4.2 "
    "u): a bent mark; u covers the lens and no lens",
    "camera A: the lens differs from its calibration (the marks' bows call for k1 +0.01 on top "
    "of it, p = 1e-05): u widened by its effect; recalibrate the camera (`align camera`)",
    "/d/z_A.png: column stripes in the background (column fixed-pattern noise, or a surface lay "
    "along the columns; rms 80 DN, 2 % of the marks' contrast, p = 1e-09): not removed (too few "
    "background columns): carried in u as background texture",
    "/d/s.tif: signed 16-bit data offset by +32768 DN to unsigned",
    "x.png mark 0: NOT OK: the angle is lens-limited (± 80″ from the lens alone)",
]


def test_information_notes_are_told_from_warnings():
    assert [is_information(n) for n in INFO_NOTES] == [True] * len(INFO_NOTES)
    assert [is_information(n) for n in WARNING_NOTES] == [False] * len(WARNING_NOTES)


def test_the_lens_stage_writes_the_notes_as_classified():
    # The two "carried in u" forms straight from solve_lens (four short lines, no lens
    # rendered): had their wording drifted from INFORMATION's patterns, they would warn again.
    import numpy as np

    from align.lens import LensRanges, solve_lens
    from align.lens_design import LineGeometry

    rng = np.random.default_rng(5)
    lines = []
    for y0 in (-150.0, -50.0, 60.0, 170.0):
        x = np.linspace(-250, 250, 60)
        pts = np.column_stack([x, y0 + 0.002 * x + rng.normal(0, 0.05, x.size)])
        lines.append(LineGeometry(pts, np.full(x.size, 0.05)))
    sol, _ = solve_lens(lines, 400.0, LensRanges())
    said = [f"camera: {n}" for n in sol.notes]  # as camera_lens names its camera
    assert any("sign not determined" in n for n in said), said
    assert any("not determined by these 4 line(s)" in n for n in said), said
    assert all(is_information(n) for n in said), said


def test_a_clean_demo_session_prints_no_warning_line(session21_result):
    # The synthetic session (what 'align synth session' writes) through 'align run': no
    # WARNING line, no warning in the JSON; its notes as 'note:' lines on the terminal and
    # in the marks' JSON notes.
    import json

    err = (session21_result.parent / "run.stderr").read_text(encoding="utf-8")
    out = (session21_result.parent / "run.stdout").read_text(encoding="utf-8")
    assert "WARNING" not in err + out, err
    doc = json.loads(session21_result.read_text(encoding="utf-8"))
    assert doc["ok"] and doc["warnings"] == []
    notes = {n for m in doc["stages"]["marks"] for n in m["notes"]}
    assert {ln.removeprefix("  note: ") for ln in out.splitlines()
            if ln.startswith("  note: ")} == {n for n in notes if is_information(n)}
    assert all(is_information(n) for n in notes), notes


def _effect(name: str, values: tuple[float, ...], u: float, description: str) -> EffectReport:
    """An effect the fusion's loop added, values [″] (two: an x, y vector)."""
    comps = (tuple((a, v * ARCSEC, u * ARCSEC) for a, v in zip("xy", values, strict=False))
             if len(values) > 1 else ())
    return EffectReport(name, values[0] * ARCSEC, u * ARCSEC, "rad", 2.0, 1.0, -50.0, 1e-9,
                        description, comps)


def test_a_found_increment_on_a_declared_roll_says_the_total_to_declare():
    """Declared -30″, found +61.1″ more: the warning says all three, and the total to
    declare is +31.1″ (not the increment)."""
    e = _effect("camera_roll[A]", (61.1,), 1.2, "roll of camera A about its optical axis")
    msg = setup_notice(e, np.array([-30.0 * ARCSEC]))
    assert "declared -30.0″" in msg and "found +61.1 ± 1.2″ more" in msg, msg
    assert "it is +31.1 ± 1.2″" in msg and "[cameras.A] roll_arcsec = +31.1" in msg, msg
    # nothing declared: the value found is the one to declare
    plain = setup_notice(e, np.zeros(1))
    assert "declared" not in plain and "[cameras.A] roll_arcsec = +61.1" in plain, plain


def test_a_declared_tilt_and_its_increment_name_both_components():
    e = _effect("platform_tilt", (-16.5, -22.9), 1.4,
                "tilt of the table axis under the levelled platform (x, y)")
    msg = setup_notice(e, np.array([10.0, 0.0]) * ARCSEC)
    assert "declared [+10.0, +0.0]″" in msg, msg
    assert "found x -16.5 ± 1.4″, y -22.9 ± 1.4″ more" in msg, msg
    assert "it is x -6.5 ± 1.4″, y -22.9 ± 1.4″" in msg, msg
    assert "[platform] table_tilt_arcsec = [-6.5, -22.9]" in msg, msg


def test_a_p_that_underflowed_is_said_as_below_the_smallest_double():
    assert p_is(0.0) == "p < 1e-300"
    assert p_is(1.234e-5) == "p = 1.2e-05"
