"""Options shared by several commands, defined once."""

from __future__ import annotations

import functools
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import click

overwrite_option = click.option(
    "--overwrite", is_flag=True, help="Replace existing outputs (refused otherwise).")
json_option = click.option(
    "--json", "as_json", is_flag=True, help="Machine-readable JSON on stdout.")
fit_workers_option = click.option(
    "--workers", type=click.IntRange(min=1), default=None,
    help="Processes for the seed fits (default: one per core, at most 8; the map is the same "
         "for any number).")
seed_option = click.option("--seed", type=int, default=0, show_default=True,
                           help="Random seed (same seed, byte-identical output).")


def check_output_file(path: Path, overwrite: bool) -> None:
    """Refuse to replace an existing output unless ``--overwrite`` was given."""
    if path.exists() and not overwrite:
        raise click.ClickException(f"{path}: already exists (use --overwrite to replace it)")


def progress_enabled() -> bool:
    """Progress bars only on an interactive stderr."""
    import sys

    return sys.stderr.isatty()


def B_option(default: float | None = 0.02):  # noqa: N802 - B is the paper's name
    """``--B``: smallest expected surface curvature radius [m]; required when ``default`` is
    None (click treats an explicit ``default=None`` as a value, so it is not passed)."""
    given = {"default": default, "show_default": True} if default is not None else {}
    return click.option(
        "--B", "B", type=click.FloatRange(min=0.0, min_open=True), required=default is None,
        help="Smallest expected surface curvature radius B [m].", **given)


robot_option = click.option(
    "--robot", "robot_file", type=click.Path(dir_okay=False, exists=True, path_type=Path),
    default=None, help="URDF file (default: the log's /robot_description).")
joint_topic_option = click.option(
    "--joint-topic", default=None, help="JointState topic (default: /joint_states).")
command_topic_option = click.option(
    "--command-topic", default=None,
    help="Commanded torques topic (JointState effort or Float64MultiArray).")


def prepare_output_dir(path: Path, names: list[str], overwrite: bool) -> None:
    """Refuse when any of ``names`` already exists in ``path`` unless overwriting, or when
    ``path`` is not a folder.  The folder itself is created by the writer, after the work
    succeeded, so a failed command leaves nothing behind."""
    if path.exists() and not path.is_dir():
        raise click.ClickException(f"{path}: exists and is not a folder")
    existing = [n for n in names if (path / n).exists()]
    if existing and not overwrite:
        raise click.ClickException(
            f"{path}: already holds {', '.join(existing)} (use --overwrite to replace)")


causal_option = click.option(
    "--causal", is_flag=True,
    help="Classify with the swept map as the robot saw it at each contact (default: whole run).")
loss_option = click.option(
    "--loss", type=click.Choice(["linear", "huber", "cauchy"]), default="huber",
    show_default=True, help="Fit loss (robust losses resist misclassified contacts).")


# ---------------------------------------------------------------------------- the rig
@dataclass(frozen=True)
class RigOptions:
    """What ``rig_options`` collected: the robot description, how to cut its chain, and where
    the torque evidence comes from; ``read_kwargs()`` are the matching ``read_run`` keywords."""

    robot: Path | None = None
    base_link: str | None = None
    tip_link: str | None = None
    package_paths: tuple[Path, ...] = ()
    effort: str = "commanded"
    stiffness: tuple[float, ...] | None = None

    def read_kwargs(self) -> dict[str, Any]:
        stiffness = (self.stiffness[0] if self.stiffness and len(self.stiffness) == 1
                     else self.stiffness)
        return {"robot": None if self.robot is None else str(self.robot),
                "base_link": self.base_link, "tip_link": self.tip_link,
                "package_paths": tuple(str(p) for p in self.package_paths),
                "effort": self.effort, "stiffness": stiffness}


def _stiffness(ctx: click.Context, param: click.Parameter, value: str | None
               ) -> tuple[float, ...] | None:
    if value is None:
        return None
    try:
        values = tuple(float(v) for v in value.split(","))
    except ValueError:
        raise click.BadParameter(f"expected a number or comma-separated numbers, got "
                                 f"{value!r}") from None
    if not all(v > 0 and v != float("inf") for v in values):
        raise click.BadParameter(f"expected positive stiffness values, got {value!r}")
    return values


def rig_options(f: Callable[..., Any]) -> Callable[..., Any]:
    """``--robot``, ``--base-link``, ``--tip-link``, ``--package-path``, ``--effort`` and
    ``--stiffness``, handed to the command as one keyword ``rig`` (:class:`RigOptions`)."""
    from wholearm_tools.logs.records import TORQUE_SOURCES

    @functools.wraps(f)
    def command(*args: Any, robot_file: Path | None, base_link: str | None,
                tip_link: str | None, package_paths: tuple[Path, ...], effort: str,
                stiffness: tuple[float, ...] | None, **kwargs: Any) -> Any:
        rig = RigOptions(robot_file, base_link, tip_link, tuple(package_paths), effort,
                         stiffness)
        return f(*args, rig=rig, **kwargs)

    options = [
        robot_option,
        click.option("--base-link", default=None, metavar="LINK",
                     help="URDF link the chain starts at (default: the URDF's root)."),
        click.option("--tip-link", default=None, metavar="LINK",
                     help="URDF link the chain ends at (needed when the URDF branches and "
                          "the log's joints do not decide, e.g. gripper frame vs jaw)."),
        click.option("--package-path", "package_paths", multiple=True,
                     type=click.Path(file_okay=False, exists=True, path_type=Path),
                     help="Folder resolving package:// meshes of the URDF (repeatable; "
                          "$ROS_PACKAGE_PATH is searched too)."),
        click.option("--effort", type=click.Choice(TORQUE_SOURCES), default="commanded",
                     show_default=True,
                     help="Torque evidence: commanded torque on the command topic, measured "
                          "effort on the state topic, or commanded position x --stiffness."),
        click.option("--stiffness", default=None, metavar="K[,K...]", callback=_stiffness,
                     help="Controller stiffness [N m/rad] for --effort position (one value, "
                          "or one per joint; default: the log's metadata)."),
    ]
    for option in reversed(options):
        command = option(command)
    return command
