"""The drives' compliance and backlash learned from a run's own map.

Encoders on the motor side of geared drives read a blocked joint's angle plus the
transmission's deflection, ``c tau / effort``, and half its play on the side the drive pushes,
``(b / 2) s`` (``RobotModel.link_angles``).  A map fitted at the readings then carries both: a
surface touched in poses that load the joints differently is read at depths that differ by
the difference of the offsets.  That is what makes ``c`` and ``b`` observable: the contacts a
reported primitive explains are re-read at the links' angles and the drives' parameters are
fitted jointly with every primitive's, so that the readings lie on their surfaces (a
calibration of the arm against the surfaces it touched).  A joint whose load hardly varies
between the contacts of one surface leaves its own value undetermined, so each is the arm's
common value plus each joint's departure from it, under Gaussian priors (:data:`PRIORS`).
Compliance and play differ where a joint's torque does: a joint pushing at its effort limit
shows their sum.  The stops' own torque ramps do not serve: the deflection builds up during
the impact, whose motion dominates the reading (docs/method.md).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from wholearm_tools.errors import InputError

FloatArray = NDArray[np.float64]

#: priors [rad]: scale of the arm's common value, and how far one joint's drive may depart from
#: it (drives sized to their loads deflect alike at their effort limits, and gearboxes of one
#: series have alike play): harmonic drives deflect 0.5-2 mrad at rated torque; spur and
#: planetary gearboxes have 0.3-4 mrad of play
PRIORS = {"compliance": (0.002, 0.0005), "backlash": (0.002, 0.0005)}
#: what a drive's parameter means, for messages
UNITS = {"compliance": "mrad at the effort limit", "backlash": "mrad of play"}


@dataclass(frozen=True)
class DriveEstimate:
    """The drives' ``compliance (n,)`` [rad at the effort limit] and ``backlash (n,)`` [rad]
    with their standard errors ``compliance_std``, ``backlash_std`` (infinite for what was not
    learned: it keeps the robot's value), from ``readings`` contacts on ``primitives``
    reported primitives; ``learned`` names what was learned (nothing where there was nothing
    to learn from)."""

    compliance: FloatArray
    compliance_std: FloatArray
    backlash: FloatArray
    backlash_std: FloatArray
    readings: int
    primitives: int
    learned: tuple[str, ...]

    def describe(self) -> str:
        parts = []
        for what in self.learned:
            values, std = getattr(self, what), getattr(self, f"{what}_std")
            mrad = ", ".join(f"{v * 1e3:.2f} ± {e * 1e3:.2f}"
                             for v, e in zip(values, std, strict=True))
            parts.append(f"{what} {mrad} {UNITS[what]}")
        return (f"the drives' {' and '.join(self.learned)} learned from {self.readings} "
                f"contacts on {self.primitives} primitives: " + "; ".join(parts))


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


def estimate_drives(rec: Any, *, compliance: bool = True,
                    backlash: bool = False) -> DriveEstimate:
    """The drives' compliance and/or backlash that put ``rec``'s contacts on its reported
    primitives (what is not learned keeps the robot's value).

    ``rec`` is a :class:`~wholearm_tools.pipeline.Reconstruction`, made at the readings or
    under a drive model (its contacts are then read back to the drives' angles first).  Each
    contact on a reported primitive keeps the reading the fit explained it by (its tip
    sphere or its link's side, on the map's link) and is re-read at the links' angles
    ``q - c tau / effort - (b / 2) s`` (``RobotModel.link_angles``; ``tau`` and the pushed side
    ``s`` where it settled).  ``c``, ``b`` and the primitives' parameters minimise the Huber
    cost of those readings' clearances plus the priors on each quantity's common value and
    each joint's departure from it (:data:`PRIORS`), in units of the map's noise level, with
    ``c, b >= 0``.
    """
    from scipy.optimize import least_squares

    run, table, contacts = rec.run, rec.table, rec.contacts
    robot = run.robot
    n, dim = robot.dof, robot.dim
    known = {"compliance": robot.joint_compliance, "backlash": robot.joint_backlash}
    learn = tuple(k for k, on in (("compliance", compliance), ("backlash", backlash)) if on)
    none = DriveEstimate(known["compliance"], np.full(n, np.inf), known["backlash"],
                         np.full(n, np.inf), 0, 0, ())
    if run.log.tau_cmd is None or not rec.fits or not learn:
        return none
    rows = np.flatnonzero(np.asarray(table.primitive) >= 0)
    if len(rows) <= n * len(learn):
        return none
    tau = np.asarray(run.log.tau_cmd)
    # what each learned quantity moves a contact's angles by, per unit, where it settled
    regressor = {}
    if "compliance" in learn:
        regressor["compliance"] = (settled_values(contacts, run.log, tau)[rows]
                                   / robot.effort_limits)
    if "backlash" in learn:
        regressor["backlash"] = 0.5 * settled_values(contacts, run.log,
                                                     robot.load_direction(tau))[rows]
    # the drives' readings less what is told (contacts of a map made under a drive model are
    # at the links' angles)
    q0 = np.asarray(contacts.q)[rows]
    for what in learn:
        q0 = q0 + known[what] * regressor[what]
    tip = np.asarray(table.used_as_tip)[rows]
    link = np.asarray(table.link_by_map)[rows]
    link = np.where(link >= 0, link, np.asarray(table.link)[rows])
    prim = np.asarray(table.primitive)[rows]
    radius = np.array([robot.contact_radius(int(k), bool(s)) for k, s in zip(link, tip,
                                                                             strict=True)])
    sides = [float(f.free_side) for f in rec.fits]
    layout = _Layout(rec.fits)
    pick = np.arange(len(rows))

    def clearances(drives: FloatArray, params: FloatArray) -> FloatArray:
        q = q0 - sum(drives[i] * regressor[what] for i, what in enumerate(learn))
        a_all, b_all = robot.link_segments(q)
        a, b = a_all[pick, link, :dim], b_all[pick, link, :dim]
        out = np.empty(len(rows))
        for j, p in enumerate(layout.primitives(params)):
            on = prim == j
            at_tip, side = on & tip, on & ~tip
            if np.any(at_tip):
                out[at_tip] = sides[j] * p.signed_distance(b[at_tip])
            if np.any(side):
                out[side] = p.segment_signed_distance(a[side], b[side], free_side=sides[j])[0]
        return out - radius

    noise = max(float(rec.surface_map.meta.get("noise") or 0.0), 1e-6)

    # each learned quantity = the arm's common value + each joint's departure from it:
    # y = [common, departures] per quantity, then the primitives' parameters
    m = len(learn) * (n + 1)
    to_joint = np.hstack([np.ones((n, 1)), np.eye(n)])
    prior = np.concatenate([[PRIORS[w][0]] + [PRIORS[w][1]] * n for w in learn])

    def drives_of(y: FloatArray) -> FloatArray:
        return np.maximum(y[:m].reshape(len(learn), n + 1) @ to_joint.T, 0.0)

    def cost(y: FloatArray) -> FloatArray:
        try:
            r = clearances(drives_of(y), y[m:])
        except InputError:          # a step to an impossible primitive (a negative radius)
            r = np.full(len(rows), 1.0)
        return np.concatenate([r, y[:m] / prior * noise])

    y0 = np.concatenate([np.zeros(m), layout.x0])
    common = np.zeros(m, dtype=bool)
    common[::n + 1] = True
    lower = np.concatenate([np.where(common, 0.0, -np.inf), np.full(len(layout.x0), -np.inf)])
    scale = np.concatenate([prior, np.full(len(layout.x0), 10 * noise)])
    sol = least_squares(cost, y0, loss="huber", f_scale=3 * noise, bounds=(lower, np.inf),
                        x_scale=scale, diff_step=1e-6)
    jac = np.asarray(sol.jac)
    drives = drives_of(sol.x)
    r = clearances(drives, sol.x[m:])
    s = max(1.4826 * float(np.median(np.abs(r - np.median(r)))), 1e-6)
    cov = np.linalg.pinv(jac.T @ jac) * s * s
    values = dict(known)
    std = {w: np.full(n, np.inf) for w in known}
    for i, what in enumerate(learn):
        block = slice(i * (n + 1), (i + 1) * (n + 1))
        values[what] = drives[i]
        std[what] = np.sqrt(np.maximum(np.diag(to_joint @ cov[block, block] @ to_joint.T), 0.0))
    return DriveEstimate(values["compliance"], std["compliance"], values["backlash"],
                         std["backlash"], len(rows), len(rec.fits), learn)
