"""Time laws for guarded moves and retreats: synchronised trapezoidal velocity profiles.

A move from ``q0`` to ``q1`` follows the straight joint-space line ``q0 + s(t) (q1 - q0)`` with a
normalised trapezoidal law ``s(t)`` (continuous velocity, bounded acceleration) whose speed and
acceleration are the largest that keep every joint within its own limits.  Joint motion is
monotone along a move, which the contact search relies on (total variation = |Δq|).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]


@dataclass(frozen=True, slots=True)
class Trapezoid:
    """Normalised trapezoidal time law ``s: [0, duration] -> [0, 1]`` (clamped outside).

    Parameters
    ----------
    vmax, amax : float
        Peak speed and acceleration of ``s`` (1/s and 1/s²).
    """

    vmax: float
    amax: float

    @property
    def t_acc(self) -> float:
        """Duration of the acceleration (and deceleration) phase."""
        return min(self.vmax / self.amax, float(np.sqrt(1.0 / self.amax)))

    @property
    def v_peak(self) -> float:
        return self.amax * self.t_acc

    @property
    def duration(self) -> float:
        ta = self.t_acc
        cruise = max(0.0, 1.0 - self.amax * ta * ta) / self.v_peak
        return 2.0 * ta + cruise

    def __call__(self, t: FloatArray | float) -> tuple[FloatArray, FloatArray]:
        """``(s(t), ds/dt(t))`` for times ``t`` (any shape), clamped to ``[0, duration]``."""
        t = np.clip(np.asarray(t, dtype=float), 0.0, self.duration)
        a, ta, vp, T = self.amax, self.t_acc, self.v_peak, self.duration
        s_acc = 0.5 * a * ta * ta
        rising = t < ta
        falling = t > T - ta
        s = np.where(rising, 0.5 * a * t * t, s_acc + vp * (t - ta))
        s = np.where(falling, 1.0 - 0.5 * a * (T - t) ** 2, s)
        v = np.where(rising, a * t, vp)
        v = np.where(falling, a * (T - t), v)
        return np.clip(s, 0.0, 1.0), v


def synchronised_law(delta: FloatArray, vmax: FloatArray, amax: FloatArray) -> Trapezoid:
    """Fastest common law for a joint displacement ``delta (n,)`` under per-joint limits."""
    d = np.abs(np.asarray(delta, dtype=float))
    moving = d > 1e-12
    if not np.any(moving):
        return Trapezoid(vmax=1e3, amax=1e6)
    return Trapezoid(vmax=float(np.min(vmax[moving] / d[moving])),
                     amax=float(np.min(amax[moving] / d[moving])))


@dataclass(frozen=True, slots=True)
class PolylinePath:
    """A joint-space polyline ``vertices (K, n)`` traversed with a trapezoidal law.

    The arc-length metric is the time each segment takes at the joints' cruise speeds
    (``max_j |Δq_j| / v_j``), so the law respects every joint's velocity limit.
    """

    vertices: FloatArray
    cum: FloatArray
    law: Trapezoid
    length: float

    @classmethod
    def build(cls, vertices: FloatArray, vmax: FloatArray, t_acc: float) -> PolylinePath:
        vertices = np.asarray(vertices, dtype=float)
        seg = np.max(np.abs(np.diff(vertices, axis=0)) / vmax, axis=1) if len(vertices) > 1 \
            else np.zeros(0)
        cum = np.concatenate([[0.0], np.cumsum(seg)])
        length = float(cum[-1])
        if length <= 0.0:
            return cls(vertices, cum, Trapezoid(1e3, 1e6), 0.0)
        # normalised: unit speed in the metric is 1/length of s per second
        return cls(vertices, cum, Trapezoid(vmax=1.0 / length, amax=1.0 / (length * t_acc)),
                   length)

    @property
    def duration(self) -> float:
        return self.law.duration if self.length > 0 else 0.0

    def sample(self, t: FloatArray) -> tuple[FloatArray, FloatArray]:
        """Configurations ``(M, n)`` and joint velocities ``(M, n)`` at times ``t (M,)``."""
        t = np.asarray(t, dtype=float)
        if self.length <= 0.0:
            q = np.broadcast_to(self.vertices[-1], t.shape + self.vertices.shape[1:]).copy()
            return q, np.zeros_like(q)
        s, sd = self.law(t)
        lam = s * self.length
        idx = np.clip(np.searchsorted(self.cum, lam, side="right") - 1, 0, len(self.cum) - 2)
        seg_len = self.cum[idx + 1] - self.cum[idx]
        frac = np.where(seg_len > 0, (lam - self.cum[idx]) / np.where(seg_len > 0, seg_len, 1.0),
                        0.0)
        a, b = self.vertices[idx], self.vertices[idx + 1]
        q = a + frac[:, None] * (b - a)
        dq_dlam = (b - a) / np.where(seg_len > 0, seg_len, 1.0)[:, None]
        qd = dq_dlam * (sd * self.length)[:, None]
        return q, qd
