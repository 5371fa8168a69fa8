"""Shared fixtures: seeded synthetic images (every failure reproducible from its seed)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from synth import ImageSpec, MarkSpec, full_well_for_snr, render_marks

REAL = Path(__file__).resolve().parents[2] / "shared" / "data" / "real"
ARCSEC = np.pi / 180 / 3600


def real_folder(name: str) -> Path:
    p = REAL / name
    if not p.is_dir():
        pytest.skip(f"real data folder {p} is absent (it lives in ../shared/data/real)")
    return p


def angle_error(measured: float, truth: float) -> float:
    """Difference of two line directions, wrapped to (-pi/2, pi/2] [rad]."""
    return (measured - truth + np.pi / 2) % np.pi - np.pi / 2


def mark_image(angle_deg: float, seed: int, snr: float = 30.0, width_px: float = 4.0,
               length_px: float = 500.0, offset_px: float = 12.3, size=(800, 600),
               with_crlb: bool = True, **kw):
    spec = ImageSpec(
        marks=(MarkSpec(np.deg2rad(angle_deg), offset_px, length_px, width_px,
                        centre_t_px=kw.pop("centre_t_px", 0.0),
                        contrast=kw.pop("contrast", -0.6)),),
        width=size[0], height=size[1], full_well_e=full_well_for_snr(snr, -0.6), seed=seed,
        **kw)
    return render_marks(spec, with_crlb=with_crlb)


@pytest.fixture
def tmp_out(tmp_path: Path) -> Path:
    return tmp_path
