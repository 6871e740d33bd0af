"""Winch measurements: the force sensor chain of thesis section 3.7.1 and the motor encoder.

Force: the physical sensor turns the force F_s on it into a signal gamma on its own sensor line
(3.29), f = gamma_1 (gamma - gamma_0), plus Gaussian noise; a bipolar AD converter of ``bits`` bits
over +-range quantises gamma; the reading applies the calibration of the robot file (3.29). With
the robot file's line as the true line (the default) the reading is F_s plus noise and
quantisation; a different true line simulates a sensor whose calibration is off.

Encoder: the cable length theta (2.25) in steps of one encoder count, r_drum 2 pi / (gear counts).
"""
from __future__ import annotations

import math

import numpy as np

from cdpr_control.kernels.jit import njit


NOISE_BLOCK = 1000      # force sensor readings whose noise is drawn at once


class ForceSensor:
    """m winch force sensors. sensor: cdpr_control.model.robot.SensorParams (range, bits, noise_std and the
    calibration gamma_1, gamma_0); rng: numpy Generator for the noise (drawn NOISE_BLOCK readings
    ahead, so do not draw from it elsewhere); gamma_1, gamma_0 (m,): the
    true sensor lines (default: the calibration); noise_std [N] overrides sensor.noise_std."""

    def __init__(self, sensor, m: int, rng: np.random.Generator, gamma_1=None, gamma_0=None,
                 noise_std: float | None = None):
        self.rng = rng
        self.m = m
        self.noise_std = float(sensor.noise_std if noise_std is None else noise_std)
        if not self.noise_std >= 0.0:
            raise ValueError(f"noise_std must be >= 0 N, got {self.noise_std}")
        self.cal_gamma_1, self.cal_gamma_0 = sensor.gamma_1, sensor.gamma_0
        self.gamma_1 = np.broadcast_to(np.asarray(sensor.gamma_1 if gamma_1 is None else gamma_1, dtype=float), (m,)).copy()
        self.gamma_0 = np.broadcast_to(np.asarray(sensor.gamma_0 if gamma_0 is None else gamma_0, dtype=float), (m,)).copy()
        if np.any(self.gamma_1 <= 0.0):
            raise ValueError("true sensor slopes gamma_1 must be > 0")
        self.lsb = 2.0 * sensor.range / 2**sensor.bits
        self._code_min, self._code_max = -(2.0 ** (sensor.bits - 1)), 2.0 ** (sensor.bits - 1) - 1.0
        # code = gamma / lsb with gamma = F / gamma_1 + gamma_0; reading = cal_1 (code lsb - cal_0)
        self._k1, self._k0 = 1.0 / (self.gamma_1 * self.lsb), self.gamma_0 / self.lsb
        self._r1, self._r0 = float(self.cal_gamma_1 * self.lsb), float(self.cal_gamma_1 * self.cal_gamma_0)
        self._noise = np.empty((0, m))     # noise of the coming readings, one row each
        self._next = 0

    def line(self, F_s) -> np.ndarray:
        """The calibrated reading [N] (m,) of F_s without noise and quantisation: the true line
        (3.29) read through the robot file's calibration."""
        return self.cal_gamma_1 * (np.asarray(F_s, dtype=float) / self.gamma_1 + self.gamma_0 - self.cal_gamma_0)

    def next_noise(self) -> np.ndarray | None:
        """The noise (m,) [N] of the next reading (None without noise); each call is one reading's."""
        if not self.noise_std:
            return None
        # drawn for NOISE_BLOCK readings at once: the generator's stream in the same order, so the
        # same numbers as one draw per reading, for one call a block instead of one a period
        if self._next == self._noise.shape[0]:
            self._noise, self._next = self.rng.normal(0.0, self.noise_std, (NOISE_BLOCK, self.m)), 0
        noise = self._noise[self._next]
        self._next += 1
        return noise

    def quantiser(self) -> tuple:
        """(k1, k0, code_min, code_max, r1, r0): the constants of quantise_kernel, for a compiled caller."""
        return self._k1, self._k0, self._code_min, self._code_max, self._r1, self._r0

    def read(self, F_s) -> np.ndarray:
        """Calibrated reading [N] (m,): quantised signal through the robot file's line (3.29)."""
        return quantise_kernel(np.asarray(F_s, dtype=float), self.next_noise(), *self.quantiser())


@njit
def quantise_kernel(F, noise, k1, k0, code_min, code_max, r1, r0):
    """AD code of each force plus its noise (None: none), clipped to the converter's range, read
    back through the calibration."""
    out = np.empty_like(F)
    for i in range(F.shape[0]):
        F_i = F[i] if noise is None else F[i] + noise[i]
        code = min(max(np.rint(F_i * k1[i] + k0[i]), code_min), code_max)
        out[i] = code * r1 - r0
    return out


class Encoder:
    """Cable length in whole encoder counts; resolution [m per count], 0 = ideal."""

    def __init__(self, resolution: float):
        if not resolution >= 0.0:
            raise ValueError(f"encoder resolution must be >= 0 m, got {resolution}")
        self.resolution = float(resolution)

    @classmethod
    def from_drive(cls, drive, counts_per_revolution: int) -> "Encoder":
        """Resolution 2 pi r_drum / (gear_ratio counts) of a motor encoder (drive: DriveParams)."""
        if counts_per_revolution <= 0:
            return cls(0.0)
        return cls(2.0 * math.pi * drive.drum_radius / (drive.gear_ratio * counts_per_revolution))

    def read(self, theta) -> np.ndarray:
        reading = np.array(theta, dtype=float)
        _count_all(reading.reshape(-1), self.resolution)
        return reading


@njit
def encoder_count(theta: float, resolution: float) -> float:
    """A cable length theta [m] in whole counts of ``resolution`` [m per count] (0: ideal)."""
    return np.rint(theta / resolution) * resolution if resolution else theta


@njit
def _count_all(theta, resolution):
    for i in range(theta.shape[0]):
        theta[i] = encoder_count(theta[i], resolution)
