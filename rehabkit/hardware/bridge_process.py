"""The robot-side bridge as a process of the host's: started for a rehearsal on the robot's MuJoCo model, stopped
with the run."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
from dataclasses import asdict

from rehabkit.core.kinds.interfaces import Context


def spawn_bridge(context: Context, config) -> tuple[subprocess.Popen, int]:
    """Start ``rehabkit bridge`` for the run's robot (its MuJoCo model as the plant), with the run's limits;
    returns the process and the UDP port it serves on."""
    spec = context.robot_spec
    cmd = [sys.executable, "-m", "rehabkit.cli", "bridge", spec["type"], "--config", json.dumps(spec),
           "--port", str(config.port), "--rate", str(1.0 / config.timestep), "--robot-id", str(config.robot_id),
           "--watchdog-ms", str(config.bridge_watchdog_ms), "--stale-ms", str(config.bridge_stale_ms),
           "--parent-pid", str(os.getpid()), *(["--lockstep"] if config.clock == "lockstep" else []),
           # the run's torque limits (the envelope's may be tighter than the robot's): the bridge clips to them
           "--effort", json.dumps(context.robot.model.limits.effort.tolist()),
           # and checks the run's ranges and speeds on its own, a margin wider than the host's safety layer
           "--limits", json.dumps({k: getattr(context.robot.model.limits, k).tolist()
                                   for k in ("lower", "upper", "velocity")}),
           # the run's instruments (a force-torque sensor's, with a simulated sensor's errors), read by the plant and
           # sent with each state, and a test rig's loads on the plant
           "--instruments", json.dumps([asdict(i) for i in context.instruments]),
           "--loads", json.dumps([x.model_dump(mode="json") for x in (context.world.loads if context.world else [])]),
           "--seed", str(context.seed or 0)]
    if config.key_file is not None:  # the same key file (the path, never the key, on the command line)
        cmd += ["--key", str(context.resolve(config.key_file))]
    # stderr to a file, never a pipe nobody reads: a full pipe would block the bridge mid-run
    log = tempfile.TemporaryFile(mode="w+")  # noqa: SIM115 (lives as long as the bridge process)
    # in the scenario's folder: the robot's files (a URDF beside the scenario) resolve there as on the host
    # in a session of its own: a terminal's Ctrl-C (sent to its whole foreground process group) reaches the host alone,
    # which brings the robot to rest through the bridge, then stops it (it stops on its own once the host is gone)
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=log, text=True, cwd=context.scenario_dir,
                            start_new_session=True)
    line = proc.stdout.readline()  # "bridge: <robot> on udp://host:port"
    if not line.startswith("bridge:"):
        proc.kill()
        proc.wait()
        proc.stdout.close()
        log.seek(0)
        with log:
            raise ValueError(f"the bridge did not start: {line.strip() or log.read().strip()[-2000:]}")
    log.close()  # (the bridge writes to its own copy; this one was for a bridge that does not start)
    return proc, int(line.rsplit(":", 1)[1])


def stop_bridge(process: subprocess.Popen | None) -> None:
    """Terminate the bridge (killed if it does not stop within 2 s)."""
    if process is None:
        return
    process.terminate()
    try:
        process.wait(timeout=2)
    except subprocess.TimeoutExpired:
        process.kill()
        process.wait()
    if process.stdout is not None:
        process.stdout.close()
