"""What helps a lens-limited angle: the advice at the end of its "NOT OK" line (docs/camera.md,
"When the tool cannot tell")."""

from __future__ import annotations

import numpy as np

from align.camera_lens import CAMERA_MODEL, MOVED_OR_BENT, CameraLens
from imaging import MarkMeasurement


def lens_advice(lens: CameraLens, m: MarkMeasurement, worst: str = "") -> str:
    """What helps a lens-limited angle: without a camera model, calibrating the camera and
    giving the model; with one the marks depart from, what tells a bent mark from a changed
    lens (``worst`` ``camera_or_bent``; a moved principal point: ``camera_moved_or_bent``) or
    recalibrating; with one they agree with, the
    model's own u is the limit (where the mark lies)."""
    # With a camera model given, "give it with --camera" is no advice: the user did.
    if lens.record.get("camera_model") == "departed from":
        if worst == "camera_or_bent":
            # One mark (or marks too near the centre) cannot tell a bent mark from a lens
            # that is not its calibration: straight marks elsewhere in the frame can (they
            # stay straight under the calibrated lens, and bow as a changed one predicts).
            return ("its bow is a bent mark's or a lens's that is not the calibration, and "
                    "this frame cannot tell which (see the camera's note): image straight "
                    "marks elsewhere in the frame with it (if they stay straight, this mark "
                    "is read as bent and the calibration kept), or recalibrate (`align "
                    "camera`) if the lens may have changed")
        return "the marks say the lens is not its calibration: recalibrate (`align camera`)"
    if worst == MOVED_OR_BENT:
        # A principal point's move and a bent mark explain the frame alike: straight marks
        # that a move would bow (far from the centre) tell them apart.
        declare = ("" if lens.record.get("pp_stability_declared") else
                   "declare the camera's principal-point stability (`--lens pp_stability_px=`"
                   ", `[cameras.X] lens_pp_stability_px`), ")
        return ("the bows read as the principal point's move since calibration or as a bent "
                "mark, and this frame cannot tell which (see the camera's note): "
                f"{declare}image more marks in this frame (straight ones far from the centre), "
                "or recalibrate (`align camera`) if the camera may have been knocked")
    if lens.record.get("source") != CAMERA_MODEL:
        return f"calibrate the camera (`align camera`) and give it with {lens.model_as}"
    x, y = np.mean(m.points, axis=0)
    return (f"the camera model's own u limits it where this mark lies, ({x:+.0f}, {y:+.0f}) px "
            f"from the image centre ({np.hypot(x, y):.0f} px out): recalibrate (`align camera`) "
            "with more chessboard views, spread so the boards cover this region of the frame, "
            "or measure a mark nearer the centre")
