"""URDF in and out: real robot descriptions to capsule-link serial chains, and back.

Reading (:func:`urdf_chain`, :func:`robot_from_urdf`, :func:`load_urdf`):

1. The text is checked before any XML parser sees it in full: at most :data:`MAX_URDF_BYTES`,
   not xacro (named in the error: expand it first), and parsed with ``defusedxml`` with
   document type declarations refused, so entity expansion ("billion laughs") and external
   entities cannot happen.
2. ``yourdfpy`` turns it into links and joints (no meshes loaded at this point).
3. :func:`wholearm_tools.robot.chain.select_chain` picks the serial chain (``base_link`` /
   ``tip_link``, or the only branch the log's joints drive); fixed joints are folded into the
   next origin, as before.
4. Each moving link becomes a capsule: a link described by a collision cylinder and/or spheres
   (wholearm's own capsule URDFs) keeps that radius exactly; a link described by meshes or boxes
   gets the capsule fitted by :mod:`wholearm_tools.robot.capsules`.  The tip is the origin of
   the chain's tip link (fixed joints after the last revolute joint); when the last link has
   no tip frame, the point of its geometry farthest from its joint.  A chain whose last link
   still has zero length cannot work and is refused.

Writing (:func:`robot_to_urdf`): ``base_link`` → revolute ``joint_i`` → ``link_i`` … → fixed
``tip_joint`` → ``tip_link``.  Each ``link_i`` carries a collision cylinder along the link axis
(radius ``w``) and a collision sphere at its outer joint; ``tip_link`` carries the tip sphere.
Reading it back gives the same model (numbers are written with 9 significant digits).
"""

from __future__ import annotations

import io
import warnings
import xml.etree.ElementTree as ET
from collections.abc import Collection, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from wholearm_tools.errors import RobotModelError
from wholearm_tools.robot.capsules import CapsuleFit, far_point, fit_capsule, group_points
from wholearm_tools.robot.chain import MOVING, TIP_TOLERANCE, Chain, select_chain
from wholearm_tools.robot.model import RobotModel

MAX_URDF_BYTES = 16 * 2**20
"""Largest URDF accepted (16 MiB; real robot descriptions are well under 1 MiB)."""

XACRO_NAMESPACE = "http://www.ros.org/wiki/xacro"


class RobotWarning(UserWarning):
    """A robot description was usable but part of it is not modelled."""


def _fmt(values: np.ndarray) -> str:
    return " ".join(f"{float(v):.9g}" for v in np.atleast_1d(values))


def _xacro_hint(text: str, source: str) -> None:
    markers = [m for m in ("xmlns:xacro", "<xacro:", "${", "$(find") if m in text]
    if source.endswith(".xacro") or markers:
        found = f" (it has {', '.join(repr(m) for m in markers)})" if markers else ""
        raise RobotModelError(f"{source}: a xacro file{found}, not a URDF; expand it first: "
                              "`xacro robot.urdf.xacro > robot.urdf`")


def parse_urdf_xml(text: str, source: str = "URDF") -> ET.Element:
    """The ``<robot>`` element of ``text``, parsed safely; RobotModelError naming ``source``.

    Refused: more than :data:`MAX_URDF_BYTES`, xacro, any DOCTYPE (entities, external
    references), malformed XML, another root element.
    """
    from defusedxml import DefusedXmlException
    from defusedxml import ElementTree as SafeET

    size = len(text.encode("utf-8"))
    if size > MAX_URDF_BYTES:
        raise RobotModelError(f"{source}: URDF of {size / 2**20:.1f} MiB exceeds the "
                              f"{MAX_URDF_BYTES // 2**20} MiB limit")
    _xacro_hint(text, source)
    try:
        root = SafeET.fromstring(text, forbid_dtd=True, forbid_entities=True,
                              forbid_external=True)
    except DefusedXmlException as exc:
        raise RobotModelError(f"{source}: refused: the URDF declares a DOCTYPE or entities "
                              f"({type(exc).__name__}); a URDF needs neither") from None
    except ET.ParseError as exc:
        raise RobotModelError(f"{source}: malformed URDF XML ({exc})") from None
    if root.tag != "robot":
        raise RobotModelError(f"{source}: root element is <{root.tag}>, expected <robot>")
    if any(elem.tag.startswith(f"{{{XACRO_NAMESPACE}}}") for elem in root.iter()):
        raise RobotModelError(f"{source}: a xacro file (xacro elements found), not a URDF; "
                              "expand it first: `xacro robot.urdf.xacro > robot.urdf`")
    if not root.get("name"):
        raise RobotModelError(f"{source}: <robot> has no name attribute")
    return root


def _yourdfpy_robot(text: str, source: str) -> Any:
    """``yourdfpy.Robot`` of an already validated URDF text."""
    from wholearm_tools._parallel import interruptible_import

    yourdfpy = interruptible_import("yourdfpy")

    try:
        urdf = yourdfpy.URDF.load(io.BytesIO(text.encode("utf-8")), build_scene_graph=False,
                                  build_collision_scene_graph=False, load_meshes=False,
                                  load_collision_meshes=False)
    except Exception as exc:  # yourdfpy raises bare KeyError/AttributeError/ValueError
        raise RobotModelError(f"{source}: cannot read the URDF ({type(exc).__name__}: "
                              f"{exc})") from None
    return urdf.robot


@dataclass(frozen=True, slots=True, eq=False)
class UrdfChain:
    """A robot read from a URDF, with what was chosen and fitted on the way.

    ``robot``: the model; ``chain``: the URDF chain it follows (base, tip, joints off the
    chain); ``fits``: one :class:`CapsuleFit` per moving link; ``link_names``: the URDF link
    each model link stands for (the child of its joint); ``tip_note``: how the tip was placed;
    ``source``: names the URDF in messages.
    """

    robot: RobotModel
    chain: Chain
    fits: tuple[CapsuleFit, ...]
    link_names: tuple[str, ...]
    tip_note: str
    source: str

    def ignored_log_joints(self, names: Sequence[str]) -> dict[str, str]:
        """Log joints the chain does not drive, each with the reason, in log order.

        RobotModelError for a joint that moves the chain's base (between the URDF's root and
        the base link): ignoring it would put every link in the wrong place.
        """
        out: dict[str, str] = {}
        for name in names:
            if name in self.robot.joint_names:
                continue
            where = self.chain.off_chain.get(name)
            if where == "upstream":
                raise RobotModelError(
                    f"{self.source}: log joint {name!r} moves the chain's base "
                    f"{self.chain.base!r} (it lies above it in the URDF); choose a --base-link "
                    "above that joint")
            out[name] = {"branch": "URDF joint off the chain",
                         "fixed": "fixed joint in the URDF"}.get(where or "", "not in the URDF")
        return out

    def describe(self) -> list[str]:
        """Human-readable lines: chain, per-link capsule, tip, what is not modelled."""
        robot = self.robot
        lines = [f"robot {robot.name!r}: chain {self.chain.base!r} → {self.chain.tip!r}, "
                 f"{robot.dof} revolute joints, reach {robot.reach:.3f} m"
                 + (", planar" if robot.planar else "")]
        ends = [robot.origins[i + 1, :3, 3] if i + 1 < robot.dof else robot.tip_offset
                for i in range(robot.dof)]
        for i, fit in enumerate(self.fits):
            lines.append(f"  link {i} ({self.link_names[i]}, joint {robot.joint_names[i]!r}): "
                         f"length {np.linalg.norm(ends[i]):.4f} m, radius "
                         f"{robot.link_radii[i]:.4f} m; {fit.describe()}")
        lines.append(f"  tip: {self.tip_note}, radius {robot.tip_radius:.4f} m")
        for link, joint in self.chain.not_modelled:
            lines.append(f"  not modelled: link {link!r} (behind joint {joint!r}, which the "
                         "chain does not drive)")
        return lines


def _capsule_radius(link: Any) -> float | None:
    """Radius of a link described by collision cylinders and/or spheres only (the largest
    cylinder radius, else the largest sphere), None when it has other or no geometry."""
    shapes = [c.geometry for c in link.collisions if c.geometry is not None]
    if not shapes or any(g.cylinder is None and g.sphere is None for g in shapes):
        return None
    cylinders = [float(g.cylinder.radius) for g in shapes if g.cylinder is not None]
    if cylinders:
        return max(cylinders)
    return max(float(g.sphere.radius) for g in shapes)


def _tip_radius(link: Any) -> float:
    radii = [float(c.geometry.sphere.radius) for c in link.collisions
             if c.geometry is not None and c.geometry.sphere is not None]
    return max(radii) if radii else 0.0


def urdf_chain(text: str, source: str = "URDF", *, base_link: str | None = None,
               tip_link: str | None = None, joints: Collection[str] | None = None,
               package_paths: Sequence[str | Path] = (), urdf_dir: str | Path | None = None
               ) -> UrdfChain:
    """Read URDF ``text`` into a :class:`UrdfChain` (see the module docstring).

    Parameters
    ----------
    text : the URDF
    source : names it in error messages (a file name, or a log and topic)
    base_link, tip_link : ends of the chain (default: the root, and the only candidate end)
    joints : the log's joint names, when known (picks the branch they drive)
    package_paths : folders that resolve ``package://`` mesh references
    urdf_dir : folder of the URDF file, for relative mesh paths (None for a log's URDF)
    """
    parse_urdf_xml(text, source)
    urdf = _yourdfpy_robot(text, source)
    chain = select_chain(urdf, source, base_link=base_link, tip_link=tip_link, joints=joints)
    links = {link.name: link for link in urdf.links}
    paths = tuple(Path(p) for p in package_paths)
    folder = Path(urdf_dir) if urdf_dir is not None else None

    names, origins, axes, lower, upper, vel, eff = [], [], [], [], [], [], []
    pending = np.eye(4)
    for joint in chain.joints:
        origin = np.eye(4) if joint.origin is None else np.asarray(joint.origin, dtype=float)
        if joint.type == "fixed":
            pending = pending @ origin
            continue
        names.append(joint.name)
        origins.append(pending @ origin)
        pending = np.eye(4)
        axes.append(np.asarray(joint.axis if joint.axis is not None else [1.0, 0.0, 0.0],
                               dtype=float))
        limit = joint.limit
        lo, hi = -np.pi, np.pi
        if joint.type == "revolute" and limit is not None:
            lo = limit.lower if limit.lower is not None else -np.pi
            hi = limit.upper if limit.upper is not None else np.pi
        lower.append(lo)
        upper.append(hi)
        vel.append(limit.velocity if limit is not None and limit.velocity is not None else 1.0)
        eff.append(limit.effort if limit is not None and limit.effort is not None else 10.0)
    tip_offset = pending[:3, 3].copy()
    tip_note = f"origin of {chain.tip!r}"

    n = len(names)
    for i in range(n - 1):
        if np.linalg.norm(origins[i + 1][:3, 3]) < TIP_TOLERANCE:
            raise RobotModelError(
                f"{source}: joints {names[i]!r} and {names[i + 1]!r} sit at one point (link "
                f"{chain.groups[i].links[0]!r} has zero length); wholearm's capsule chain needs "
                "a length between consecutive joints (intersecting wrist axes are not supported)")
    radii: list[float] = []
    fits: list[CapsuleFit] = []
    for i, group in enumerate(chain.groups):
        last = i == n - 1
        end = origins[i + 1][:3, 3] if not last else tip_offset
        child = links[group.links[0]]
        capsule = _capsule_radius(child)
        if capsule is not None:
            fit = CapsuleFit(link=i, joint=group.joint, method="capsule", sources=(child.name,),
                             radius=capsule, length=float(np.linalg.norm(end)))
        else:
            points, used = group_points([links[name] for name in group.links], group.poses,
                                        urdf_dir=folder, package_paths=paths, source=source)
            if last and np.linalg.norm(end) < TIP_TOLERANCE and points.shape[0]:
                tip_offset = end = far_point(points)
                tip_note = (f"point of {', '.join(used)} farthest from joint {group.joint!r} "
                            f"(no tip frame after it in the URDF)")
            if points.shape[0]:
                fit = fit_capsule(points, end, link=i, joint=group.joint, sources=used)
            else:
                raise RobotModelError(
                    f"{source}: link {child.name!r} (moved by joint {group.joint!r}) has no "
                    "collision or visual geometry; wholearm needs the shape of every moving "
                    "link (a cylinder, sphere, box or mesh)")
        if last and np.linalg.norm(end) < TIP_TOLERANCE:
            raise RobotModelError(
                f"{source}: the chain ends at joint {group.joint!r} with no tip: its link "
                f"{child.name!r} has zero length (no fixed joint to a tip link after it); "
                "add a tip link, or choose another --tip-link")
        radii.append(fit.radius)
        fits.append(fit)

    not_modelled = [link for link, _ in chain.not_modelled
                    if links[link].collisions or links[link].visuals]
    if not_modelled:
        joints_behind = sorted({j for link, j in chain.not_modelled if link in not_modelled})
        warnings.warn(f"{source}: links {not_modelled} are not modelled: they move with joints "
                      f"{joints_behind}, which are not on the chain {chain.base!r} → "
                      f"{chain.tip!r}", RobotWarning, stacklevel=2)
    robot = RobotModel(
        name=urdf.name, joint_names=tuple(names), origins=np.stack(origins),
        axes=np.array(axes), tip_offset=tip_offset, link_radii=np.array(radii),
        tip_radius=_tip_radius(links[chain.tip]), lower=np.array(lower, dtype=float),
        upper=np.array(upper, dtype=float), velocity_limits=np.array(vel, dtype=float),
        effort_limits=np.array(eff, dtype=float),
    )
    return UrdfChain(robot=robot, chain=chain, fits=tuple(fits),
                     link_names=tuple(g.links[0] for g in chain.groups), tip_note=tip_note,
                     source=source)


def robot_from_urdf(text: str, source: str = "URDF", **options: Any) -> RobotModel:
    """Parse URDF ``text`` into a :class:`RobotModel`; ``source`` names it in error messages.

    ``options`` are those of :func:`urdf_chain` (``base_link``, ``tip_link``, ``joints``,
    ``package_paths``, ``urdf_dir``).
    """
    return urdf_chain(text, source, **options).robot


def read_urdf_text(path: str | Path) -> str:
    """Text of a URDF file, size-capped; RobotModelError naming the file."""
    path = Path(path)
    try:
        size = path.stat().st_size
        if size > MAX_URDF_BYTES:
            raise RobotModelError(f"{path}: URDF of {size / 2**20:.1f} MiB exceeds the "
                                  f"{MAX_URDF_BYTES // 2**20} MiB limit")
        return path.read_text(encoding="utf-8")
    except OSError as exc:
        raise RobotModelError(f"{path}: cannot read URDF ({exc.strerror})") from None
    except UnicodeDecodeError:
        raise RobotModelError(f"{path}: not a text file (a URDF is UTF-8 XML)") from None


def load_urdf_chain(path: str | Path, **options: Any) -> UrdfChain:
    """Read a URDF file into a :class:`UrdfChain`; relative mesh paths are resolved from its
    folder; errors name the file."""
    path = Path(path)
    options.setdefault("urdf_dir", path.parent)
    return urdf_chain(read_urdf_text(path), str(path), **options)


def load_urdf(path: str | Path, **options: Any) -> RobotModel:
    """Read a URDF file into a :class:`RobotModel` (options of :func:`urdf_chain`)."""
    return load_urdf_chain(path, **options).robot


def robot_to_urdf(robot: RobotModel, notes: Sequence[str] | None = None) -> str:
    """Serialise ``robot`` as URDF text that :func:`robot_from_urdf` reads back exactly.

    ``notes``: one comment per link (how its capsule was obtained), written above it, and any
    further lines at the top.
    """
    from scipy.spatial.transform import Rotation

    root = ET.Element("robot", name=robot.name)
    if notes is not None:
        for line in notes[robot.dof:]:
            root.append(ET.Comment(f" {line} "))
    ET.SubElement(root, "link", name="base_link")
    parent = "base_link"
    for i, jname in enumerate(robot.joint_names):
        child = f"link_{i + 1}"
        joint = ET.SubElement(root, "joint", name=jname, type="revolute")
        ET.SubElement(joint, "parent", link=parent)
        ET.SubElement(joint, "child", link=child)
        rpy = Rotation.from_matrix(robot.origins[i, :3, :3]).as_euler("xyz")
        ET.SubElement(joint, "origin", xyz=_fmt(robot.origins[i, :3, 3]), rpy=_fmt(rpy))
        ET.SubElement(joint, "axis", xyz=_fmt(robot.axes[i]))
        ET.SubElement(joint, "limit", lower=_fmt(robot.lower[i]), upper=_fmt(robot.upper[i]),
                      effort=_fmt(robot.effort_limits[i]),
                      velocity=_fmt(robot.velocity_limits[i]))
        if notes is not None and i < len(notes):
            root.append(ET.Comment(f" {child}: {notes[i]} "))
        link = ET.SubElement(root, "link", name=child)
        end = robot.origins[i + 1, :3, 3] if i + 1 < robot.dof else robot.tip_offset
        length = float(np.linalg.norm(end))
        w = robot.link_radii[i]
        if length > 0:
            direction = end / length
            rot, _ = Rotation.align_vectors([direction], [[0.0, 0.0, 1.0]])
            with warnings.catch_warnings():  # gimbal lock is harmless: any valid rpy will do
                warnings.simplefilter("ignore", UserWarning)
                rpy_body = rot.as_euler("xyz")
            col = ET.SubElement(link, "collision", name=f"{child}_body")
            ET.SubElement(col, "origin", xyz=_fmt(end / 2), rpy=_fmt(rpy_body))
            ET.SubElement(ET.SubElement(col, "geometry"), "cylinder", radius=_fmt(w),
                          length=_fmt(length))
        col = ET.SubElement(link, "collision", name=f"{child}_joint")
        ET.SubElement(col, "origin", xyz=_fmt(end), rpy="0 0 0")
        ET.SubElement(ET.SubElement(col, "geometry"), "sphere", radius=_fmt(w))
        parent = child
    joint = ET.SubElement(root, "joint", name="tip_joint", type="fixed")
    ET.SubElement(joint, "parent", link=parent)
    ET.SubElement(joint, "child", link="tip_link")
    ET.SubElement(joint, "origin", xyz=_fmt(robot.tip_offset), rpy="0 0 0")
    tip = ET.SubElement(root, "link", name="tip_link")
    col = ET.SubElement(tip, "collision", name="tip")
    ET.SubElement(ET.SubElement(col, "geometry"), "sphere", radius=_fmt(robot.tip_radius))
    ET.indent(root)
    return '<?xml version="1.0"?>\n' + ET.tostring(root, encoding="unicode") + "\n"


__all__ = ["MAX_URDF_BYTES", "MOVING", "RobotWarning", "UrdfChain", "load_urdf",
           "load_urdf_chain", "parse_urdf_xml", "read_urdf_text", "robot_from_urdf",
           "robot_to_urdf", "urdf_chain"]
