"""The first screens of the two reports, as docs/reports.md shows them, and the pages' sizes.

    python3 benchmarks/report_screens.py [--out FOLDER]

Runs ``align demo`` (seed 1), makes a lot of 40 units from its result (synth.lot: 10 ± 2″ per
angle; unit 12's E_xZ and unit 30's E_zX pushed outside ±30″, unit 21's E_yX set 1 u inside
it: two FAIL, one INCONCLUSIVE), runs ``align lot --tolerance-arcsec 30`` and takes a
1280 × 900 screenshot of each page in headless Chromium (Debian package ``chromium``).
"""

from __future__ import annotations

import argparse
import datetime as dt
import json
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import benchpage

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from align.cli import main  # noqa: E402
from synth.lot import lot_results  # noqa: E402

ARCSEC = 3.141592653589793 / 180 / 3600


def shot(page: Path, png: Path) -> None:
    browser = next((b for b in ("chromium", "chromium-browser", "google-chrome")
                    if shutil.which(b)), None)
    if browser is None:
        print("no headless Chromium: no screenshot")
        return
    subprocess.run([browser, "--headless", "--no-sandbox", "--disable-gpu", "--hide-scrollbars",
                    "--window-size=1280,900", f"--screenshot={png}", page.as_uri()],
                   capture_output=True, timeout=120, check=True)
    print(f"screenshot {png}")


def run(out: Path) -> None:
    demo = out / "demo"
    assert main(["demo", "--out", str(demo), "-q"]) == 0
    page = demo / "report.html"
    print(f"session report {page}: {page.stat().st_size / 1000:.0f} kB")
    shot(page, out / "report-session-first-screen.png")
    real = json.loads((demo / "result.json").read_text())
    real["metadata"] = dict(real["metadata"], lot="L-2026-47")
    results, _ = lot_results(real, 40, seed=7, mean_rad=[10 * ARCSEC] * 6,
                             sigma_rad=2 * ARCSEC, shifts={12: (1, 12.5), 30: (4, -21.0)},
                             metadata={"operator": ["kim", "lee"], "lot": ["L-2026-47"]},
                             start=dt.datetime(2026, 11, 2, 6, 0))
    u = results[21]["misalignment_u_rad"][1][0]
    results[21]["misalignment_rad"][1][0] = 30 * ARCSEC - u  # inside by 1 u: inconclusive
    folder = out / "results"
    folder.mkdir()
    for d in results:
        (folder / f"{d['session']}.json").write_text(json.dumps(d))
    shutil.copy(page, folder / f"{results[12]['session']}.html")  # a unit's report at hand
    lot = out / "lot.html"
    main(["lot", str(folder), "--report", str(lot), "--tolerance-arcsec", "30", "-q"])
    print(f"lot report {lot}: {lot.stat().st_size / 1000:.0f} kB")
    shot(lot, out / "report-lot-first-screen.png")



def screens() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, help="a new folder (default: a temporary one)")
    a = ap.parse_args()
    out = a.out or Path(tempfile.mkdtemp(prefix="report-screens-"))
    out.mkdir(parents=True, exist_ok=True)
    run(out)


if __name__ == "__main__":
    benchpage.run(screens, "Reports: first screens and page sizes")
