"""Camera frames of a mirrored scene, rendered in a process of their own.

Software rendering holds the interpreter for the whole frame (~15 ms at 640x480 here):
in the host process it would stall a real-time control loop by as much, whatever thread
asks for it. The server (``python -m rehabkit.hardware.frame_server``, started by
:class:`FrameServer`) gets the scene's compiled model once; a frame request sends the pose
(``qpos`` and the kinematic objects) and waits for the pixels on a pipe, so the loop runs
meanwhile. Requests are serialised by a lock. The server runs with one rasteriser thread and, for a
real-time loop, as an idle-priority task: frames yield to the control loop and to the robot's bridge. A loop on the
lock-step clock waits for each frame (it has no deadline to keep), so there the server runs at normal priority: at
idle priority a machine with every core busy starved it, and every frame held the loop up by as long (measured on
this 2-core VM beside three busy processes: 30-370 ms a frame at idle priority, 8-18 ms at normal).
"""

from __future__ import annotations

import os
import pickle
import subprocess
import sys
import threading

import mujoco
import numpy as np
from threadpoolctl import threadpool_limits

from rehabkit.sim.scene_view import camera_renderer


def _serve(inp, out, idle: bool = True) -> None:  # pragma: no cover - runs in the server process
    if idle:
        try:  # frames run only when nothing else wants the CPU: a waking control loop preempts them at once
            os.sched_setscheduler(0, os.SCHED_IDLE, os.sched_param(0))
        except (AttributeError, OSError):  # not Linux: the next best thing
            os.nice(10)
    os.environ.setdefault("LP_NUM_THREADS", "1")  # read when the first GL context is made, below
    threadpool_limits(limits=1, user_api="blas")  # nothing here is BLAS work worth a spinning thread
    model: mujoco.MjModel = pickle.load(inp)
    data = mujoco.MjData(model)
    renderers: dict[tuple[int, int], mujoco.Renderer] = {}
    mujoco.Renderer(model, 8, 8).close()  # the GL display and driver start now, not in the first frame
    pickle.dump("ready", out)
    out.flush()
    try:
        while (request := pickle.load(inp)) is not None:
            qpos, mocap_pos, mocap_quat, camera, width, height = request
            data.qpos[:], data.mocap_pos[:], data.mocap_quat[:] = qpos, mocap_pos, mocap_quat
            mujoco.mj_kinematics(model, data)
            mujoco.mj_camlight(model, data)
            try:
                key = (width, height)
                if key not in renderers:
                    renderers[key] = camera_renderer(model, width, height)
                renderers[key].update_scene(data, camera=camera)
                reply = renderers[key].render().tobytes()
            except Exception as exc:  # noqa: BLE001 (the asking side raises it)
                reply = f"{type(exc).__name__}: {exc}"
            pickle.dump(reply, out, protocol=pickle.HIGHEST_PROTOCOL)
            out.flush()
    except EOFError:
        pass
    finally:
        for r in renderers.values():
            r.close()


class FrameServer:
    """A rendering process for one compiled scene; ``idle``: at idle priority (beside a real-time loop), else at
    normal priority (a loop that waits for its frames)."""

    def __init__(self, model: mujoco.MjModel, idle: bool = True):
        self._proc = subprocess.Popen([sys.executable, "-m", __name__, *([] if idle else ["--normal-priority"])],
                                      stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL)
        pickle.dump(model, self._proc.stdin)
        self._proc.stdin.flush()
        self._lock = threading.Lock()
        self._ready = False

    def wait_ready(self) -> None:
        """Block until the server can render: its imports and GL start-up are CPU-heavy, not for a run."""
        if not self._ready:
            try:
                if pickle.load(self._proc.stdout) != "ready":
                    raise EOFError
            except EOFError:
                raise RuntimeError(f"the frame server did not start (exit code {self._proc.poll()})") from None
            self._ready = True

    def render(self, data: mujoco.MjData, camera: str, width: int, height: int) -> np.ndarray:
        """The camera's RGB image (height, width, 3) of the scene posed as ``data``."""
        with self._lock:
            self.wait_ready()
            pickle.dump((data.qpos.copy(), data.mocap_pos.copy(), data.mocap_quat.copy(), camera, width, height),
                        self._proc.stdin)
            self._proc.stdin.flush()
            reply = pickle.load(self._proc.stdout)
        if isinstance(reply, str):
            raise RuntimeError(f"camera '{camera}': the frame server failed: {reply}")
        return np.frombuffer(reply, np.uint8).reshape(height, width, 3)

    def close(self) -> None:
        try:
            pickle.dump(None, self._proc.stdin)
            self._proc.stdin.close()
        except (BrokenPipeError, OSError):
            pass
        try:
            self._proc.wait(timeout=5)
        except subprocess.TimeoutExpired:
            self._proc.kill()
            self._proc.wait()
        self._proc.stdout.close()


if __name__ == "__main__":
    _serve(sys.stdin.buffer, sys.stdout.buffer, idle="--normal-priority" not in sys.argv[1:])
