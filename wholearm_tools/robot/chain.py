"""The serial chain a RobotModel describes, chosen from a URDF's kinematic tree.

A URDF is a tree of links joined by joints; wholearm models one serial chain of revolute joints
from a base link to a tip link.  :func:`select_chain` picks that chain:

* the base is ``base_link`` or the tree's root;
* the tip is ``tip_link`` or, when not given, the end of the only branch below the base that
  holds revolute joints (branches whose joints the log does not drive are set aside when the
  log's joint names are known; branches that end in the same joints and the same tip point are
  one choice).  Anything else is ambiguous, and the error lists the candidates for
  ``--tip-link``.

Joints off the chain are not modelled: :class:`Chain` lists them (and the links behind them) so
that the reader can say which log joints it ignores and why.
"""

from __future__ import annotations

from collections.abc import Collection, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from wholearm_tools.errors import RobotModelError
from wholearm_tools.robot.model import MIN_TIP_DISTANCE

MOVING = ("revolute", "continuous")
"""Joint types the model drives."""

TIP_TOLERANCE = MIN_TIP_DISTANCE
"""Tip points closer than this [m] are the same tip (two frames at one point, e.g. a tool frame
and an end-effector frame), and a last link shorter than this has no tip."""


def _origin(joint: Any) -> np.ndarray:
    return np.eye(4) if joint.origin is None else np.asarray(joint.origin, dtype=float)


@dataclass(frozen=True, slots=True)
class RigidGroup:
    """URDF links that move with one model joint, each with its pose in that joint's frame.

    ``links[k]`` sits at ``poses[k]`` (4x4, link frame → joint frame).  The first entry is the
    joint's child link; the rest are reached from it through fixed joints (on the chain up to
    the next revolute joint, and fixed branches off it).
    """

    joint: str
    links: tuple[str, ...]
    poses: tuple[np.ndarray, ...]


@dataclass(frozen=True, slots=True)
class Chain:
    """A chain chosen from a URDF tree (see :func:`select_chain`).

    ``joints`` are the URDF joints on the path base → tip in order (fixed ones included);
    ``moving`` the names of its revolute/continuous joints (the model's joints); ``groups`` one
    :class:`RigidGroup` per moving joint; ``off_chain`` maps every URDF joint the model does
    not drive to why: ``"fixed"`` (a fixed joint, on the chain or not), ``"upstream"`` (a movable
    joint between the tree's root and the base, so it moves the base), ``"branch"`` (a movable
    joint on a branch the chain does not follow); ``not_modelled`` the links
    behind off-chain movable joints that hang off the chain (their geometry is not part of any
    capsule, because the model has no joint to move them).
    """

    base: str
    tip: str
    joints: tuple[Any, ...]
    moving: tuple[str, ...]
    groups: tuple[RigidGroup, ...]
    off_chain: dict[str, str]
    not_modelled: tuple[tuple[str, str], ...]


class _Tree:
    def __init__(self, robot: Any, source: str) -> None:
        self.source = source
        self.links = [link.name for link in robot.links]
        self.link_set = set(self.links)
        self.parent_joint: dict[str, Any] = {}
        self.children: dict[str, list[Any]] = {name: [] for name in self.links}
        for joint in robot.joints:
            for end in (joint.parent, joint.child):
                if end not in self.link_set:
                    raise RobotModelError(f"{source}: joint {joint.name!r} refers to an unknown "
                                          f"link {end!r}")
            if joint.child in self.parent_joint:
                raise RobotModelError(f"{source}: link {joint.child!r} has two parent joints "
                                      f"({self.parent_joint[joint.child].name!r}, "
                                      f"{joint.name!r}); a URDF must be a tree")
            self.parent_joint[joint.child] = joint
            self.children[joint.parent].append(joint)
        roots = [name for name in self.links if name not in self.parent_joint]
        if len(roots) != 1:
            raise RobotModelError(f"{source}: expected one root link, found {roots}")
        self.root = roots[0]

    def check_link(self, name: str, option: str) -> None:
        if name not in self.link_set:
            close = ", ".join(self.links[:12]) + (" …" if len(self.links) > 12 else "")
            raise RobotModelError(f"{self.source}: no link {name!r} ({option}); links: {close}")

    def path(self, base: str, tip: str) -> list[Any]:
        """Joints from ``base`` down to ``tip``."""
        out: list[Any] = []
        link = tip
        while link != base:
            joint = self.parent_joint.get(link)
            if joint is None:
                raise RobotModelError(f"{self.source}: link {tip!r} is not below the base link "
                                      f"{base!r}")
            out.append(joint)
            link = joint.parent
        return out[::-1]

    def below(self, link: str) -> list[str]:
        """Every link below ``link`` (itself included), depth first."""
        out, stack = [], [link]
        while stack:
            name = stack.pop()
            out.append(name)
            stack.extend(j.child for j in reversed(self.children[name]))
        return out


def _tip_point(path: Sequence[Any]) -> np.ndarray:
    """Tip point in the frame of the path's last movable joint (fixed joints after it)."""
    tf = np.eye(4)
    for joint in reversed(path):
        if joint.type != "fixed":
            break
        tf = _origin(joint) @ tf
    return tf[:3, 3]


def _describe(tree: _Tree, base: str, tip: str) -> str:
    moving = [j.name for j in tree.path(base, tip) if j.type != "fixed"]
    return f"{tip!r} ({len(moving)} joints, last {moving[-1]!r})"


def select_chain(robot: Any, source: str, *, base_link: str | None = None,
                 tip_link: str | None = None, joints: Collection[str] | None = None) -> Chain:
    """Choose the serial chain of ``robot`` (a ``yourdfpy.Robot``) that wholearm models.

    Parameters
    ----------
    robot : yourdfpy.Robot
    source : names the URDF in error messages
    base_link, tip_link : ends of the chain (default: the root, and the only candidate tip)
    joints : joint names the log carries, when known; used to set aside branches the log
        does not drive
    """
    tree = _Tree(robot, source)
    base = tree.root if base_link is None else base_link
    tree.check_link(base, "--base-link")
    if tip_link is not None:
        tree.check_link(tip_link, "--tip-link")
        tip = tip_link
        path = tree.path(base, tip)
    else:
        tip = _choose_tip(tree, base, joints)
        path = tree.path(base, tip)
    for joint in path:
        if joint.type not in (*MOVING, "fixed"):
            raise RobotModelError(f"{source}: joint {joint.name!r} on the chain {base!r} → "
                                  f"{tip!r} has unsupported type {joint.type!r} (wholearm "
                                  "models revolute joints)")
    moving = tuple(j.name for j in path if j.type in MOVING)
    if not moving:
        raise RobotModelError(f"{source}: no revolute joints in the chain {base!r} → {tip!r}")
    on_chain = {j.name for j in path}
    upstream = {j.name for j in tree.path(tree.root, base)}
    off_chain = {}
    for joint in robot.joints:
        if joint.type == "fixed":
            off_chain[joint.name] = "fixed"
        elif joint.name not in on_chain:
            off_chain[joint.name] = "upstream" if joint.name in upstream else "branch"
    groups, not_modelled = _rigid_groups(tree, path)
    return Chain(base=base, tip=tip, joints=tuple(path), moving=moving, groups=groups,
                 off_chain=off_chain, not_modelled=not_modelled)


def _choose_tip(tree: _Tree, base: str, joints: Collection[str] | None) -> str:
    leaves = [name for name in tree.below(base) if not tree.children[name]]
    candidates = [leaf for leaf in leaves
                  if any(j.type != "fixed" for j in tree.path(base, leaf))]
    if not candidates:
        raise RobotModelError(f"{tree.source}: no revolute joints below the base link {base!r}")
    if joints is not None:
        driven = [leaf for leaf in candidates
                  if all(j.name in joints for j in tree.path(base, leaf) if j.type != "fixed")]
        candidates = driven or candidates
    # leaves with the same joints and the same tip point are one choice (e.g. tool0 and ee_link)
    distinct: list[str] = []
    for leaf in candidates:
        path = tree.path(base, leaf)
        key = tuple(j.name for j in path if j.type != "fixed")
        if not any(key == tuple(j.name for j in tree.path(base, other) if j.type != "fixed")
                   and np.allclose(_tip_point(path), _tip_point(tree.path(base, other)),
                                   atol=TIP_TOLERANCE)
                   for other in distinct):
            distinct.append(leaf)
    if len(distinct) > 1:
        paths = [tree.path(base, leaf) for leaf in distinct]
        fork = base
        for joints_at_depth in zip(*paths, strict=False):
            if len({j.name for j in joints_at_depth}) > 1:
                break
            fork = joints_at_depth[0].child
        listed = "; ".join(_describe(tree, base, leaf) for leaf in distinct)
        raise RobotModelError(f"{tree.source}: the URDF branches at link {fork!r}; choose the "
                              f"chain's end with --tip-link: {listed}")
    return distinct[0]


def _rigid_groups(tree: _Tree, path: Sequence[Any]
                  ) -> tuple[tuple[RigidGroup, ...], tuple[tuple[str, str], ...]]:
    """One group per moving joint of ``path``: the links that move with it, posed in its frame.

    Links reached through fixed joints (on the chain before the next moving joint, or on
    branches) join the group; branches behind a movable joint that is not on the chain are
    listed as not modelled, as ``(link, joint)``.
    """
    on_chain = {j.name for j in path}
    groups: list[RigidGroup] = []
    not_modelled: list[tuple[str, str]] = []
    moving_idx = [k for k, j in enumerate(path) if j.type in MOVING]
    for n, k in enumerate(moving_idx):
        joint = path[k]
        stop = moving_idx[n + 1] if n + 1 < len(moving_idx) else len(path)
        links: list[str] = []
        poses: list[np.ndarray] = []
        stack = [(joint.child, np.eye(4))]
        chain_fixed = {j.name for j in path[k + 1:stop]}
        while stack:
            link, pose = stack.pop()
            links.append(link)
            poses.append(pose)
            for child in reversed(tree.children[link]):
                if child.type == "fixed" and (child.name in chain_fixed
                                              or child.name not in on_chain):
                    stack.append((child.child, pose @ _origin(child)))
                elif child.name not in on_chain:
                    not_modelled.extend((name, child.name) for name in tree.below(child.child))
        groups.append(RigidGroup(joint.name, tuple(links), tuple(poses)))
    return tuple(groups), tuple(not_modelled)
