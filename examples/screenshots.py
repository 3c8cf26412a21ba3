"""Screenshots of the built-in scenarios as Rerun's web viewer shows their recordings, for the README.

    pip install -e ".[screenshots]"   # Playwright's Python driver (it drives the machine's own Chromium)
    python examples/screenshots.py [--only hit] [--out examples/screenshots] [--chromium /usr/bin/chromium]

Each scenario is run (``rehabkit run ... --out out/screenshots/NAME``), its ``run.rrd`` opened alone — nothing but
the file, as a person would — in Rerun's web viewer served on loopback, and the page photographed by headless
Chromium with software WebGL (``--use-angle=swiftshader``) once it has drawn: two pictures a second apart that are
the same, after the data has loaded. Run it again whenever what a recording holds changes.
"""

from __future__ import annotations

import argparse
import os
import shutil
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path
from urllib.parse import quote

ROOT = Path(__file__).resolve().parents[1]
SHOTS = {  # name -> (scenario, --set overrides)
    "hit": ("scenarios/hit_roundtrip.yaml", []),
    "lexos_myoarm": ("scenarios/lexos_myoarm.yaml", []),
    "keep_in_breach": ("examples/hit_keep_in_breach.yaml", []),
    "capaman": ("scenarios/capaman_obstacle.yaml", []),
    "coman": ("scenarios/coman_juggling.yaml", []),
}
CHROMIUM_FLAGS = ["--no-sandbox", "--use-angle=swiftshader", "--use-gl=angle", "--enable-unsafe-swiftshader",
                  "--disable-background-networking", "--disable-component-update", "--disable-sync", "--no-first-run"]
SIZE = {"width": 1600, "height": 900}


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def record(name: str, scenario: str, overrides: list[str], out: Path) -> Path:
    """The scenario's recording, made afresh."""
    folder = out / name
    cmd = [sys.executable, "-m", "rehabkit.cli", "run", str(ROOT / scenario), "--out", str(folder)]
    for o in overrides:
        cmd += ["--set", o]
    done = subprocess.run(cmd, capture_output=True, text=True, cwd=ROOT)
    if done.returncode not in (0, 1):  # (1: a verdict failed, as the keep-in breach's may; the file is whole)
        raise SystemExit(f"{name}: rehabkit run failed:\n{done.stderr[-2000:]}")
    return folder / "run.rrd"


def photograph(rrd: Path, png: Path, chromium: str, settle_s: float = 8.0, timeout_s: float = 120.0) -> None:
    """``rrd`` in Rerun's web viewer on loopback, photographed once it has drawn."""
    from playwright.sync_api import sync_playwright

    web, grpc = free_port(), free_port()
    viewer = subprocess.Popen([shutil.which("rerun"), "--web-viewer", "--bind", "127.0.0.1", "--web-viewer-port",
                               str(web), "--port", str(grpc), "--renderer", "webgl", str(rrd)],
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
    try:
        url = f"http://127.0.0.1:{web}/?url={quote(f'rerun+http://127.0.0.1:{grpc}/proxy', safe='')}&renderer=webgl"
        with sync_playwright() as p:
            browser = p.chromium.launch(executable_path=chromium, headless=True, args=CHROMIUM_FLAGS)
            page = browser.new_page(viewport=SIZE)
            deadline = time.monotonic() + timeout_s
            while True:  # the viewer's page is up once the server answers
                try:
                    page.goto(url)
                    break
                except Exception:  # noqa: BLE001 (not listening yet)
                    if time.monotonic() > deadline:
                        raise
                    time.sleep(0.5)
            time.sleep(settle_s)  # the data streams in, then the views lay out and draw
            last = page.screenshot()
            while time.monotonic() < deadline:
                time.sleep(1.0)
                shot = page.screenshot()
                if shot == last:
                    break
                last = shot
            png.write_bytes(last)
            browser.close()
    finally:  # the whole group: `rerun` is a launcher whose viewer is a process of its own
        os.killpg(viewer.pid, signal.SIGTERM)
        viewer.wait(timeout=10)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--only", action="append", choices=sorted(SHOTS), help="these scenarios only (repeatable)")
    ap.add_argument("--out", type=Path, default=ROOT / "examples" / "screenshots", help="where the PNGs go")
    ap.add_argument("--runs", type=Path, default=ROOT / "out" / "screenshots", help="where the recordings go")
    ap.add_argument("--chromium", default=shutil.which("chromium") or "/usr/bin/chromium")
    args = ap.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    for name in args.only or SHOTS:
        scenario, overrides = SHOTS[name]
        rrd = record(name, scenario, overrides, args.runs)
        png = args.out / f"{name}.png"
        photograph(rrd, png, args.chromium)
        print(f"{name}: {png.relative_to(ROOT) if png.is_relative_to(ROOT) else png} ({rrd.stat().st_size} bytes "
              "of recording)")


if __name__ == "__main__":
    main()
