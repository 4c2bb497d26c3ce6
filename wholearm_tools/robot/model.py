"""Serial chains of revolute joints with capsule links: kinematics and point velocities.

Geometry convention (one place): joint ``i`` (0-based) sits at the origin of frame ``i``; link
``i`` is the segment from joint ``i`` to joint ``i + 1`` (for the last link: to the tip point),
a capsule of radius ``link_radii[i]`` (cylinder plus a sphere at each end).  The tip is a sphere
of radius ``tip_radius`` centred on the tip point (0 = sharp tip: contacts at the end of the last
link then have radius ``link_radii[-1]``).  Link ``i`` moves with joints ``0..i`` only, which is
what makes link identification possible.

All frames are expressed in the base frame ``base_link``.  Transforms are 4x4 homogeneous
matrices named ``A2B`` style where needed; ``frames(q)`` returns ``joint_i -> base``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from wholearm_tools._arrays import read_only
from wholearm_tools.errors import InputError, RobotModelError

FloatArray = NDArray[np.float64]

#: torque that turns a drive's motor through its play, as a fraction of its effort limit: the
#: rotor's and gears' own friction (a few per cent in geared drives)
PLAY_TORQUE = 0.02

MIN_TIP_DISTANCE = 1e-6
"""Shortest distance [m] from the last joint to the tip: a last link shorter than this has no
tip to touch with and no axis, and every later stage would divide by its length."""


def rotation_about_axis(axis: FloatArray, angle: FloatArray) -> FloatArray:
    """Rodrigues rotation matrices: unit ``axis (3,)`` and ``angle (...)`` → ``(..., 3, 3)``."""
    x, y, z = axis
    k = np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])
    angle = np.asarray(angle, dtype=float)[..., None, None]
    return np.eye(3) + np.sin(angle) * k + (1.0 - np.cos(angle)) * (k @ k)


def transform_from_xyz_rpy(xyz: ArrayLike, rpy: ArrayLike = (0.0, 0.0, 0.0)) -> FloatArray:
    """URDF origin (translation, roll-pitch-yaw: R = Rz(yaw) Ry(pitch) Rx(roll)) → 4x4 matrix."""
    from scipy.spatial.transform import Rotation

    tf = np.eye(4)
    tf[:3, :3] = Rotation.from_euler("xyz", np.asarray(rpy, dtype=float)).as_matrix()
    tf[:3, 3] = np.asarray(xyz, dtype=float)
    return tf


@dataclass(frozen=True, slots=True, eq=False)
class RobotModel:
    """A serial chain of ``n`` revolute joints with capsule links and a spherical tip.

    Parameters
    ----------
    name : str
    joint_names : tuple of n str
    origins : (n, 4, 4) float
        Fixed transform of joint ``i``'s frame in the frame of link ``i - 1`` (base for i = 0),
        before the joint rotation.
    axes : (n, 3) float
        Unit rotation axis of each joint in its own frame.
    tip_offset : (3,) float
        Tip point in the frame of the last joint.
    link_radii : (n,) float
        Capsule radius ``w`` of each link.
    tip_radius : float
        Radius of the tip sphere (0 for a sharp tip).
    lower, upper : (n,) float
        Joint limits in radians.
    velocity_limits, effort_limits : (n,) float
    joint_compliance : (n,) float, optional
        Deflection of each joint's transmission at its effort limit [rad] (a drive's torsional
        stiffness ``k`` gives ``effort / k``), for encoders that read the motor side; zeros
        (default) for encoders on the link or stiff drives.  See :meth:`link_angles`.
    joint_backlash : (n,) float, optional
        Lost motion of each joint's transmission [rad]: the play between the motor and the
        link (gearboxes 0.3-4 mrad, harmonic drives about none), for encoders that read the
        motor side; zeros (default) for encoders on the link or drives without play.
    """

    name: str
    joint_names: tuple[str, ...]
    origins: FloatArray
    axes: FloatArray
    tip_offset: FloatArray
    link_radii: FloatArray
    tip_radius: float
    lower: FloatArray
    upper: FloatArray
    velocity_limits: FloatArray
    effort_limits: FloatArray
    joint_compliance: FloatArray | None = None
    joint_backlash: FloatArray | None = None
    planar: bool = field(init=False)

    def __post_init__(self) -> None:
        n = len(self.joint_names)
        if n == 0:
            raise RobotModelError(f"robot {self.name!r} has no revolute joints")
        if len(set(self.joint_names)) != n:
            raise RobotModelError(f"robot {self.name!r} has duplicate joint names")
        checks = {
            "origins": (n, 4, 4), "axes": (n, 3), "tip_offset": (3,), "link_radii": (n,),
            "lower": (n,), "upper": (n,), "velocity_limits": (n,), "effort_limits": (n,),
        }
        for attr, shape in checks.items():
            value = np.asarray(getattr(self, attr), dtype=float)
            if value.shape != shape:
                raise RobotModelError(f"expected {attr} of shape {shape}, got {value.shape}")
            if not np.all(np.isfinite(value)):
                raise RobotModelError(f"robot {self.name!r}: {attr} has non-finite values")
            if attr == "axes":
                norms = np.linalg.norm(value, axis=1)
                if np.any(norms < 1e-9):
                    raise RobotModelError(f"robot {self.name!r}: a joint axis is zero")
                value = value / norms[:, None]
            object.__setattr__(self, attr, read_only(value))
        drives = (("joint_compliance", "joint compliance", "rad at the effort limit"),
                  ("joint_backlash", "joint backlash", "rad"))
        for attr, what, unit in drives:
            value = np.asarray(0.0 if getattr(self, attr) is None else getattr(self, attr),
                               dtype=float)
            if value.shape not in ((), (1,), (n,)):
                raise RobotModelError(f"robot {self.name!r}: expected one {what} or {n} (one "
                                      f"per joint), got {value.size}")
            value = np.broadcast_to(value, (n,))
            if not np.all(np.isfinite(value) & (value >= 0)):
                raise RobotModelError(f"robot {self.name!r}: {what} must be finite and "
                                      f"non-negative [{unit}], got {value}")
            object.__setattr__(self, attr, read_only(value.copy()))
        if np.any(((self.joint_compliance > 0) | (self.joint_backlash > 0))
                  & ~(np.asarray(self.effort_limits, dtype=float) > 0)):
            raise RobotModelError(f"robot {self.name!r}: a compliant joint or one with play "
                                  "needs a positive effort limit (its compliance is the "
                                  "deflection there; its play is crossed at a share of it)")
        if np.any(self.link_radii < 0) or self.tip_radius < 0:
            raise RobotModelError(f"robot {self.name!r}: negative link or tip radius")
        if float(np.linalg.norm(self.tip_offset)) < MIN_TIP_DISTANCE:
            raise RobotModelError(f"robot {self.name!r}: the last link has zero length (the tip "
                                  f"is at joint {self.joint_names[-1]!r}); the tip must lie "
                                  "beyond the last joint")
        if np.any(self.lower >= self.upper):
            raise RobotModelError(f"robot {self.name!r}: a joint has lower limit >= upper limit")
        object.__setattr__(self, "tip_radius", float(self.tip_radius))
        object.__setattr__(self, "planar", self._is_planar())

    # ------------------------------------------------------------------ construction
    @classmethod
    def from_spec(cls, spec: dict[str, Any], name: str = "robot") -> RobotModel:
        """Build a robot from a scenario's ``robot:`` mapping.

        ``spec = {"joints": [{"name", "origin": [x, y, z], "rpy": [r, p, y], "axis": [x, y, z],
        "limits": [lo, hi], "radius": w, "velocity": v, "effort": e}, ...],
        "tip": {"offset": [x, y, z], "radius": w_tip}}`` — ``rpy``, ``axis`` (default z),
        ``limits`` (default ±pi), ``velocity`` (1 rad/s) and ``effort`` (10 N m) may be omitted.
        """
        try:
            joints = spec["joints"]
            tip = spec["tip"]
            n = len(joints)
            names = tuple(str(j.get("name", f"joint_{i + 1}")) for i, j in enumerate(joints))
            origins = np.stack(
                [transform_from_xyz_rpy(j.get("origin", [0, 0, 0]), j.get("rpy", [0, 0, 0]))
                 for j in joints]
            ) if n else np.zeros((0, 4, 4))
            axes = np.array([j.get("axis", [0.0, 0.0, 1.0]) for j in joints], dtype=float)
            limits = np.array([j.get("limits", [-np.pi, np.pi]) for j in joints], dtype=float)
            return cls(
                name=str(spec.get("name", name)),
                joint_names=names,
                origins=origins,
                axes=axes.reshape(n, 3),
                tip_offset=np.asarray(tip["offset"], dtype=float),
                link_radii=np.array([j["radius"] for j in joints], dtype=float),
                tip_radius=float(tip.get("radius", 0.0)),
                lower=limits.reshape(n, 2)[:, 0],
                upper=limits.reshape(n, 2)[:, 1],
                velocity_limits=np.array([j.get("velocity", 1.0) for j in joints], dtype=float),
                effort_limits=np.array([j.get("effort", 10.0) for j in joints], dtype=float),
            )
        except (KeyError, TypeError, ValueError) as exc:
            if isinstance(exc, RobotModelError):
                raise
            raise RobotModelError(f"invalid robot description: {exc!r}") from None

    def _is_planar(self) -> bool:
        """True when every joint axis is the base z axis and every link lies in the z = 0 plane."""
        z = np.array([0.0, 0.0, 1.0])
        # tested on a few fixed configurations: cheap, and needs no special case for rpy origins
        rng = np.random.default_rng(0)
        q = rng.uniform(self.lower, self.upper, size=(4, self.dof))
        frames = self.frames(q)
        axes_world = np.einsum("...ij,...j->...i", frames[..., :3, :3], self.axes)
        pts = self.joint_positions(q)
        return bool(np.allclose(np.abs(axes_world @ z), 1.0, atol=1e-9)
                    and np.allclose(pts[..., 2], 0.0, atol=1e-9))

    def link_angles(self, q: ArrayLike, tau: ArrayLike | None) -> FloatArray:
        """Link-side joint angles from motor-side readings ``q (N, n)`` under the drives'
        torques ``tau (N, n)``, rows in time order::

            q - c tau / effort - (b / 2) s

        Each transmission is a torsion spring that deflects by ``c`` at the effort limit, and
        has a play ``b`` whose gap the drive holds closed on the side it pushes: ``s`` is
        :meth:`load_direction`.  The geometry of a contact is the links'; the detector's
        signals stay the drives'.  ``q`` itself when the drives are stiff and without play
        (``joint_compliance`` and ``joint_backlash`` all zero) or no torque was logged.
        """
        stiff, tight = not np.any(self.joint_compliance > 0), not np.any(self.joint_backlash > 0)
        if tau is None or (stiff and tight):
            return np.asarray(q, dtype=float)
        tau = np.asarray(tau, dtype=float)
        out = np.asarray(q, dtype=float)
        if not stiff:
            out = out - tau * (self.joint_compliance / self.effort_limits)
        if not tight:
            out = out - 0.5 * self.joint_backlash * self.load_direction(tau)
        return out

    def load_direction(self, tau: ArrayLike) -> FloatArray:
        """The side of its play each drive holds closed, ``+1``, ``-1`` or ``0`` (not known
        yet), over torques ``tau (N, n)`` in time order: the sign of the torque once it
        exceeds ``PLAY_TORQUE`` of the effort limit (enough to turn the motor through the
        gap against its own friction), held while the torque stays inside that band."""
        tau = np.asarray(tau, dtype=float)
        rows = tau.reshape(-1, self.dof)
        band = PLAY_TORQUE * self.effort_limits
        pushed = np.where(rows > band, 1.0, np.where(rows < -band, -1.0, 0.0))
        last = np.where(pushed != 0, np.arange(len(rows))[:, None], -1)
        last = np.maximum.accumulate(last, axis=0)
        held = np.take_along_axis(pushed, np.maximum(last, 0), axis=0)
        return np.where(last >= 0, held, 0.0).reshape(tau.shape)

    # ------------------------------------------------------------------ kinematics
    @property
    def dof(self) -> int:
        """Number of revolute joints ``n``."""
        return len(self.joint_names)

    @property
    def dim(self) -> int:
        """Workspace dimension: 2 for planar robots (xy plane), else 3."""
        return 2 if self.planar else 3

    def check_q(self, q: ArrayLike, name: str = "q") -> FloatArray:
        """Validate joint values of shape ``(..., n)``."""
        arr = np.asarray(q, dtype=float)
        if arr.ndim == 0 or arr.shape[-1] != self.dof:
            raise InputError(f"expected {name} of shape (..., {self.dof}), got {arr.shape}")
        if not np.all(np.isfinite(arr)):
            raise InputError(f"{name} contains NaN or infinite values")
        return arr

    def frames(self, q: ArrayLike) -> FloatArray:
        """World transforms of every joint frame after rotation, ``(..., n, 4, 4)``."""
        q = self.check_q(q)
        batch = q.shape[:-1]
        out = np.zeros((*batch, self.dof, 4, 4))
        out[..., 3, 3] = 1.0
        # rotation and translation composed apart: the 3x3 products cost half the 4x4 ones
        rot = np.broadcast_to(np.eye(3), (*batch, 3, 3))
        pos = np.zeros((*batch, 3))
        for i in range(self.dof):
            pos = rot @ self.origins[i, :3, 3] + pos
            rot = rot @ (self.origins[i, :3, :3] @ rotation_about_axis(self.axes[i], q[..., i]))
            out[..., i, :3, :3] = rot
            out[..., i, :3, 3] = pos
        return out

    def joint_positions(self, q: ArrayLike) -> FloatArray:
        """Joint origins and the tip point, ``(..., n + 1, 3)``; link ``i`` spans rows i, i+1."""
        return self._positions(self.frames(q))

    def joint_axes(self, q: ArrayLike) -> FloatArray:
        """Unit joint axes in the base frame, ``(..., n, 3)``."""
        return self._axes(self.frames(q))

    def joint_positions_and_axes(self, q: ArrayLike) -> tuple[FloatArray, FloatArray]:
        """:meth:`joint_positions` and :meth:`joint_axes` from one forward kinematics pass."""
        frames = self.frames(q)
        return self._positions(frames), self._axes(frames)

    def _positions(self, frames: FloatArray) -> FloatArray:
        pts = np.empty((*frames.shape[:-3], self.dof + 1, 3))
        pts[..., : self.dof, :] = frames[..., :3, 3]
        last = frames[..., -1, :, :]
        pts[..., self.dof, :] = last[..., :3, :3] @ self.tip_offset + last[..., :3, 3]
        return pts

    def _axes(self, frames: FloatArray) -> FloatArray:
        return np.einsum("...ij,...j->...i", frames[..., :3, :3], self.axes)

    def link_segments(self, q: ArrayLike) -> tuple[FloatArray, FloatArray]:
        """Start and end points of every link axis, each ``(..., n, 3)``."""
        pts = self.joint_positions(q)
        return pts[..., :-1, :], pts[..., 1:, :]

    def tip_position(self, q: ArrayLike) -> FloatArray:
        """Tip point, ``(..., 3)``."""
        return self.joint_positions(q)[..., -1, :]

    def point_velocities(
        self, q: ArrayLike, qd: ArrayLike, link: ArrayLike, s: ArrayLike
    ) -> FloatArray:
        """Velocity of the point at fraction ``s`` along link ``link`` (broadcast), ``(..., 3)``.

        ``q, qd : (..., n)``; ``link`` int and ``s`` float broadcast against the batch shape.
        v = sum over joints j <= link of qd_j * (axis_j x (p - o_j)).
        """
        q = self.check_q(q)
        qd = self.check_q(qd, "qd")
        pts, axes = self.joint_positions_and_axes(q)
        link = np.asarray(link, dtype=int)
        s = np.asarray(s, dtype=float)
        batch = np.broadcast_shapes(q.shape[:-1], link.shape, s.shape)
        pts = np.broadcast_to(pts, batch + pts.shape[-2:])
        axes = np.broadcast_to(axes, batch + axes.shape[-2:])
        qd = np.broadcast_to(qd, (*batch, self.dof))
        link = np.broadcast_to(link, batch)
        s = np.broadcast_to(s, batch)
        if np.any((link < 0) | (link >= self.dof)):
            raise InputError(f"link index out of range 0..{self.dof - 1}")
        a = np.take_along_axis(pts, link[..., None, None], axis=-2)[..., 0, :]
        b = np.take_along_axis(pts, link[..., None, None] + 1, axis=-2)[..., 0, :]
        p = a + s[..., None] * (b - a)
        lever = p[..., None, :] - pts[..., :-1, :]
        contrib = np.cross(axes, lever) * qd[..., None]
        mask = np.arange(self.dof) <= link[..., None]
        return np.sum(contrib * mask[..., None], axis=-2)

    def contact_radius(self, link: int, tip: bool) -> float:
        """Contact radius ``w`` on ``link``: tip/joint sphere if ``tip``, else link cylinder."""
        if not tip:
            return float(self.link_radii[link])
        if link == self.dof - 1:
            return max(self.tip_radius, float(self.link_radii[link]))
        return float(max(self.link_radii[link], self.link_radii[link + 1]))

    @property
    def base(self) -> FloatArray:
        """The first joint's origin, ``(dim,)``: the base point every configuration shares."""
        return self.joint_positions(np.zeros(self.dof))[0, : self.dim]

    @property
    def reach(self) -> float:
        """Upper bound on the distance from the base to any point of the robot."""
        lengths = np.linalg.norm(self.origins[1:, :3, 3], axis=1).sum() + np.linalg.norm(
            self.tip_offset)
        return float(np.linalg.norm(self.origins[0, :3, 3]) + lengths
                     + max(self.tip_radius, float(self.link_radii.max())))
