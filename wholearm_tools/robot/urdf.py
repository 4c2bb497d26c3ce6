"""URDF in and out for capsule-link serial chains.

Written URDF: ``base_link`` → revolute ``joint_i`` → ``link_i`` … → fixed ``tip_joint`` →
``tip_link``.  Each ``link_i`` carries a collision cylinder along the link axis (radius ``w``) and a
collision sphere at its outer joint; ``tip_link`` carries the tip sphere.  Reading accepts any
URDF whose chain from the root to its single leaf is made of revolute/continuous/fixed joints;
fixed joints are folded into the next origin.  Link radii come from the collision cylinder of each
moving link (or its largest collision sphere); the tip radius from a sphere on the leaf link.
"""

from __future__ import annotations

import warnings
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

from wholearm_tools.errors import RobotModelError
from wholearm_tools.robot.model import RobotModel, transform_from_xyz_rpy


def _floats(text: str | None, count: int, what: str) -> np.ndarray:
    if text is None:
        return np.zeros(count)
    try:
        values = np.array([float(v) for v in text.split()], dtype=float)
    except ValueError:
        raise RobotModelError(f"URDF {what}: cannot parse numbers from {text!r}") from None
    if values.shape != (count,):
        raise RobotModelError(f"URDF {what}: expected {count} numbers, got {text!r}")
    return values


def _origin(elem: ET.Element | None, what: str) -> np.ndarray:
    if elem is None:
        return np.eye(4)
    return transform_from_xyz_rpy(_floats(elem.get("xyz"), 3, f"{what} origin xyz"),
                                  _floats(elem.get("rpy"), 3, f"{what} origin rpy"))


def _fmt(values: np.ndarray) -> str:
    return " ".join(f"{float(v):.9g}" for v in np.atleast_1d(values))


def robot_from_urdf(text: str, source: str = "URDF") -> RobotModel:
    """Parse URDF ``text`` into a :class:`RobotModel`; ``source`` names it in error messages."""
    try:
        root = ET.fromstring(text)
    except ET.ParseError as exc:
        raise RobotModelError(f"{source}: malformed URDF XML ({exc})") from None
    if root.tag != "robot":
        raise RobotModelError(f"{source}: root element is <{root.tag}>, expected <robot>")
    links = {link.get("name"): link for link in root.findall("link")}
    joints = root.findall("joint")
    by_parent: dict[str, list[ET.Element]] = {}
    children = set()
    for joint in joints:
        parent, child = joint.find("parent"), joint.find("child")
        if parent is None or child is None:
            raise RobotModelError(f"{source}: joint {joint.get('name')!r} lacks parent or child")
        by_parent.setdefault(parent.get("link", ""), []).append(joint)
        children.add(child.get("link"))
    roots = [name for name in links if name not in children]
    if len(roots) != 1:
        raise RobotModelError(f"{source}: expected one root link, found {roots}")

    names, origins, axes, lower, upper, vel, eff, radii = [], [], [], [], [], [], [], []
    pending = np.eye(4)  # fixed transforms accumulated since the last revolute joint
    current = roots[0]
    while current in by_parent:
        nxt = by_parent[current]
        if len(nxt) != 1:
            raise RobotModelError(f"{source}: link {current!r} branches; only serial chains are "
                                  "supported")
        joint = nxt[0]
        jtype, jname = joint.get("type"), joint.get("name", "?")
        origin = _origin(joint.find("origin"), f"joint {jname!r}")
        child = joint.find("child").get("link", "")  # type: ignore[union-attr]
        if jtype in ("revolute", "continuous"):
            names.append(jname)
            origins.append(pending @ origin)
            pending = np.eye(4)
            axis = joint.find("axis")
            axes.append(_floats(axis.get("xyz") if axis is not None else "1 0 0", 3,
                                f"joint {jname!r} axis"))
            limit = joint.find("limit")
            lo, hi = (-np.pi, np.pi)
            if jtype == "revolute" and limit is not None:
                lo = float(limit.get("lower", -np.pi))
                hi = float(limit.get("upper", np.pi))
            lower.append(lo)
            upper.append(hi)
            vel.append(float(limit.get("velocity", 1.0)) if limit is not None else 1.0)
            eff.append(float(limit.get("effort", 10.0)) if limit is not None else 10.0)
            radii.append(_link_radius(links.get(child), child, source))
        elif jtype == "fixed":
            pending = pending @ origin
        else:
            raise RobotModelError(f"{source}: joint {jname!r} has unsupported type {jtype!r}")
        current = child
    if not names:
        raise RobotModelError(f"{source}: no revolute joints in the chain")
    tip_radius = _sphere_radius(links.get(current)) or 0.0
    return RobotModel(
        name=root.get("name", "robot"), joint_names=tuple(names), origins=np.stack(origins),
        axes=np.array(axes), tip_offset=pending[:3, 3].copy(), link_radii=np.array(radii),
        tip_radius=tip_radius, lower=np.array(lower), upper=np.array(upper),
        velocity_limits=np.array(vel), effort_limits=np.array(eff),
    )


def _sphere_radius(link: ET.Element | None) -> float | None:
    if link is None:
        return None
    radii = [float(s.get("radius", 0.0)) for s in link.findall("collision/geometry/sphere")]
    return max(radii) if radii else None


def _link_radius(link: ET.Element | None, name: str, source: str) -> float:
    if link is not None:
        cylinders = link.findall("collision/geometry/cylinder")
        if cylinders:
            return max(float(c.get("radius", 0.0)) for c in cylinders)
        sphere = _sphere_radius(link)
        if sphere is not None:
            return sphere
    raise RobotModelError(f"{source}: link {name!r} has no collision cylinder or sphere; "
                          "wholearm needs capsule links")


def robot_to_urdf(robot: RobotModel) -> str:
    """Serialise ``robot`` as URDF text that :func:`robot_from_urdf` reads back exactly."""
    from scipy.spatial.transform import Rotation

    root = ET.Element("robot", name=robot.name)
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


def load_urdf(path: str | Path) -> RobotModel:
    """Read a URDF file; errors name the file."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        raise RobotModelError(f"{path}: cannot read URDF ({exc.strerror})") from None
    return robot_from_urdf(text, source=str(path))
