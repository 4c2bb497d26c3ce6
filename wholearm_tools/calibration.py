"""The drives' compliance learned from a run's own map.

Encoders on the motor side of compliant drives read a blocked joint's angle plus the
transmission's deflection, ``c tau / effort`` (``RobotModel.link_angles``).  A map fitted at the
readings then carries the deflection: a surface touched in poses that load the joints
differently is read at depths that differ by the difference of the deflections.  That is what
makes ``c`` observable: the contacts a reported primitive explains are re-read at
``q - c tau / effort`` and ``c`` is fitted jointly with every primitive's parameters, so that
the readings lie on their surfaces (a calibration of the arm against the surfaces it
touched).  A joint whose torque hardly varies between the contacts of one surface leaves its
own ``c`` undetermined, so ``c`` is the arm's common compliance plus each joint's departure
from it, under Gaussian priors (``prior`` on the common part, the range of harmonic drives;
``spread`` on the departures: drives sized to their loads deflect alike at their effort
limits).  The stops' own torque ramps do not serve: the deflection builds up during the
impact, whose motion dominates the reading (docs/method.md).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from wholearm_tools.errors import InputError

FloatArray = NDArray[np.float64]

#: the prior's scale [rad at the effort limit]: harmonic drives deflect 0.5-2 mrad at rated torque
DEFAULT_PRIOR = 0.002
#: how far one joint's drive may depart from the arm's common compliance, a priori [rad]
DEFAULT_SPREAD = 0.0005


@dataclass(frozen=True)
class ComplianceEstimate:
    """``compliance (n,)`` [rad at the effort limit] with its standard error ``std (n,)``, from
    ``readings`` contacts on ``primitives`` reported primitives (``compliance`` is zero and
    ``std`` infinite where there was nothing to learn from)."""

    compliance: FloatArray
    std: FloatArray
    readings: int
    primitives: int

    def describe(self) -> str:
        mrad = ", ".join(f"{c * 1e3:.2f} ± {s * 1e3:.2f}"
                         for c, s in zip(self.compliance, self.std, strict=True))
        return (f"the drives' compliance learned from {self.readings} contacts on "
                f"{self.primitives} primitives: {mrad} mrad at the effort limit")


def settled_values(contacts: Any, log: Any, values: FloatArray) -> FloatArray:
    """``values (N, n)`` of the log where each contact settled: the median over the samples
    its configuration ``q`` was taken from (``contacts.index`` on, ``min_stop_samples`` long,
    ending at its release)."""
    from wholearm_tools.contacts.detect import settled_window

    length = int(contacts.meta.get("min_stop_samples", 1))
    end = np.searchsorted(np.asarray(log.t), np.asarray(contacts.t_end), side="left")
    out = np.empty((len(contacts), values.shape[1]))
    for i, k in enumerate(np.asarray(contacts.index)):
        out[i] = np.median(values[settled_window(int(k), length, int(end[i]))], axis=0)
    return out


class _Layout:
    """The primitives' parameters as one vector (and back)."""

    def __init__(self, fits: tuple[Any, ...]) -> None:
        self.types = [type(f.primitive) for f in fits]
        self.keys: list[list[tuple[str, tuple[int, ...]]]] = []
        parts = []
        for f in fits:
            keys = []
            for key, value in f.primitive.params().items():
                arr = np.asarray(value, dtype=float)
                keys.append((key, arr.shape))
                parts.append(arr.ravel())
            self.keys.append(keys)
        self.x0 = np.concatenate(parts) if parts else np.zeros(0)
        sizes = [sum(int(np.prod(s)) for _, s in keys) for keys in self.keys]
        self.offsets = np.concatenate([[0], np.cumsum(sizes)]).astype(int)

    def primitives(self, x: FloatArray) -> list[Any]:
        out = []
        for j, keys in enumerate(self.keys):
            o, params = int(self.offsets[j]), {}
            for key, shape in keys:
                m = int(np.prod(shape))
                params[key] = x[o:o + m].reshape(shape) if shape else float(x[o])
                o += m
            out.append(self.types[j].from_params(params))
        return out


def estimate_compliance(rec: Any, *, prior: float = DEFAULT_PRIOR,
                        spread: float = DEFAULT_SPREAD) -> ComplianceEstimate:
    """The drives' compliance that puts ``rec``'s contacts on its reported primitives.

    ``rec`` is a :class:`~wholearm_tools.pipeline.Reconstruction`, made at the readings or
    under a compliance (its contacts are then read back to the drives' angles first).  Each
    contact on a reported primitive keeps the reading the fit explained it by (its tip
    sphere or its link's side, on the map's link); ``c`` and the primitives' parameters
    minimise the Huber cost of those readings' clearances plus the priors on the
    common compliance and each joint's departure from it, in units of the map's noise level,
    with ``c >= 0``.
    """
    from scipy.optimize import least_squares

    run, table, contacts = rec.run, rec.table, rec.contacts
    robot = run.robot
    n, dim = robot.dof, robot.dim
    none = ComplianceEstimate(np.zeros(n), np.full(n, np.inf), 0, 0)
    if run.log.tau_cmd is None or not rec.fits:
        return none
    rows = np.flatnonzero(np.asarray(table.primitive) >= 0)
    if len(rows) <= n:
        return none
    tau = np.asarray(run.log.tau_cmd)
    per_effort = settled_values(contacts, run.log, tau)[rows] / robot.effort_limits
    # the drives' readings, less a play that is known (a map made under a compliance has its
    # contacts at the links')
    q0 = np.asarray(contacts.q)[rows] + robot.joint_compliance * per_effort
    tip = np.asarray(table.used_as_tip)[rows]
    link = np.asarray(table.link_by_map)[rows]
    link = np.where(link >= 0, link, np.asarray(table.link)[rows])
    prim = np.asarray(table.primitive)[rows]
    radius = np.array([robot.contact_radius(int(k), bool(s)) for k, s in zip(link, tip,
                                                                             strict=True)])
    sides = [float(f.free_side) for f in rec.fits]
    layout = _Layout(rec.fits)
    pick = np.arange(len(rows))

    def clearances(x: FloatArray) -> FloatArray:
        a_all, b_all = robot.link_segments(q0 - x[:n] * per_effort)
        a, b = a_all[pick, link, :dim], b_all[pick, link, :dim]
        out = np.empty(len(rows))
        for j, p in enumerate(layout.primitives(x[n:])):
            on = prim == j
            at_tip, side = on & tip, on & ~tip
            if np.any(at_tip):
                out[at_tip] = sides[j] * p.signed_distance(b[at_tip])
            if np.any(side):
                out[side] = p.segment_signed_distance(a[side], b[side], free_side=sides[j])[0]
        return out - radius

    noise = max(float(rec.surface_map.meta.get("noise") or 0.0), 1e-6)

    # c = the arm's common compliance + each joint's departure from it (drives sized to
    # their loads deflect alike at their effort limits): y = [common, departures, params]
    to_c = np.hstack([np.ones((n, 1)), np.eye(n)])

    def c_of(y: FloatArray) -> FloatArray:
        return np.maximum(to_c @ y[:n + 1], 0.0)

    def cost(y: FloatArray) -> FloatArray:
        try:
            r = clearances(np.concatenate([c_of(y), y[n + 1:]]))
        except InputError:          # a step to an impossible primitive (a negative radius)
            r = np.full(len(rows), 1.0)
        return np.concatenate([r, [y[0] / prior * noise], y[1:n + 1] / spread * noise])

    y0 = np.concatenate([np.zeros(n + 1), layout.x0])
    lower = np.concatenate([[0.0], np.full(n + len(layout.x0), -np.inf)])
    scale = np.concatenate([np.full(n + 1, prior), np.full(len(layout.x0), 10 * noise)])
    sol = least_squares(cost, y0, loss="huber", f_scale=3 * noise, bounds=(lower, np.inf),
                        x_scale=scale, diff_step=1e-6)
    jac = np.asarray(sol.jac)
    c = c_of(sol.x)
    r = clearances(np.concatenate([c, sol.x[n + 1:]]))
    s = max(1.4826 * float(np.median(np.abs(r - np.median(r)))), 1e-6)
    cov = np.linalg.pinv(jac.T @ jac) * s * s
    cov_c = to_c @ cov[:n + 1, :n + 1] @ to_c.T
    std = np.sqrt(np.maximum(np.diag(cov_c), 0.0))
    return ComplianceEstimate(c, std, len(rows), len(rec.fits))
