"""A hardware run's view of its scene: the host's mirror, frames from the render process, sensor threads."""

import threading
from pathlib import Path

import numpy as np
import pytest

from rehabkit.core.kinds.interfaces import Context, Sensor
from rehabkit.core.run.sensor_threads import SensorThreads
from rehabkit.core.scenario.loader import load_scenario
from rehabkit.hardware.frame_server import FrameServer
from rehabkit.hardware.mirrored_scene import SceneMirror
from rehabkit.sim.mujoco import MujocoBackend, MujocoConfig
from tests.conftest import SCENARIOS


def test_the_mirror_renders_what_the_simulation_shows_at_the_same_pose(lexos):
    world = load_scenario(SCENARIOS / "lexos_reaching.yaml").model.world
    ctx = Context(Path("."), np.random.default_rng(0), 0.001, robot=lexos, world=world)
    sim = MujocoBackend(MujocoConfig(), ctx)
    q = np.radians([35.0, -30.0, 10.0, -60.0])
    sim.reset(q)
    ball = np.array([0.7, 0.2, 0.85])
    sim.move_object("ball", ball)
    sim.step(1)  # the mocap ball moves with the next step
    mirror = SceneMirror(lexos.model, world)
    mirror.move_object("ball", ball)
    _, q_sim, _ = sim.state()
    view = mirror.frame(q_sim, sim.joint_positions(["q5_pronation"]))
    frames = FrameServer(mirror.model)
    try:
        image = frames.render(view.data, "overhead", 320, 240)
    finally:
        frames.close()
    expected = sim.render("overhead", 320, 240)
    sim.close()
    assert image.shape == expected.shape == (240, 320, 3)
    assert np.abs(image.astype(int) - expected.astype(int)).mean() < 0.5  # the same picture
    red = (image[..., 0] > 150) & (image[..., 1] < 80)
    assert red.sum() > 50  # the ball is in it
    np.testing.assert_allclose(view.object_position("ball"), ball, atol=1e-12)
    for a, b in zip(view.camera_pose("overhead"), sim.camera_pose("overhead")):
        np.testing.assert_allclose(a, b, atol=1e-12)
    np.testing.assert_allclose(view.ee_position(), lexos.ee_world(q_sim[None])[0], atol=1e-9)


class _Slow(Sensor):
    blocking = True

    def __init__(self):
        self.go = threading.Event()
        self.fail = False
        self.unplugged = RuntimeError("camera unplugged")

    def read(self, t, q, qd, backend):
        self.go.wait(5)
        if self.fail:
            raise self.unplugged
        return {"image": np.zeros((4, 4, 3), np.uint8), "value": t}


def test_a_blocking_sensor_reads_in_its_thread_and_overruns_are_counted():
    sensor = _Slow()
    threads = SensorThreads(["cam"], prepare=lambda r: {**r, "prepared": True})
    try:
        threads.start("cam", sensor, 0.1, np.zeros(2), np.zeros(2), None)
        threads.start("cam", sensor, 0.2, np.zeros(2), np.zeros(2), None)  # still reading: skipped
        assert threads.busy and threads.finished() == [] and threads.overruns["cam"] == 1
        sensor.go.set()
        for _ in range(500):
            done = threads.finished()
            if done:
                break
            threading.Event().wait(0.01)
        [(name, t, reading)] = done
        assert name == "cam" and t == 0.1 and reading["value"] == 0.1 and reading["prepared"]
        assert not threads.busy
        sensor.fail = True
        threads.start("cam", sensor, 0.3, np.zeros(2), np.zeros(2), None)
        with pytest.raises(RuntimeError) as err:
            for _ in range(500):
                threads.finished()
                threading.Event().wait(0.01)
        assert err.value is sensor.unplugged  # the sensor's own error, not another
    finally:
        threads.close()
