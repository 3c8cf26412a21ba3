"""The README's picture of ``rehabkit progress``: five simulated sessions of one person, their dataset, the page, and
the page as headless Chromium shows it.

    pip install -e ".[screenshots]"   # Playwright's Python driver (it drives the machine's own Chromium)
    python examples/progress_screenshot.py [--out examples/screenshots/progress.png] [--chromium /usr/bin/chromium]

The person is the L-Exos patient P01 (``scenarios/lexos_patient.yaml``, a ``simulated-arm``) in five sessions whose
voluntary participation rises from 0.4 to 0.8 — a recovery made up for the picture — each run with its bag
(``--bag``), exported with ``rehabkit export bids`` and drawn with ``rehabkit progress``; then photographed as
``examples/screenshots.py`` photographs recordings (software WebGL, the same Chromium flags).
"""

from __future__ import annotations

import argparse
import shutil
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(Path(__file__).resolve().parent))
from screenshots import CHROMIUM_FLAGS  # noqa: E402 (beside this file)

SESSIONS = 5


def rehabkit(*args: str) -> None:
    done = subprocess.run([sys.executable, "-m", "rehabkit.cli", *args], capture_output=True, text=True, cwd=ROOT)
    if done.returncode not in (0, 1):  # (1: a verdict)
        raise SystemExit(f"rehabkit {' '.join(args)} failed:\n{done.stderr[-2000:]}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", type=Path, default=ROOT / "examples" / "screenshots" / "progress.png")
    ap.add_argument("--runs", type=Path, default=ROOT / "out" / "progress_screenshot", help="the sessions and dataset")
    ap.add_argument("--chromium", default=shutil.which("chromium") or "/usr/bin/chromium")
    args = ap.parse_args()
    shutil.rmtree(args.runs, ignore_errors=True)
    folders = []
    for k in range(1, SESSIONS + 1):
        folder = args.runs / f"ses{k}"
        participation = 0.4 + 0.4 * (k - 1) / (SESSIONS - 1)
        rehabkit("run", "scenarios/lexos_patient.yaml", "--bag", "--out", str(folder), "--set", f"patient.session={k}",
                 "--set", f"seed={k}", "--set", f"patient.model.voluntary.participation={participation:.2f}")
        folders.append(str(folder))
    dataset = args.runs / "bids"
    rehabkit("export", "bids", *folders, "--out", str(dataset), "--study", "examples/study.yaml")
    page = args.runs / "progress.html"
    rehabkit("progress", str(dataset), "--out", str(page))
    from playwright.sync_api import sync_playwright

    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=args.chromium, headless=True, args=CHROMIUM_FLAGS)
        view = browser.new_page(viewport={"width": 1000, "height": 900})
        view.goto(page.resolve().as_uri())
        view.wait_for_load_state("load")
        drawn = view.eval_on_selector_all("img", "els => els.every(e => e.complete && e.naturalWidth > 0)")
        if not drawn:
            raise SystemExit("the page's figures did not load")
        args.out.parent.mkdir(parents=True, exist_ok=True)
        view.screenshot(path=str(args.out), full_page=True)
        browser.close()
    print(f"{args.out}: the progress page of {SESSIONS} sessions ({page})")


if __name__ == "__main__":
    main()
