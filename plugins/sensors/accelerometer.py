"""An array of triaxial accelerometers on a robot body, filtered and turned into body motion.

After Carbone et al. (CaPaMan): MuJoCo accelerometer sensors at the mounting
points give the true specific force; Gaussian noise (σ, Table 1) and a constant,
calibrated offset make the raw readings. A Kalman filter per accelerometer (the
paper's 6-state constant-rate model) filters them; least squares on the rigid-
body equations gives the body-origin acceleration from raw and from filtered
readings, and the angular velocity two ways: algebraically from the raw
quadratic terms, and by an EKF fed with the filtered ones. A noiseless
accelerometer and a gyro at the body origin are the ground truth.
"""

from __future__ import annotations

import numpy as np
from pydantic import Field

from rehabkit.plugin import Backend, Context, Instrument, Instruments, Metric, Sensor, SensorConfig, hookimpl
from rehabkit.sensing import AccelerometerArray, AngularVelocityEKF, ConstantRateModel, KalmanBank, rts_smooth

Vec3 = tuple[float, float, float]
MOVING_RAD_S = 0.02  # the plate counts as moving above this true angular speed
TETRAHEDRON: list[Vec3] = [(0.08, 0.0, 0.0), (-0.04, 0.0693, 0.0), (-0.04, -0.0693, 0.0), (0.0, 0.0, -0.05)]


class AccelerometerArrayConfig(SensorConfig):
    """Where the accelerometers are and how they and their filters behave (defaults: the paper's Table 1)."""

    rate_hz: float = Field(500.0, gt=0)
    body: str = Field(description="robot or scene body the array is fixed to")
    points: list[Vec3] = Field(
        TETRAHEDRON,
        min_length=4,
        description="mounting points, body frame [m]; "
        "not all in one plane (three under a plate and one on a short post)",
    )
    noise_std: Vec3 = Field((0.5, 0.5, 0.5), description="σ_px, σ_py, σ_pz of each accelerometer [m/s²]")
    offset_std: float = Field(0.1, ge=0, description="spread of the constant offsets, known by calibration [m/s²]")
    mu_value: float = Field(0.01, gt=0, description="μ_m1 of the filter model [m/s²]")
    mu_rate: float = Field(0.05, gt=0, description="μ_m2 of the filter model [m/s³]")
    adaptive: bool = Field(False, description="scale the process noise up by the innovations (fast motions)")


class AccelerometerArraySensor(Sensor):
    """Triaxial accelerometers on a body + Kalman filtering + rigid-body reconstruction (a, ω)."""

    metrics = (
        Metric("accel_rms_*", "m/s^2", description="RMS error of an acceleration estimate "
               "(raw, filtered, smoothed; over the run, while moving, or against the planned motion)"),
        Metric("omega_rms_*", "rad/s", description="RMS error of an angular-velocity estimate (as accel_rms_*)"),
        Metric("accel_filter_gain*", description="raw RMS error over the Kalman filter's"),
        Metric("accel_smoother_gain*", description="raw RMS error over the RTS smoother's"),
        Metric("omega_filter_gain*", description="raw RMS error over the EKF's"),
        Metric("omega_smoother_gain*", description="raw RMS error over the smoother's"),
    )

    requires = (Instruments,)

    def __init__(self, config: AccelerometerArrayConfig, context: Context):
        self.config = config
        self.frame = config.body  # the body the array is fixed to
        self.array = AccelerometerArray(np.array(config.points))  # refuses layouts that can't give all of z
        self.rng = context.rng
        self.offsets = self.rng.normal(0.0, config.offset_std, (len(config.points), 3))
        dt = 1.0 / config.rate_hz
        self.dt = dt
        self.bank = KalmanBank(
            ConstantRateModel(dt, config.mu_value, config.mu_rate, tuple(config.noise_std)),
            len(config.points),
            adaptive=config.adaptive,
        )
        self.raw_cov = (
            self.array.M_pinv @ np.diag(np.tile(np.square(config.noise_std), len(config.points))) @ self.array.M_pinv.T
        )
        self.ekf = AngularVelocityEKF()
        self.prefix = f"acc_{config.body}"
        self._names = [f"{self.prefix}_{i}" for i in range(len(config.points))]
        self._truth = f"{self.prefix}_true_acc", f"{self.prefix}_true_gyro"
        self._noise_std = np.asarray(config.noise_std, float)
        self._true = np.empty((len(config.points), 3))
        self.times: list[float] = []
        self.estimates: dict[str, list[np.ndarray]] = {
            k: [] for k in ("a_raw", "a_filtered", "w_raw", "w_filtered", "a_true", "w_true")
        }
        self.robot = context.robot
        self.model = ConstantRateModel(dt, config.mu_value, config.mu_rate, tuple(config.noise_std))
        self.recording: list[np.ndarray] = []  # raw readings, for the offline (smoothed) validation
        self.variances: list[np.ndarray] = []

    def instruments(self) -> list[Instrument]:
        body = self.config.body
        items = [Instrument(f"{self.prefix}_{i}", "accelerometer", body, p) for i, p in enumerate(self.config.points)]
        return items + [
            Instrument(f"{self.prefix}_true_acc", "accelerometer", body, (0.0, 0.0, 0.0)),
            Instrument(f"{self.prefix}_true_gyro", "gyro", body, (0.0, 0.0, 0.0)),
        ]

    def read(self, t: float, q: np.ndarray, qd: np.ndarray, backend: Backend) -> dict[str, np.ndarray]:
        true = self._true
        for i, name in enumerate(self._names):
            true[i] = backend.read_instrument(name)
        raw = true + self.offsets
        raw += self.rng.standard_normal(true.shape) * self._noise_std  # (the draws of normal(0, 1), cheaper)
        filtered = self.bank.step(raw)
        var = self.bank.value_variance
        z_raw, z_f, w_raw, w_f = self.array.sample(raw, filtered, var, self.offsets, self.ekf, self.dt)
        self.recording.append(raw)
        self.variances.append(var.ravel().copy())  # (the filter updates its variances in place)
        a_true, w_true = backend.read_instrument(self._truth[0]), backend.read_instrument(self._truth[1])
        a_raw, a_f = z_raw[:3], z_f[:3]
        self.times.append(t)
        est = self.estimates
        for key, value in (("a_raw", a_raw), ("a_filtered", a_f), ("w_raw", w_raw), ("w_filtered", w_f),
                           ("a_true", a_true), ("w_true", w_true)):
            est[key].append(value)
        return {"raw_readings": raw.ravel(), "filtered_readings": filtered.ravel(), "acc_raw": a_raw,
                "acc_filtered": a_f, "acc_true": a_true, "omega_raw": w_raw, "omega_filtered": w_f,
                "omega_true": w_true}

    def channels(self, key: str, width: int) -> list[str] | None:
        """Each accelerometer's axes for the per-point readings, the body's axes for the estimates."""
        if key in ("raw_readings", "filtered_readings"):
            return [f"#{i} {axis}" for i in range(width // 3) for axis in "xyz"]
        return super().channels(key, width)

    def report(self, metrics: dict[str, float]) -> str | None:
        """The validation table: RMS errors of raw and filtered estimates against truth and the plan."""
        if "accel_rms_raw_m_s2" not in metrics:
            return None
        rows = [("plate acceleration [m/s²]", "accel", "m_s2"), ("angular velocity [rad/s]", "omega", "rad_s")]
        lines = [f"  {'RMS error of':28}{'raw':>9}{'filtered':>10}{'gain':>7}{'smoothed':>10}{'gain':>7}   against"]
        for label, key, unit in rows:
            first = True
            for ref, suffix in (("vs MuJoCo truth", ""), ("  while moving", "_moving"), ("vs planned motion", None)):
                if suffix is None:
                    raw, filt, smooth = (
                        metrics.get(f"{key}_rms_{k}_vs_planned_{unit}") for k in ("raw", "filtered", "smoothed")
                    )
                else:
                    raw, filt, smooth = (
                        metrics.get(f"{key}_rms_{k}{suffix}_{unit}") for k in ("raw", "filtered", "smoothed")
                    )
                if raw is None or filt is None or smooth is None:
                    continue
                lines.append(
                    f"  {label if first else '':28}{raw:9.4f}{filt:10.4f}{raw / filt:7.1f}"
                    f"{smooth:10.4f}{raw / smooth:7.1f}   {ref}"
                )
                first = False
        return "\n".join(lines)

    def theory(self, trace) -> tuple[np.ndarray, np.ndarray] | None:
        """Specific force and angular velocity (body frame) the *planned* motion implies at the sample times."""
        try:
            t = np.asarray(self.times)
            k = np.clip(np.rint(t / (trace.t[1] - trace.t[0])).astype(int), 0, len(trace.t) - 1)
            p, R = self.robot.body_poses(self.config.body, trace.q_ref[k])
        except (NotImplementedError, IndexError):
            return None
        dt = 1.0 / self.config.rate_hz
        acc = np.gradient(np.gradient(p, dt, axis=0), dt, axis=0)
        gravity = self.robot.model.base_pose[:3, :3].T @ self.robot.model.gravity
        force = np.einsum("nji,nj->ni", R, acc - gravity)  # Rᵀ (a − g): what a still accelerometer reads
        dR = np.gradient(R, dt, axis=0)
        W = np.einsum("nji,njk->nik", R, dR)  # Rᵀ Ṙ = [ω]×, body frame
        omega = np.stack([W[:, 2, 1] - W[:, 1, 2], W[:, 0, 2] - W[:, 2, 0], W[:, 1, 0] - W[:, 0, 1]], 1) / 2
        return force, omega

    def smoothed(self) -> tuple[np.ndarray, np.ndarray]:
        """Offline estimates (RTS-smoothed readings → a, and ω by the EKF) for every sample."""
        readings = rts_smooth(self.model, np.array(self.recording), self.config.adaptive)
        z = (readings.reshape(len(readings), -1) - self.offsets.ravel()) @ self.array.M_pinv.T
        M = self.array.M_pinv
        covs = np.einsum("ij,tj,kj->tik", M, np.array(self.variances), M)  # M⁺ diag(var) M⁺ᵀ per sample
        return z[:, :3], AngularVelocityEKF().run(z, covs, self.dt)

    def run_metrics(self, trace) -> dict[str, float]:
        if not self.times:
            return {}
        a_s, w_s = self.smoothed()
        est = {k: np.array(v) for k, v in self.estimates.items()} | {"a_smoothed": a_s, "w_smoothed": w_s}
        errors = {k: est[k] - est[f"{k[0]}_true"] for k in est if not k.endswith("_true")}
        skip = min(len(self.times) // 10, int(self.config.rate_hz * 0.2))  # filters settling
        out: dict[str, float] = {}
        moving = np.linalg.norm(est["w_true"], axis=1) > MOVING_RAD_S  # the plate moving (its true rotation)
        moving[:skip] = False
        for suffix, keep in (("", slice(skip, None)), ("_moving", moving)):
            if not np.any(np.ones(len(moving), bool)[keep]):
                continue
            rms = {k: float(np.sqrt(np.mean(np.square(v[keep])))) for k, v in errors.items()}
            out |= {
                f"accel_rms_raw{suffix}_m_s2": rms["a_raw"],
                f"accel_rms_filtered{suffix}_m_s2": rms["a_filtered"],
                f"accel_filter_gain{suffix}": rms["a_raw"] / max(rms["a_filtered"], 1e-12),
                f"omega_rms_raw{suffix}_rad_s": rms["w_raw"],
                f"omega_rms_filtered{suffix}_rad_s": rms["w_filtered"],
                f"omega_filter_gain{suffix}": rms["w_raw"] / max(rms["w_filtered"], 1e-12),
                f"accel_rms_smoothed{suffix}_m_s2": rms["a_smoothed"],
                f"omega_rms_smoothed{suffix}_rad_s": rms["w_smoothed"],
                f"accel_smoother_gain{suffix}": rms["a_raw"] / max(rms["a_smoothed"], 1e-12),
                f"omega_smoother_gain{suffix}": rms["w_raw"] / max(rms["w_smoothed"], 1e-12),
            }
        planned = self.theory(trace) if trace is not None else None
        if planned is not None:  # the paper's comparison: measured (raw, filtered) against the planned motion
            keep = slice(skip, None)
            for name, key, ref in (("accel", "a", planned[0]), ("omega", "w", planned[1])):
                unit = "m_s2" if name == "accel" else "rad_s"
                for kind in ("raw", "filtered", "smoothed", "true"):  # 'true': how far the run was from the plan
                    err = est[f"{key}_{kind}"][keep] - ref[keep]
                    out[f"{name}_rms_{kind}_vs_planned_{unit}"] = float(np.sqrt(np.mean(np.square(err))))
                raw = out[f"{name}_rms_raw_vs_planned_{unit}"]
                out[f"{name}_filter_gain_vs_planned"] = raw / max(out[f"{name}_rms_filtered_vs_planned_{unit}"], 1e-12)
                out[f"{name}_smoother_gain_vs_planned"] = raw / max(
                    out[f"{name}_rms_smoothed_vs_planned_{unit}"], 1e-12
                )
        return out


@hookimpl
def rehabkit_register_sensors(registry) -> None:
    registry.add("accelerometer-array", config=AccelerometerArrayConfig, factory=AccelerometerArraySensor)
