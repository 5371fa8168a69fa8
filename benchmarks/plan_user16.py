"""`align plan` on user 16's cameras: is the noise of "another image" honest? Every ranked
"another image" option of user 16's sessions (two microscope cameras, their reversal views,
tests/imaging/user16_inputs.py) realised with the user's generator; z = (obtained u -
predicted u) / stated noise on the critical angle (tests/align/test_plan.py, whose slow test
runs seeds 4, 7, 11 of this).

Run:  python3 benchmarks/plan_user16.py [--seeds 4-22]

Prints one line per option and the mean, RMS and largest |z|. About 40 s of CPU a session
(5-6 runs of 1280×1024 images).
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

import benchpage

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests" / "align"))


def main() -> None:
    from test_plan import user16_one_more_image_z

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seeds", default="4-22", help="first-last (inclusive)")
    a = ap.parse_args()
    lo, hi = (int(v) for v in a.seeds.split("-"))
    with tempfile.TemporaryDirectory() as tmp:
        user16_one_more_image_z(Path(tmp), range(lo, hi + 1))


if __name__ == "__main__":
    benchpage.run(main, "align plan: the noise of another image on user 16's cameras")
