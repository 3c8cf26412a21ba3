"""A six-axis force-torque sensor between the robot and what the person holds or wears (a handle, a cuff).

In a simulation it is a pair of MuJoCo force and torque sensors whose site sits on a light mount body
beyond the sensor: whatever pushes on the mount (a strap, a test rig's ``world.loads``) is read. Over a
hardware link the bridge sends the readings with each state (its plant reads the sensor: a real one,
or the MuJoCo plant's). Either way the host then

- removes the bias (tare): the mean of the first ``tare_s`` of readings, taken while the ramp-in holds the
  robot at its start with nothing pushing — a real sensor's offset drifts between sessions;
- filters the readings: a second-order Butterworth low-pass at ``cutoff_hz`` (the bilinear transform's closed
  form, as ``scipy.signal.butter(2, cutoff_hz, fs=rate, output="sos")`` designs it — checked against it in the
  tests; importing ``scipy.signal`` costs ~1 s, a third of a short run), run sample by sample at the rate it is read;
- gives the safety envelope its interaction force every control step (``interaction: true``), and the log
  its readings at ``rate_hz``.

Readings are what the person (or rig) puts on the robot, in the sensor's frame (the mount body's axes). At a
strap (``strap: forearm``) the mount is that strap's cuff, ``cuff_forearm``: a musculoskeletal patient's strap
is fastened to it, and the sensor reads the cuff force.
"""

from __future__ import annotations

import mujoco
import numpy as np
from pydantic import Field

from rehabkit.plugin import (
    Backend,
    Context,
    Instrument,
    Instruments,
    InteractionForceSensor,
    Metric,
    SensorConfig,
    SettingError,
    StrictModel,
    hookimpl,
)

Vec3 = tuple[float, float, float]


class SimulatedError(StrictModel):
    """What a simulated sensor gets wrong (a real one brings its own): a constant offset and white noise."""

    bias_n: Vec3 = Field((0.0, 0.0, 0.0), description="force offset [N]")
    bias_nm: Vec3 = Field((0.0, 0.0, 0.0), description="torque offset [N·m]")
    noise_n: float = Field(0.0, ge=0, description="force noise, standard deviation per axis [N]")
    noise_nm: float = Field(0.0, ge=0, description="torque noise, standard deviation per axis [N·m]")


class ForceTorqueConfig(SensorConfig):
    """Where the sensor sits, how it is tared and filtered, and whether the safety envelope reads it."""

    rate_hz: float = Field(100.0, gt=0, description="logging rate [Hz] (the envelope reads it every control step)")
    name: str | None = Field(None, description="the sensor's mount in the scene: the body a rig's load pushes on "
                                               "(default: ft, or cuff_<strap> at a strap)")
    strap: str | None = Field(None, description="at the cuff of this strap of the robot's wearable (upper_arm, "
                                                "forearm): a strapped person's cuff force is what it reads")
    body: str | None = Field(None, description="robot body it is fixed to (default: the hand's, at the hand site)")
    position: Vec3 | None = Field(None, description="where on that body [m] (default: the hand site's position)")
    tare_s: float = Field(0.2, ge=0, description="bias removed: the mean reading over the first this-many seconds "
                                                 "(0: none, the sensor was zeroed before the person was strapped in)")
    cutoff_hz: float = Field(30.0, ge=0, description="low-pass cut-off (2nd-order Butterworth; 0: unfiltered)")
    interaction: bool = Field(True, description="the safety envelope's interaction-force limit reads this sensor")
    simulated: SimulatedError = SimulatedError()


def butterworth2(cutoff_hz: float, fs: float) -> np.ndarray:
    """A second-order Butterworth low-pass as one second-order section ``[[b0, b1, b2, 1, a1, a2]]``: the analogue
    prototype at the prewarped cut-off, bilinear-transformed."""
    k = np.tan(np.pi * cutoff_hz / fs)
    norm = 1.0 / (1.0 + np.sqrt(2.0) * k + k * k)
    b0 = k * k * norm
    return np.array([[b0, 2.0 * b0, b0, 1.0, 2.0 * (k * k - 1.0) * norm, (1.0 - np.sqrt(2.0) * k + k * k) * norm]])


class Biquads:
    """A second-order-sections filter run one sample (a vector of channels) at a time (transposed direct form II)."""

    def __init__(self, sos: np.ndarray, channels: int):
        self.sos = sos
        self.z = np.zeros((len(sos), 2, channels))

    def __call__(self, x: np.ndarray) -> np.ndarray:
        for i, (b0, b1, b2, _, a1, a2) in enumerate(self.sos):
            z = self.z[i]
            y = b0 * x + z[0]
            z[0] = b1 * x - a1 * y + z[1]
            z[1] = b2 * x - a2 * y
            x = y
        return x

    def settle(self, x: np.ndarray) -> None:
        """Start at rest at ``x`` (no step response from zero): each section's state in its steady state for a
        constant input, the input of the next its output (``scipy.signal.sosfilt_zi`` times ``x``)."""
        for i, (b0, b1, b2, _, a1, a2) in enumerate(self.sos):
            y = (b0 + b1 + b2) / (1.0 + a1 + a2) * x
            self.z[i, 1] = b2 * x - a2 * y
            self.z[i, 0] = b1 * x - a1 * y + self.z[i, 1]
            x = y

    def run(self, xs: np.ndarray) -> np.ndarray:
        """Each of ``xs`` (samples × channels) filtered in turn."""
        return np.array([self(x) for x in xs])


def hand_mount(mjcf: str, site: str) -> tuple[str, Vec3]:
    """The body a site is on and its position there."""
    spec = mujoco.MjSpec.from_string(mjcf)
    s = spec.site(site)
    return s.parent.name, tuple(float(v) for v in s.pos)


class ForceTorqueSensor(InteractionForceSensor):
    """Six-axis force-torque sensor: tared, low-pass filtered, read every control step by the safety envelope."""

    requires = (Instruments,)
    metrics = (
        Metric("ft_bias_n", "N", description="force offset the tare removed (its magnitude)"),
        Metric("ft_noise_n", "N", description="raw force noise during the tare, standard deviation per axis"),
        Metric("ft_noise_filtered_n", "N", description="the same noise after the low-pass filter"),
        Metric("ft_peak_force_n", "N", description="largest filtered force after the tare"),
    )

    def __init__(self, config: ForceTorqueConfig, context: Context):
        self.config, self.interaction = config, config.interaction
        model = context.robot.model
        body, position = config.body, config.position
        self.name = config.name or (f"cuff_{config.strap}" if config.strap else "ft")
        if config.strap is not None:
            straps = {s.segment: s for s in (model.wearable.straps if model.wearable else ())}
            if config.strap not in straps:
                raise SettingError("strap", f"'{config.strap}': robot '{model.name}' has "
                                 f"{'straps ' + ', '.join(straps) if straps else 'no wearable straps'}")
            body, position = straps[config.strap].body, straps[config.strap].position
        if body is None or position is None:
            hand_body, hand_at = hand_mount(model.mjcf, model.ee_site)
            body = body or hand_body
            position = position if position is not None else (hand_at if body == hand_body else (0.0, 0.0, 0.0))
        self.body, self.position = body, position
        self.frame = body  # the mount body's axes
        # read every control step when the envelope uses it, else at the logging rate
        self.fs = 1.0 / context.control_dt if config.interaction else config.rate_hz
        if config.cutoff_hz >= self.fs / 2:
            raise SettingError("cutoff_hz", f"{config.cutoff_hz:g} must be below half the rate it is "
                             f"read at ({self.fs:g} Hz)")
        self._names = (f"{self.name}_force", f"{self.name}_torque")
        self._tare_n = round(config.tare_s * self.fs)
        self._tare: list[np.ndarray] = []
        self.bias = np.zeros(6)
        self.filter = None
        if config.cutoff_hz > 0:
            self.filter = Biquads(butterworth2(config.cutoff_hz, self.fs), 6)
            if not self._tare_n:
                self.filter.settle(np.zeros(6))
        self.raw = self.value = np.zeros(6)
        self.peak = 0.0
        self._last_t = -1.0
        self._model = model
        self._pin = None  # (model, data, frame id), made when first asked where the force acts

    def instruments(self) -> list[Instrument]:
        sim, name = self.config.simulated, self.name
        return [Instrument(self._names[0], "force", self.body, self.position, mount=name, bias=sim.bias_n,
                           noise=sim.noise_n),
                Instrument(self._names[1], "torque", self.body, self.position, mount=name, bias=sim.bias_nm,
                           noise=sim.noise_nm)]

    def sample(self, t: float, backend: Backend) -> np.ndarray:
        """Read, tare and filter once (at most once per time ``t``); the force and torque on the robot, 6 values."""
        if t == self._last_t:
            return self.value
        self._last_t = t
        # MuJoCo's sensors give what the robot exerts on the mount: the person's push is its opposite
        raw = -np.concatenate((backend.read_instrument(self._names[0]), backend.read_instrument(self._names[1])))
        self.raw = raw
        if len(self._tare) < self._tare_n:
            self._tare.append(raw)
            self.bias = np.mean(self._tare, axis=0)
            if len(self._tare) == self._tare_n and self.filter is not None:
                self.filter.settle(np.zeros(6))
            self.value = raw - self.bias
            return self.value
        x = raw - self.bias
        self.value = self.filter(x) if self.filter is not None else x
        self.peak = max(self.peak, float(np.linalg.norm(self.value[:3])))
        return self.value

    def interaction_force(self, t: float, backend: Backend) -> np.ndarray:
        return self.sample(t, backend)[:3]

    def joint_torque(self, q: np.ndarray, force: np.ndarray) -> np.ndarray | None:
        """Jᵀ F at the sensor: the reading turned from the mount's axes into the base frame's by the body's
        rotation, the Jacobian of the point it acts at (Pinocchio); None for a robot Pinocchio cannot load."""
        if self._pin is None:
            import pinocchio as pin

            try:
                model = self._model.pin_model
            except Exception:  # noqa: BLE001 (a closed chain: no Pinocchio model, no direction)
                return None
            if not model.existFrame(self.body):
                return None
            self._pin = (pin, model, model.createData(), model.getFrameId(self.body))
        pin, model, data, frame = self._pin
        J = pin.computeFrameJacobian(model, data, q, frame, pin.LOCAL_WORLD_ALIGNED)  # (updates the placements)
        rot = data.oMf[frame].rotation
        r = rot @ np.asarray(self.position, float)  # the point, from the body's origin, base axes
        linear = J[:3] - np.cross(r, J[3:].T).T  # v_point = v_origin + ω × r
        return linear.T @ (rot @ np.asarray(force, float))

    def read(self, t: float, q: np.ndarray, qd: np.ndarray, backend: Backend) -> dict[str, np.ndarray]:
        value = self.sample(t, backend) if not self.interaction else self.value  # (sampled by the loop already)
        return {"force_n": value[:3].copy(), "torque_nm": value[3:].copy(), "raw_force_n": self.raw[:3].copy()}

    def run_metrics(self, trace) -> dict[str, float]:
        if len(self._tare) < 2:
            return {}
        tare = np.array(self._tare)
        out = {"ft_bias_n": float(np.linalg.norm(self.bias[:3])),
               "ft_noise_n": float(np.mean(np.std(tare[:, :3], axis=0))), "ft_peak_force_n": self.peak}
        if self.filter is not None:
            filtered = Biquads(self.filter.sos, 3).run(tare[:, :3] - self.bias[:3])  # (from rest at zero)
            settled = filtered[len(filtered) // 3:]  # past the filter's start-up
            out["ft_noise_filtered_n"] = float(np.mean(np.std(settled, axis=0)))
        return out

    def report(self, metrics: dict[str, float]) -> str | None:
        if "ft_bias_n" not in metrics:
            return None
        return (f"force-torque '{self.name}': bias {metrics['ft_bias_n']:.2f} N tared, noise "
                f"{metrics['ft_noise_n']:.3f} N raw / {metrics.get('ft_noise_filtered_n', float('nan')):.3f} N "
                f"filtered, peak {metrics['ft_peak_force_n']:.1f} N")


@hookimpl
def rehabkit_register_sensors(registry) -> None:
    registry.add("force-torque", config=ForceTorqueConfig, factory=ForceTorqueSensor)
