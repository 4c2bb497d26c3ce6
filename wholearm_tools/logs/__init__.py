"""Joint logs: MCAP read/write in the ROS 2 and JSON profiles, with a vectorised JointState path.

``write_run`` / ``read_run`` / ``read_joint_log`` / ``inspect_log`` are the public entry points;
the records (``JointLog``, ``GroundTruth``, ``Run``) are shared by every stage.
"""

from wholearm_tools.logs.records import CONTACT_KINDS, TORQUE_SOURCES, GroundTruth, JointLog, Run

__all__ = ["CONTACT_KINDS", "TORQUE_SOURCES", "GroundTruth", "JointLog", "LogWarning", "Run",
           "inspect_log", "read_joint_log", "read_run", "write_run"]


def __getattr__(name: str):  # lazy: keep `import wholearm_tools.logs` free of mcap
    if name == "write_run":
        from wholearm_tools.logs.writer import write_run

        return write_run
    if name in ("read_run", "read_joint_log", "LogWarning"):
        from wholearm_tools.logs import reader

        return getattr(reader, name)
    if name == "inspect_log":
        from wholearm_tools.logs.inspect import inspect_log

        return inspect_log
    raise AttributeError(f"module 'wholearm_tools.logs' has no attribute {name!r}")
