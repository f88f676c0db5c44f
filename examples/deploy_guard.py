"""The guard's decision on a robot, from the folder ``gaitlib survival export`` writes: numpy and onnxruntime only.

Each control step, give it the running gait, the actor observation its ``policy.onnx`` reads, the reference phase,
the time since the robot started, s, and the trunk's acceleration in its own frame with gravity taken away (x
forward, y left, z up; m/s^2, over the last control step: what the IMU reads); it answers whether to switch now, to
which gait and destination phase. After a catch into a catch skill (``holds_until_calm``), hold it beyond horizon_s
until ``calm`` says so, at most the spec's calm wait_s after the catch.
"""

import json
from pathlib import Path

import numpy as np
import onnxruntime as ort

EPS = 1e-6


def sigmoid(z):
    return 1.0 / (1.0 + np.exp(-z))


class RobotGuard:
    def __init__(self, folder):
        folder = Path(folder)
        self.spec = json.loads((folder / "guard.json").read_text())
        self.gaits = self.spec["gaits"]
        self.latent = {g: ort.InferenceSession(str(folder / f"latent_{g}.onnx")) for g in self.gaits}
        self.survival = ort.InferenceSession(str(folder / "survival.onnx"))
        self.net = ort.InferenceSession(str(folder / "net.onnx"))
        self.candidates = np.asarray(self.spec["candidates"], dtype=np.float32)

    def read(self, gait, obs, phase, acceleration):
        """(staying up, {other gait: (calibrated offer, best destination phase)})."""
        m, count = self.gaits.index(gait), len(self.gaits)
        psi = self.latent[gait].run(None, {"obs": obs.reshape(1, -1).astype(np.float32)})[0][0]
        angle = 2 * np.pi * phase
        imu = acceleration if "imu" in self.spec["inputs"] else []
        x = np.concatenate([np.eye(count)[m], psi, [np.sin(angle), np.cos(angle)], imu]).astype(np.float32)
        a, b = self.spec["survival_platt"][gait]
        stay = sigmoid(a * self.survival.run(None, {"features": x[None]})[0][0] + b)
        offers = {}
        for n, dest in enumerate(self.gaits):
            if n == m:
                continue
            angles = 2 * np.pi * self.candidates
            rows = np.concatenate([
                np.tile(np.concatenate([np.eye(count)[m], np.eye(count)[n], psi]), (len(angles), 1)),
                np.stack([np.sin(angles), np.cos(angles)], axis=1),
            ], axis=1).astype(np.float32)
            score = np.clip(sigmoid(self.net.run(None, {"features": rows})[0]), EPS, 1 - EPS)
            a, b = self.spec["net_calibration"].get(f"{gait}-{dest}", (1.0, 0.0))
            p = sigmoid(a * np.log(score / (1 - score)) + b)
            best = int(np.argmax(p))
            offers[dest] = (float(p[best]), float(self.candidates[best]))
        return float(stay), offers

    def sector(self, acceleration):
        """The direction the trunk is pushed toward, one of spec["sectors"] (front, left, back, right)."""
        k = np.round(np.arctan2(acceleration[1], acceleration[0]) / (np.pi / 2))
        return self.spec["sectors"][int(k) % 4]

    def decide(self, gait, obs, phase, time_s, acceleration, just_switched=False):
        """(gait, destination phase) to switch to at once, or None to keep the gait. ``just_switched``: the last
        switch your switching rule chose was less than the spec's horizon_s ago (only the floor catches then)."""
        table = self.spec["catch_into"]  # gait -> sector -> catch (where it lacks one, never caught), or None
        into = None if table is None else table.get(gait, {}).get(self.sector(acceleration))
        if time_s < self.spec["armed_from_s"] or (table is not None and into is None):
            return None  # still settling from the start (states the estimate never saw), or never caught
        stay, offers = self.read(gait, obs, phase, acceleration)
        dest = into if into is not None else max(offers, key=lambda g: offers[g][0])
        beats = offers[dest][0] - stay > self.spec["margin"] and not just_switched
        if beats or stay < self.spec["floor"]:
            return dest, offers[dest][1]
        return None

    def holds_until_calm(self, gait):
        """A catch into this gait (a catch skill) is held beyond horizon_s until calm, at most calm["wait_s"], s."""
        return gait in self.spec["catchers"]

    def calm(self, gravity, velocity, rates):
        """The trunk is calm: gravity, the unit gravity direction in the trunk frame (the observation's projected
        gravity); velocity, the trunk's horizontal velocity (world or heading frame) from the state estimator, m/s;
        rates, the gyro's angular rates, rad/s."""
        c = self.spec["calm"]
        return bool(np.linalg.norm(gravity[:2]) < np.sin(np.deg2rad(c["tilt_deg"]))
                    and np.linalg.norm(velocity[:2]) < c["speed_m_s"] and np.linalg.norm(rates) < c["rate_rad_s"])
