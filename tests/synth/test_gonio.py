"""synth's goniometer physics: clockwise runs and the pyramidal-error x slit-tilt coupling."""

from __future__ import annotations

import numpy as np

from align.gonio import measure_log
from synth.gonio import GonioSpec, simulate, write_log

ARCSEC = np.pi / 180 / 3600


def test_pyramidal_error_with_a_tilted_slit_shifts_the_pulses_in_both_directions(tmp_path):
    """A face normal tilted 60" out of the horizontal with the detector slit 2 deg off vertical
    fires p tan e = 2.1" late, whichever way the table turns: the measured angles follow the
    pulses, not the normals, and the mean of both directions keeps the shift (no reversal on
    the table removes it — only a vertical slit or level faces)."""
    pyr = (0.0, 60 * ARCSEC, -40 * ARCSEC, 0.0)
    kw = dict(revolutions=300, pyramidal_rad=pyr, slit_tilt_rad=np.deg2rad(2.0), latency_s=0.0)
    s1 = simulate(GonioSpec(seed=1, **kw))
    s2 = simulate(GonioSpec(seed=2, direction=-1, **kw))
    p1, p2 = write_log(s1, tmp_path / "ccw.csv"), write_log(s2, tmp_path / "cw.csv")
    spec = GonioSpec(**kw)
    normals = spec.angles
    shift = np.diff(np.append(spec.trigger_azimuths, 2 * np.pi)) - normals
    assert np.max(np.abs(shift)) > 1.5 * ARCSEC
    both = measure_log(p1, 4, np.deg2rad(50.45), reverse_log=p2)
    fa = both.angles
    assert np.all(np.abs(fa.angles_rad - (normals + shift)) < 4.5 * fa.u_rad)
    assert np.max(np.abs(fa.angles_rad - normals) / fa.u_rad) > 10
    # The log's own truth file keeps the normals.
    assert np.allclose(s1["truth"]["angles_rad"], normals)
