"""A shadow's edge running along a mark: the mark measured on the light with the edge divided out.

A straight shadow edge at a few degrees to a mark lies beside (or under) its groove over
most of its length: each segment's background steps inside its profile window, which the
segment model (a level and a slope across) does not take, and the centres are biased (a
5 deg, 50 % edge: 2-34 u). The edge is fitted to the background beside the mark
(:func:`imaging.shadow_free`: its factor on the light is 1 - D Phi(s / w), straight) and the
mark measured again on the image divided by that factor, with a note naming the edge.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from imaging import (
    CameraModel,
    ImageInputError,
    MarkMeasurement,
    measure_candidate,
    shadow_free,
)
from imaging.io import full_scale

Edge = tuple[float, float, float, float]
"""A shadow's edge: angle to the mark [rad], offset at its middle [px], penumbra sigma [px],
depth (the light's fraction lost beyond it)."""


def unshadowed(items: Sequence[MarkMeasurement | ImageInputError], image: np.ndarray,
               camera: CameraModel | None, name: str
               ) -> tuple[list[MarkMeasurement | ImageInputError], dict[int, Edge]]:
    """The frame's marks, each one that a shadow's edge runs along measured again on the
    image with the edge's shadow divided out, and that edge of each such mark (keyed by
    the ``id`` of the mark's new measurement or error: a later split renumbers the marks).

    Parameters
    ----------
    items : sequence of MarkMeasurement or ImageInputError
        The frame's marks as measured.
    image : numpy.ndarray
        The image they were measured on [DN].
    camera : imaging.CameraModel or None
        The camera model they were measured with.
    name : str
        The image, as notes name it.

    Returns
    -------
    list, dict
        The marks (re-measured where an edge runs along them) and their edges (angle to
        the mark [rad], offset at its middle [px], penumbra sigma [px], depth).
    """
    top = full_scale(image)
    out: list[MarkMeasurement | ImageInputError] = []
    edges: dict[int, Edge] = {}
    for m in items:
        free = None if isinstance(m, ImageInputError) else shadow_free(image, m.candidate, top)
        if free is not None:
            img, edge = free
            try:
                # In the same frame (the file's encoder, the marks crossing it, the lines
                # beside it, the stripes' offsets): only the shadow is divided out.
                m = measure_candidate(img, m.candidate, camera, name, top, m.around)
            except ImageInputError as exc:
                m = exc
            edges[id(m)] = edge
        out.append(m)
    return out, edges


def shadow_edge_note(where: str, edge: Edge) -> str:
    """The note naming the shadow's edge a mark was measured under (``where``: the mark as
    messages name it)."""
    turn, off, width, depth = edge
    return (f"{where}: a shadow's edge runs along the mark (at {np.rad2deg(turn):+.1f}° to "
            f"it, {100 * abs(depth):.0f} % deep, penumbra {width:.1f} px, {off:+.0f} px "
            "from it at its middle): measured on the light with the edge's shadow divided out")
