"""The goniometer's face plan: the rules the fusion relies on, one place for every interface.

Face 0 is the reference face (the pulse the binding signal marks): the azimuths of housings x
and y are taken relative to it, so it cannot itself be a housing. Housings x and y are
perpendicular, so a plan whose nominal angles put their faces other than 90° apart (mod 180°)
contradicts itself. ``align gonio`` (flags) and ``session.toml`` (keys) both call
:func:`check_face_plan`, each naming what the user wrote.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from axisbase.errors import InputError

HOUSINGS = ("x", "y", "z")
PERPENDICULAR_TOLERANCE_RAD = np.deg2rad(1.0)
"""How far from 90° (mod 180°) the nominal gap between faces x and y may be [rad]."""


def check_face_plan(faces: Sequence[str], nominal_rad: np.ndarray | None, faces_name: str,
                    nominal_name: str) -> None:
    """Refuse a face plan the fusion cannot use, naming the flag or key.

    Parameters
    ----------
    faces : sequence of str
        Face names in passing order, the reference face first.
    nominal_rad : numpy.ndarray or None
        The nominal angle from each face to the next [rad] (None: equal angles).
    faces_name, nominal_name : str
        How the user wrote the faces and the nominal angles (``--faces ref,x,z,y``,
        ``session.toml: [goniometer] nominal_deg = [...]``): the messages start with them.

    Raises
    ------
    InputError
        The reference face is a housing, or the nominal angles put faces x and y other than
        90° apart (mod 180°).

    Examples
    --------
    >>> check_face_plan(["ref", "y", "x", "z"], None, "--faces", "--nominal")
    >>> check_face_plan(["ref", "x", "z", "y"], None, "--faces ref,x,z,y", "--nominal")
    ... # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    axisbase.errors.InputError: --nominal: faces x and y would be 0.000° apart (mod 180°); ...
    """
    if faces[0] in HOUSINGS:
        raise InputError(f"{faces_name}: the first face is the reference face (marked by the "
                         f"binding signal); {faces[0]!r} is a housing")
    nom = (np.full(len(faces), 2 * np.pi / len(faces)) if nominal_rad is None
           else np.asarray(nominal_rad, float))
    rel = {f: -nom[:k].sum() for k, f in enumerate(faces)}  # the sign does not matter here
    if "x" in rel and "y" in rel:
        gap = (rel["y"] - rel["x"]) % np.pi
        if abs(gap - np.pi / 2) > PERPENDICULAR_TOLERANCE_RAD:
            raise InputError(f"{nominal_name}: faces x and y would be {np.rad2deg(gap):.3f}° "
                             "apart (mod 180°); the axes are perpendicular — contradictory "
                             "nominal orientation")
