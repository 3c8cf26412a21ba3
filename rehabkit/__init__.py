"""rehabkit: rehabilitation and assistive robotics scenarios, from YAML to MuJoCo and Rerun."""

import os
import sys

# Offscreen rendering without a display: EGL works on CPU-only machines; MuJoCo reads this once, on first use.
if sys.platform.startswith("linux") and not os.environ.get("DISPLAY") and not os.environ.get("WAYLAND_DISPLAY"):
    os.environ.setdefault("MUJOCO_GL", "egl")

from rehabkit.core.plugins.hookspecs import hookimpl  # noqa: E402
from rehabkit.core.version import __version__  # noqa: E402


def __getattr__(name: str):
    # the heavy parts (MuJoCo, Pinocchio, Rerun) load on first use, so that plugins
    # importing `hookimpl` stay cheap to import
    if name in ("run_scenario",):
        from rehabkit import api

        return getattr(api, name)
    if name in ("load_scenario", "ScenarioError", "RunResult"):
        from rehabkit.core.run.runner import RunResult
        from rehabkit.core.scenario.errors import ScenarioError
        from rehabkit.core.scenario.loader import load_scenario

        return {"load_scenario": load_scenario, "ScenarioError": ScenarioError, "RunResult": RunResult}[name]
    raise AttributeError(f"module 'rehabkit' has no attribute {name!r}")


__all__ = ["hookimpl", "run_scenario", "load_scenario", "ScenarioError", "RunResult", "__version__"]
