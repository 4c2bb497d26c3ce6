"""``wholearm robot ROBOT.urdf``: the chain and capsules wholearm makes of a URDF.

Prints the chain (base → tip), each moving link's length and capsule radius with how it was
obtained (the URDF's own cylinder/sphere, or a capsule fitted to its meshes/boxes and how much
it over-covers them), the tip, and what is not modelled.  With ``--log RUN`` the chain is cut
to the joints that log drives, and the log joints it ignores are listed with the reason.
``--write-capsules OUT.urdf`` writes the capsule URDF (readable by every command with
``--robot``, each link commented with its fit) so a user can check it in any URDF viewer and
reuse it without the meshes.
"""

from __future__ import annotations

import json
import warnings
from pathlib import Path

import click

from cli.options import (
    MAX_URDF_BYTES,
    InputFile,
    InputPath,
    check_output_file,
    joint_topic_option,
    json_option,
    overwrite_option,
    result,
    status,
)


@click.command("robot")
@click.argument("urdf", type=InputFile(max_bytes=MAX_URDF_BYTES))
@click.option("--base-link", default=None, metavar="LINK",
              help="URDF link the chain starts at (default: the URDF's root).")
@click.option("--tip-link", default=None, metavar="LINK",
              help="URDF link the chain ends at (needed when the URDF branches).")
@click.option("--package-path", "package_paths", multiple=True,
              type=click.Path(file_okay=False, exists=True, path_type=Path),
              help="Folder resolving package:// meshes (repeatable).")
@click.option("--log", "log_path", type=InputPath(), default=None,
              help="A run log: cut the chain to the joints it drives and list the ones ignored.")
@joint_topic_option
@click.option("--write-capsules", type=click.Path(dir_okay=False, path_type=Path), default=None,
              metavar="OUT.urdf", help="Write the capsule URDF of the chain.")
@json_option
@overwrite_option
def command(urdf: Path, base_link: str | None, tip_link: str | None,
            package_paths: tuple[Path, ...], log_path: Path | None, joint_topic: str | None,
            write_capsules: Path | None, as_json: bool, overwrite: bool) -> None:
    """Show the serial chain and capsules wholearm models from URDF."""
    from wholearm_tools._io import write_text_atomic
    from wholearm_tools.robot import load_urdf_chain, robot_to_urdf

    if write_capsules is not None:
        check_output_file(write_capsules, overwrite)
    log_joints = None
    if log_path is not None:
        log_joints = _log_joints(log_path, joint_topic)
    with warnings.catch_warnings(record=True) as caught:  # shown as notes below
        warnings.simplefilter("always")
        chain = load_urdf_chain(urdf, base_link=base_link, tip_link=tip_link,
                                package_paths=package_paths, joints=log_joints)
    ignored = chain.ignored_log_joints(log_joints) if log_joints is not None else {}
    robot = chain.robot
    if write_capsules is not None:
        notes = [fit.describe() for fit in chain.fits]
        notes.append(f"capsule URDF written by wholearm from {urdf.name}: chain "
                     f"{chain.chain.base} -> {chain.chain.tip}; tip: {chain.tip_note}")
        write_text_atomic(write_capsules, robot_to_urdf(robot, notes=notes))
    if as_json:
        result(json.dumps({
            "urdf": str(urdf), "name": robot.name, "base_link": chain.chain.base,
            "tip_link": chain.chain.tip, "joints": list(robot.joint_names),
            "links": [{"urdf_link": chain.link_names[i], "joint": robot.joint_names[i],
                       "length": fit.length, "radius": float(robot.link_radii[i]),
                       "method": fit.method, "sources": list(fit.sources),
                       "over_cover": fit.over_cover} for i, fit in enumerate(chain.fits)],
            "tip_offset": robot.tip_offset.tolist(), "tip_radius": robot.tip_radius,
            "tip": chain.tip_note, "reach": robot.reach, "planar": robot.planar,
            "not_modelled": [{"link": link, "joint": joint}
                             for link, joint in chain.chain.not_modelled],
            "ignored_log_joints": ignored,
            "capsules": None if write_capsules is None else str(write_capsules)}, indent=2))
        return
    result("\n".join([*chain.describe(),
                       *(f"  log joint {name!r} ignored: {why}" for name, why in ignored.items())]))
    for warning in caught:
        status(f"note: {warning.message}")
    if write_capsules is not None:
        status(f"wrote {write_capsules}")


def _log_joints(path: Path, joint_topic: str | None) -> tuple[str, ...]:
    """Joint names on the log's JointState topic (the one a run would use)."""
    from wholearm_tools.logs.bags import scan_log
    from wholearm_tools.logs.decoders import JointStateColumns
    from wholearm_tools.logs.reader import _select_joint_topic
    from wholearm_tools.logs.scan import check_log_path
    from wholearm_tools.logs.schemas import JOINT_STATE

    check_log_path(path)
    scan = scan_log(path, lambda topic, schema: schema == JOINT_STATE
                    and (joint_topic is None or topic == joint_topic))
    topic = _select_joint_topic(scan, joint_topic, None)
    state = scan.decoded[topic]
    assert isinstance(state, JointStateColumns)
    return tuple(state.names)
