"""One reading of the residual loop's report on a mark: its angle, u and named u terms.

What a bow the loop found means for the angle (the chord between the groove's ends, u
covering the straight fit and where the ends are), and what structure no effect names does
to u (:func:`structure_inflation`, ``structure_chord_vs_fit``); :func:`align.marks.loop_mark`
reads the loop's own report, and each decision's other side on the edge of its test
(:mod:`align.mark_choice`), with it.
"""

from __future__ import annotations

import numpy as np
from scipy import special  # (not scipy.stats: ~0.8 s of CPU to import; the same functions)

from align.loop import LoopReport
from align.mark_stage import BEND, MarkStage
from imaging import MarkMeasurement, defocus_note, jpeg_note, line_frame

NEGLIGIBLE_BOW = 0.05
"""A bow whose certain effects widen the angle's u by less than this fraction (below ~0.32 u
in quadrature) changes no reading of the angle: carried in u as ``bow_ends`` and
``bow_vs_straight``, the straight fit kept, not named a bent mark."""


def read_mark(stage: MarkStage, rep: LoopReport, m: MarkMeasurement, image: str, index: int,
          alpha: float, lens_bow_px: float, structured: bool | None = None):
    """One reading of the loop's report on a mark: (angle [rad], its u [rad], the offset's
    u [px], the structure inflation, the named u terms [rad], notes, the bow effect or None,
    whether a bowed mark runs off the frame). ``structured``: the structure decision taken
    (None: the report's own)."""
    unexplained = rep.unexplained_structure if structured is None else structured
    a, au = rep.after.quantities["angle_rad"]
    du = rep.after.quantities["offset_px"][1]
    infl = structure_inflation(rep, structured=structured)
    au, du = au * infl * stage.u_scale, du * infl * stage.u_scale
    terms: dict[str, float] = {}
    notes: list[str] = []
    f = rep.after
    if m.jpeg is not None:  # a Type B term: how far the blocks move this groove's angle
        wide = m.jpeg_turn.angle_u(au) if m.jpeg_turn else au  # with its draws' own spread
        terms["jpeg_blocks"], au = float(np.sqrt(max(0.0, wide**2 - au**2))), wide
        notes.append(jpeg_note(f"{image} mark {index}", m.jpeg,
                               float(np.rad2deg(terms["jpeg_blocks"]) * 3600),
                               float(np.median(stage.sigma / m.sigma))))
    # Type B terms: the profile at the grid's phase, a striped background's rest, a worn side
    for name, v in (("groove_profile", m.profile_u_rad), ("striped_background",
                    m.background_u_rad), ("groove_asymmetry", m.asymmetry and m.asymmetry.u_rad)):
        if v:
            terms[name] = v
            au = float(np.hypot(au, v))
    defocus = defocus_note(f"{image} mark {index}", m.blur)
    if defocus:
        notes.append(defocus)
    elif f.dof > 0 and special.chdtr(f.dof, f.chi2) < 1e-6:
        notes.append(f"{image} mark {index}: the centres scatter far less than their stated "
                     f"sigma (chi2/dof {f.chi2 / f.dof:.2f}): the groove model does not fit "
                     "this groove; u kept as stated (a misfit never narrows it)")
    bend = next((e for e in rep.effects if e.name == BEND), None)
    off_frame = False
    if bend is not None:
        # A bent mark has no one direction: its straight fit and its end-to-end chord differ,
        # and which one the user means is not in the image. Its direction is read as the
        # chord between the groove's own ends (the tangent at its middle), and u covers the
        # other readings (the straight fit over the measured centres, the tangent at their
        # middle): the direction meant anywhere between the chord and the farthest of them,
        # uniform (Type B), so about the chord its standard uncertainty is that difference
        # / sqrt 3 (the difference is the bound, not a standard uncertainty).
        chord = float(rep.after.payload["chord_rad"])
        a0 = rep.before.quantities["angle_rad"][0]
        # Where the ends are: a groove's tip (round, square or tapering over about its own
        # width w, blurred by s) puts each half-depth end within +-(w/2 + s), uniform (Type
        # B); their middle then moves by that / sqrt(2), and the chord turns with the
        # curvature times that shift.
        u_mid = (m.profile.width_px / 2 + m.profile.blur_px) / np.sqrt(3) / np.sqrt(2)
        ends = float(abs(rep.after.payload["curvature_per_px"]) * u_mid)
        # (Where the ends lie along the line; across it, the centres' noise near each end
        # moves the chord too: ``chord_u_rad`` with the JPEG factor's spread, ``u_scale``.)
        # A bow is a finding only if it matters to the angle: what it does for certain —
        # its ends term, and the straight fit with the bow's column against without it —
        # must widen u by at least NEGLIGIBLE_BOW. (A 0.025 +- 0.007 px bow on a clean
        # mark, 3.6 sigma, was called bent: its own sigma says it is there, not that it
        # changes any reading.) The chord is in the test only by how far it differs from the
        # fit beyond its own noise (at alpha): its ends' noise is not the bow's, but a groove
        # whose ends lie off the fitted curve (an S the parabola averages away) is read
        # differently end to end, for certain.
        shift = abs(wrap_line_angle(a - a0)) / np.sqrt(3)
        chord_u = float(np.sqrt(ends**2 + (rep.after.payload["chord_u_rad"] * stage.u_scale)**2
                                + rep.after.payload["chord_bound_rad"]**2 / 3))
        off_chord = max(0.0, abs(wrap_line_angle(a - chord))
                        + float(special.ndtri(alpha / 2)) * chord_u)
        if np.hypot(np.hypot(ends, shift), off_chord / np.sqrt(3)) < (
                np.sqrt((1 + NEGLIGIBLE_BOW)**2 - 1) * au):
            terms["bow_ends"], terms["bow_vs_straight"] = ends, shift
            au = float(np.sqrt(au**2 + ends**2 + shift**2))
        else:
            au, off_frame = _bent(terms, notes, m, bend, au, a, a0, chord, chord_u, lens_bow_px,
                                  alpha, f"{image} mark {index}")
            a = chord
    elif unexplained:
        # Structure no effect named (an S-shaped groove, whose odd bow no parabola takes):
        # the straight fit is then not the groove's end-to-end direction for certain, and
        # which one the user means is not in the image: the truth anywhere between the fit
        # and the chord between the groove's ends (or as far as their extrapolation beyond
        # the last centres may carry it), uniform (Type B), about the fit the bound / sqrt 3.
        chord = float(rep.after.payload["chord_rad"])
        terms["structure_chord_vs_fit"] = (abs(wrap_line_angle(a - chord))
                                           + rep.after.payload["chord_bound_rad"]) / np.sqrt(3)
        au = float(np.hypot(au, terms["structure_chord_vs_fit"]))
    return a, au, du, infl, terms, notes, bend, off_frame


def _bent(terms: dict[str, float], notes: list[str], m: MarkMeasurement, bend, au: float,
          a: float, a0: float, chord: float, ends: float, lens_bow_px: float, alpha: float,
          where: str) -> tuple[float, bool]:
    """A bow that matters: read end to end (the chord), u widened to cover the straight fit
    and the ends; named a bent mark beyond what the lens can make. Returns (u [rad], whether
    the bowed mark runs off the image)."""
    bent = abs(bend.estimate) > lens_bow_px + float(-special.ndtri(alpha / 2)) * bend.u
    pre = "bent_mark" if bent else "bow"
    terms[f"{pre}_chord_vs_fit"] = float(max(abs(wrap_line_angle(a - chord)),
                                             abs(wrap_line_angle(a0 - chord))) / np.sqrt(3))
    terms[f"{pre}_ends"] = ends
    if bent:
        notes.append(f"{where}: the mark is bent (sagitta {bend.estimate:+.3g} ± "
                     f"{bend.u:.2g} px; the lens can make at most {lens_bow_px:.2g} px here) "
                     "and the lens does not explain the bow: its direction is ambiguous "
                     "(chord between its ends vs straight fit), u widened to cover both")
    else:
        notes.append(f"{where}: a bow of {bend.estimate:+.3g} ± {bend.u:.2g} px, within what "
                     f"the camera's undetermined lens can make here ({lens_bow_px:.2g} px): "
                     "lens or a bend of the mark; its direction is read end to end, u covers "
                     "the straight fit too")
    au = float(np.sqrt(au**2 + terms[f"{pre}_chord_vs_fit"]**2 + ends**2))
    off_frame = runs_off_frame(m)
    if off_frame:
        notes.append(f"{where}: NOT OK: the bowed mark runs off the image, so its ends are not "
                     "in it: the whole mark's chord (its direction) cannot be read; image the "
                     "whole mark")
    return au, off_frame


def runs_off_frame(m: MarkMeasurement) -> bool:
    """Whether an end of the groove (its half-depth end in the raw image) lies within its
    blurred half-width of the frame's edge: the mark may go on beyond it."""
    h, w = m.image_shape
    u, n = line_frame(m.profile.angle_rad)
    reach = m.profile.width_px / 2 + 3 * m.profile.blur_px + 2
    for t in m.extent_px:
        x, y = m.profile.offset_px * n + t * u
        if abs(x) > (w - 1) / 2 - reach or abs(y) > (h - 1) / 2 - reach:
            return True
    return False


def wrap_line_angle(a: float) -> float:
    """A line's angle (or a difference of two) wrapped to [-pi/2, pi/2) [rad]."""
    return float((a + np.pi / 2) % np.pi - np.pi / 2)


def structure_inflation(rep: LoopReport, alpha_low: float = 1e-6,
                        structured: bool | None = None) -> float:
    """Factor on the stated uncertainty when the residual keeps unexplained structure.

    ``structured`` overrides the report's own structure decision (None: keep it; the other
    side of a decision on the edge, :mod:`align.mark_choice`).

    Never below 1: an improbably small chi2 (lower tail below ``alpha_low``) is a groove
    model that does not fit, not a licence to shrink u.

    Correlated residuals carry less information than independent ones: with lag-1
    correlation rho the variance of a fitted slope grows by about (1 + rho) / (1 - rho)
    (AR(1) noise), and an excess chi2/dof scales it further. 1 for a clean fit.
    """
    f = rep.after
    if f.dof > 0 and special.chdtr(f.dof, f.chi2) < alpha_low:
        # The centres scatter far less than their stated sigma: the groove model's shape
        # does not describe this groove. A model misfit never narrows u (a defocus gradient
        # once got x0.4 here and scattered at twice its u): u stays as stated, and the
        # misfit is reported (warnings).
        return 1.0
    if not (rep.unexplained_structure if structured is None else structured):
        return 1.0
    z = (f.residuals / f.sigma)[np.argsort(f.regressors[f.order])]
    zc = z - z.mean()
    rho = float(np.clip(zc[1:] @ zc[:-1] / max(zc @ zc, 1e-300), 0.0, 0.9))
    return float(np.sqrt(max(1.0, f.chi2 / max(f.dof, 1)) * (1 + rho) / (1 - rho)))
