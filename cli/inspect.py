"""``wholearm inspect RUN``: what a log contains (topics, joints, rates, torque sources, run
readiness).  RUN is an MCAP file, a rosbag2 folder, a ``.db3`` or a ROS 1 ``.bag``."""

from __future__ import annotations

import json
from pathlib import Path

import click
import numpy as np

from cli.options import InputPath, json_option, result, stage


def _yes(value: object) -> str:
    return "yes" if value else "no"


@click.command("inspect")
@click.argument("run", type=InputPath())
@json_option
@click.option("--joint-topic", default=None, metavar="TOPIC",
              help="JointState topic to describe (default /joint_states or the only one).")
def command(run: Path, as_json: bool, joint_topic: str | None) -> None:
    """Describe the log RUN: topics, joints, duration, rates, URDF, torque sources, truth."""
    from wholearm_tools.logs.inspect import inspect_log

    with stage(f"reading {run}"):
        info = inspect_log(run, joint_topic=joint_topic)
    info["torque_sources"] = _torque_sources(info)
    with stage("detecting contacts"):
        info["contacts_found"] = _contacts_found(run, info, joint_topic)
    if as_json:
        result(json.dumps(info, indent=2, sort_keys=True))
        return
    container = (f"{info['mcap_profile']}, read with {info['library']}"
                 if info["mcap_profile"].startswith(("rosbag2", "ros1 bag")) else
                 f"MCAP profile {info['mcap_profile']!r}, written by {info['library'] or '?'}")
    out = [f"file:      {info['file']}",
           f"profile:   {info['profile'] or '?'} ({container})",
           f"duration:  {info['duration_s']:.3f} s, {info['messages']} messages"
           + ("  [TRUNCATED: read up to the cut]" if info["truncated"] else ""),
           "topics:"]
    width = max((len(t["topic"]) for t in info["topics"]), default=0)
    for t in info["topics"]:
        rate = f"{t['rate_hz']:>8.2f} Hz" if t["messages"] > 1 else f"{'-':>8}   "
        out.append(f"  {t['topic']:<{width}}  {t['messages']:>8} msgs  {rate}"
                   f"  {t['schema'] or '-'} ({t['message_encoding']})")
    for topic, jt in info["joint_topics"].items():
        fields = ", ".join(f for f in ("velocity", "effort") if jt[f]) or "positions only"
        mark = "*" if topic == info["joint_topic"] else " "
        out.append(f"{mark} joints on {topic}: {', '.join(jt['joints'])} ({fields})")
    if info["joint_topic"] is None and len(info["joint_topics"]) > 1:
        out.append("  several JointState topics: choose one with --joint-topic")
    robot = info["robot"]
    urdf = _yes(info["urdf"])
    if robot and "error" in robot:
        urdf += f" (unusable: {robot['error']})"
    elif robot:
        urdf += f" (robot {robot['name']!r}, {len(robot['joints'])} joints)"
    out.append(f"URDF:      {urdf}")
    cmd = info["commands"]
    out.append("commands:  " + (f"{cmd['topic']} ({cmd['schema']}; torques "
                                f"{_yes(cmd['torques'])}, positions {_yes(cmd['positions'])})"
                                if cmd else "no"))
    out.append("torque:    " + _torque_line(info["torque_sources"]))
    gt = info["ground_truth"]
    slid = (f", {gt['stopped']} stopped the arm"
            if gt and gt["stopped"] < gt["contacts"] else "")
    out.append("truth:     " + (f"{gt['contacts']} contacts ({gt['tip']} tip, {gt['body']} body"
                                f"{slid}), {gt['surfaces']} surfaces" if gt else "no"))
    found = info["contacts_found"]
    if found is not None:
        if "error" in found:
            out.append(f"contacts:  not detected ({found['error']})")
        else:
            links = ", ".join(f"link {k}: {v}" for k, v in found["per_link"].items()) or "none"
            line = f"contacts:  {found['count']} detected ({links})"
            if found.get("matched") is not None:
                line += (f"; {found['matched']} match a true contact, "
                         f"{found['link_right']} on the true link")
            out.append(line)
    if info["metadata"]:
        out.append(f"metadata:  {', '.join(info['metadata'])}")
    if info["attachments"]:
        out.append(f"attachments: {', '.join(info['attachments'])}")
    result("\n".join(out))


def _torque_sources(info: dict) -> dict:
    """Which torque evidence the log offers (``--effort``): commanded torques, measured effort
    on the JointState topics, commanded positions on the command topic."""
    cmd = info.get("commands") or {}
    return {"commanded": bool(cmd.get("torques")),
            "measured": [t for t, jt in info["joint_topics"].items()
                         if jt["effort"] and t != cmd.get("topic")],
            "position": bool(cmd.get("positions"))}


def _torque_line(sources: dict) -> str:
    measured = sources["measured"]
    parts = ["commanded " + ("yes (default)" if sources["commanded"] else "no"),
             "measured " + (f"on {len(measured)} JointState topic{'s' * (len(measured) > 1)} "
                            "(--effort measured)" if measured else "no"),
             "position " + ("yes (--effort position --stiffness K)" if sources["position"]
                            else "only with a command topic carrying positions "
                                 "(--command-topic T --effort position --stiffness K)")]
    return "; ".join(parts)


def _contacts_found(run: Path, info: dict, joint_topic: str | None) -> dict | None:
    """Contacts detected in the log (needs commanded torques; the URDF, when usable, for the
    rigid-group choice); ``None`` when the log has no torques to detect them from."""
    from wholearm_tools.contacts import detect_contacts, match_events
    from wholearm_tools.errors import WholearmError
    from wholearm_tools.logs import read_joint_log, read_run

    cmd = info.get("commands")
    if not cmd or not cmd.get("torques") or info.get("joint_topic") is None:
        return None
    robot_ok = bool(info.get("robot")) and "error" not in info["robot"]
    try:
        if robot_ok:
            r = read_run(run, joint_topic=joint_topic, require_commands=True)
            log, robot, truth = r.log, r.robot, r.truth
        else:
            log = read_joint_log(run, joint_topic=joint_topic, require_commands=True)
            robot, truth = None, None
        c = detect_contacts(log, robot)
    except WholearmError as exc:
        return {"error": str(exc)}
    links, counts = np.unique(np.asarray(c.link), return_counts=True)
    out: dict = {"count": len(c), "per_link": {int(k): int(v) for k, v in zip(links, counts,
                                                                            strict=True)},
                 "matched": None, "link_right": None}
    if truth is not None:
        m = match_events(c, truth)
        ok = m >= 0
        out["matched"] = int(ok.sum())
        out["link_right"] = int(np.sum(np.asarray(c.link)[ok]
                                       == np.asarray(truth.contact_link)[m[ok]]))
    return out
