"""Logs at the 50 Hz many rigs record at: the contacts' noise floor is the encoders', not the
arm's motion, whatever the log rate."""

from __future__ import annotations

import numpy as np
import pytest

from wholearm_tools.contacts.events import second_difference_scale
from wholearm_tools.pipeline import position_noise_floor
from wholearm_tools.sim.scenarios import load_scenario

QUANTUM = 2 * np.pi / 2**17   # a 17-bit encoder
NOISE = 1e-5                  # its white noise [rad]


def _log(rate: float, seed: int = 3) -> np.ndarray:
    """Positions of a two-joint arm under a lightly damped controller: a step
    every 1.5 s (transients of 4 Hz, settled within a second), read by the encoder."""
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, 60.0, 1.0 / rate)
    q = np.zeros((len(t), 2))
    for j in range(2):
        for start in np.arange(0.0, 60.0, 1.5):
            tau = np.clip(t - start, 0.0, None)
            q[:, j] += np.where(t >= start, rng.uniform(-0.5, 0.5) * (
                1 - np.exp(-6 * tau) * (np.cos(25 * tau) + 0.24 * np.sin(25 * tau))), 0.0)
    return np.round((q + rng.normal(0.0, NOISE, q.shape)) / QUANTUM) * QUANTUM


def test_the_position_noise_floor_does_not_depend_on_the_log_rate():
    """At 50 Hz the controller's transients reach the positions' second differences (the
    whole-log scale is several times the encoders'); the contacts' noise floor stays the one
    the same motion logged at 500 Hz gives."""
    robot = load_scenario("lab_circle").robot
    floors = {rate: position_noise_floor(robot, _log(rate)) for rate in (500.0, 50.0)}
    whole = robot.reach * np.sqrt(np.sum(second_difference_scale(_log(50.0)) ** 2))
    assert whole > 4 * floors[500.0]
    assert floors[50.0] == pytest.approx(floors[500.0], rel=0.2)
