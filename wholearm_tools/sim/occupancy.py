"""Coarse occupancy grid of the space the robot has swept (cells swept are known free)."""

from __future__ import annotations

import itertools

import numpy as np
from numpy.typing import NDArray

from wholearm_tools.robot.model import RobotModel

FloatArray = NDArray[np.float64]


class SweptGrid:
    """Boolean voxel (or pixel, for planar robots) grid over the robot's reach.

    Parameters
    ----------
    robot : RobotModel
    cell : float
        Cell size [m]; default ``reach / 25``.
    """

    def __init__(self, robot: RobotModel, cell: float | None = None) -> None:
        self.robot = robot
        self.dim = robot.dim
        reach = robot.reach
        self.cell = float(cell) if cell else reach / 25.0
        base = robot.base
        self.origin = base - reach
        self.shape = tuple([int(np.ceil(2 * reach / self.cell)) + 1] * self.dim)
        self.swept = np.zeros(self.shape, dtype=bool)
        self.attempted = np.zeros(self.shape, dtype=bool)
        # sample points along each link axis, spaced at most half a cell apart
        pts0 = robot.joint_positions(np.zeros(robot.dof))
        lengths = np.linalg.norm(np.diff(pts0, axis=0), axis=1)
        self._fractions = [np.linspace(0.0, 1.0, max(2, int(np.ceil(2 * L / self.cell)) + 1))
                           for L in lengths]

    def robot_points(self, Q: FloatArray) -> FloatArray:
        """Points along every link axis for configurations ``Q (M, n)``, shape ``(P, dim)``."""
        pts = self.robot.joint_positions(np.atleast_2d(Q))[..., : self.dim]
        out = []
        for i, fr in enumerate(self._fractions):
            a, b = pts[:, i], pts[:, i + 1]
            out.append((a[:, None, :] + fr[None, :, None] * (b - a)[:, None, :]).reshape(-1,
                                                                                       self.dim))
        return np.concatenate(out)

    def cells(self, points: FloatArray) -> NDArray[np.int64]:
        """Flat indices of the cells holding ``points`` (points outside the grid dropped)."""
        ijk = np.floor((points - self.origin) / self.cell).astype(np.int64)
        inside = np.all((ijk >= 0) & (ijk < np.array(self.shape)), axis=1)
        return np.ravel_multi_index(tuple(ijk[inside].T), self.shape)

    def mark(self, Q: FloatArray) -> None:
        """Mark the cells swept by the robot axes at configurations ``Q (M, n)``."""
        self.swept.flat[self.cells(self.robot_points(Q))] = True

    def attempt(self, Q: FloatArray) -> None:
        """Mark cells a blocked move was commanded through (tried already, not swept)."""
        self.attempted.flat[self.cells(self.robot_points(Q))] = True

    def novelty(self, Q: FloatArray) -> int:
        """Number of distinct cells, neither swept nor already attempted, that the robot axes
        visit at configurations ``Q``."""
        idx = np.unique(self.cells(self.robot_points(Q)))
        return int(np.count_nonzero(~(self.swept.flat[idx] | self.attempted.flat[idx])))

    @property
    def fraction_swept(self) -> float:
        return float(self.swept.mean())


def densify(vertices: FloatArray, robot_step: float, lever: float) -> FloatArray:
    """Configurations along a joint-space polyline such that no robot point moves more than
    ``robot_step`` between consecutive ones (``lever`` bounds the distance of any point from any
    joint), shape ``(K, n)``."""
    out = [vertices[:1]]
    for a, b in itertools.pairwise(vertices):
        k = max(1, int(np.ceil(np.abs(b - a).sum() * lever / robot_step)))
        f = np.linspace(0.0, 1.0, k + 1)[1:, None]
        out.append(a + f * (b - a))
    return np.concatenate(out)
