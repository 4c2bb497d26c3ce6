"""Options shared by several commands, defined once, and the conventions every command follows.

* **Inputs**: a missing, unreadable or non-regular input file (a folder, a device node, a FIFO)
  is a *usage* error, exit status 2, from the argument's type (:class:`InputFile`); an input
  that exists but cannot be used (not a log, malformed map) is a user error, exit status 1.
* **Outputs**: ``-o/--output`` is a file for commands that write one file and a folder for
  commands that write a set of files; an existing output is replaced only with
  ``--overwrite`` (checked before the work and again at the rename); outputs are regular files.
* **Printing**: results (what the user asked to see) go to stdout; status (progress, what was
  written, summaries) goes to stderr and ``-q`` silences it; ``--json`` prints the result as
  JSON with typed numbers on stdout and nothing else there.
"""

from __future__ import annotations

import functools
import os
import stat
import sys
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import click

#: B used by every command when --B is not given [m]
DEFAULT_B = 0.02


class InputFile(click.Path):
    """An existing, readable regular file (symlinks followed), optionally at most
    ``max_bytes`` long; anything else is a usage error naming the path."""

    name = "file"

    def __init__(self, max_bytes: int | None = None, **kwargs: Any) -> None:
        kwargs.setdefault("path_type", Path)
        super().__init__(exists=True, dir_okay=False, readable=True, **kwargs)
        self.max_bytes = max_bytes

    def convert(self, value: Any, param: click.Parameter | None,
                ctx: click.Context | None) -> Any:
        path = super().convert(value, param, ctx)
        try:
            info = os.stat(path)
        except OSError as exc:
            self.fail(f"{os.fsdecode(path)!r}: {exc.strerror}", param, ctx)
        if not stat.S_ISREG(info.st_mode):
            self.fail(f"{os.fsdecode(path)!r} is not a regular file (a device, FIFO or "
                      "socket).", param, ctx)
        if self.max_bytes is not None and info.st_size > self.max_bytes:
            self.fail(f"{os.fsdecode(path)!r} is {info.st_size / 2**20:.0f} MiB, more than "
                      f"the {self.max_bytes / 2**20:.0f} MiB this input may have.", param, ctx)
        return path


class InputPath(click.Path):
    """An existing file or folder; a file must be a regular file (see :class:`InputFile`)."""

    def __init__(self, **kwargs: Any) -> None:
        kwargs.setdefault("path_type", Path)
        super().__init__(exists=True, **kwargs)

    def convert(self, value: Any, param: click.Parameter | None,
                ctx: click.Context | None) -> Any:
        path = super().convert(value, param, ctx)
        mode = os.stat(path).st_mode
        if not (stat.S_ISREG(mode) or stat.S_ISDIR(mode)):
            self.fail(f"{os.fsdecode(path)!r} is not a regular file or a folder.", param, ctx)
        return path


class PositiveLength(click.FloatRange):
    """A finite length > 0 in metres (``nan`` and ``inf`` are usage errors too)."""

    name = "length"

    def __init__(self) -> None:
        super().__init__(min=0.0, min_open=True)

    def convert(self, value: Any, param: click.Parameter | None,
                ctx: click.Context | None) -> Any:
        import math

        number = super().convert(value, param, ctx)
        if not math.isfinite(number):
            self.fail(f"{value!r} is not a finite length.", param, ctx)
        return number


#: largest URDF accepted by --robot
MAX_URDF_BYTES = 64 * 2**20


# ------------------------------------------------------------------------ printing


def _root_params() -> dict[str, Any]:
    ctx = click.get_current_context(silent=True)
    return dict(ctx.find_root().params) if ctx is not None else {}


def is_quiet() -> bool:
    """``-q`` was given to the ``wholearm`` group."""
    return bool(_root_params().get("quiet"))


def verbosity() -> int:
    """How many ``-v`` were given to the ``wholearm`` group."""
    return int(_root_params().get("verbose") or 0)


def status(message: str) -> None:
    """A status line on stderr (silenced by ``-q``)."""
    if not is_quiet():
        click.echo(message, err=True)


def result(text: str) -> None:
    """A result on stdout (never silenced: the user asked for it)."""
    click.echo(text)


def progress_enabled() -> bool:
    """Progress bars only on an interactive stderr, and not with ``-q``."""
    return sys.stderr.isatty() and not is_quiet()


@contextmanager
def stage(label: str) -> Iterator[Callable[[str], None]]:
    """A step of a command that may take a while.

    On a terminal (and without ``-q``) the line ``label … 12 s`` is redrawn every second and
    ends with the step's time; elsewhere, with ``-v``, the start and end are logged on stderr;
    otherwise nothing is printed.  The block receives a function that names the part of the
    step now running (``label: part … 12 s``; logged with ``-v``).
    """
    import logging

    log = logging.getLogger("wholearm")
    start = time.perf_counter()
    live = progress_enabled()
    if not live:
        log.info("%s ...", label)
    stop = threading.Event()
    part = [""]

    def now() -> str:
        return f"{label}: {part[0]}" if part[0] else label

    def redraw() -> None:
        while not stop.wait(1.0):
            click.echo(f"\r\x1b[K{now()} … {time.perf_counter() - start:.0f} s", err=True,
                       nl=False)

    def step(text: str) -> None:
        part[0] = text
        if not live:
            log.info("%s: %s", label, text)

    thread = threading.Thread(target=redraw, daemon=True) if live else None
    if thread is not None:
        click.echo(f"{label} …", err=True, nl=False)
        thread.start()
    ok = False
    try:
        yield step
        ok = True
    finally:
        stop.set()
        if thread is not None:
            thread.join()
            mark = "done" if ok else "stopped"
            click.echo(f"\r\x1b[K{label}: {mark} in {time.perf_counter() - start:.1f} s",
                       err=True)
        if ok and not live:
            log.info("%s: done in %.1f s", label, time.perf_counter() - start)


# ------------------------------------------------------------------------ options

json_option = click.option(
    "--json", "as_json", is_flag=True,
    help="Print the result as JSON (typed numbers) on stdout, nothing else there.")
fit_workers_option = click.option(
    "--workers", type=click.IntRange(min=1), default=None,
    help="Processes for the seed fits (default: one per core, at most 8; the map is the same "
         "for any number).")
seed_option = click.option("--seed", type=int, default=0, show_default=True,
                           help="Random seed (same seed, byte-identical output).")


def overwrite_option(command: Callable[..., Any]) -> Callable[..., Any]:
    """``--overwrite``: replace existing outputs (refused otherwise).  The command runs inside
    :func:`wholearm_tools._io.output_policy`, so the check is made again when each output is
    renamed into place, not only before the work."""

    @functools.wraps(command)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        from wholearm_tools._io import output_policy

        with output_policy(overwrite=bool(kwargs.get("overwrite"))):
            return command(*args, **kwargs)

    return click.option("--overwrite", is_flag=True,
                        help="Replace existing outputs (refused otherwise).")(wrapper)


def check_output_file(path: Path, overwrite: bool) -> None:
    """Refuse an output that is not a regular file, and an existing one unless
    ``--overwrite`` was given; the output's folder must exist."""
    from wholearm_tools._io import check_output_target
    from wholearm_tools.errors import OutputError

    try:
        check_output_target(path)
    except OutputError as exc:
        raise click.ClickException(str(exc)) from None
    if path.exists() and not overwrite:
        raise click.ClickException(f"{path}: already exists (use --overwrite to replace it)")
    folder = path.parent if str(path.parent) else Path(".")
    if not folder.is_dir():
        raise click.ClickException(f"{path}: output folder {folder} does not exist")


def B_option(default: float = DEFAULT_B, text: str | None = None):  # noqa: N802 - paper's B
    """``--B``: smallest expected surface curvature radius [m], default :data:`DEFAULT_B`."""
    return click.option(
        "--B", "B", type=PositiveLength(), default=default,
        show_default=True,
        help=text or "Smallest expected surface curvature radius B [m], between the encoder "
                     "level and the robot's reach.")


robot_option = click.option(
    "--robot", "robot_file", type=InputFile(max_bytes=MAX_URDF_BYTES), default=None,
    help="URDF file (default: the log's /robot_description).")
joint_topic_option = click.option(
    "--joint-topic", default=None, help="JointState topic (default: /joint_states).")
command_topic_option = click.option(
    "--command-topic", default=None,
    help="Commanded torques topic (JointState effort or Float64MultiArray).")


def prepare_output_dir(path: Path, names: list[str], overwrite: bool) -> None:
    """Refuse when any of ``names`` already exists in ``path`` unless overwriting (or exists
    and is not a regular file), or when ``path`` is not a folder.  The folder itself is
    created by the writer, after the work succeeded, so a failed command leaves nothing
    behind."""
    from wholearm_tools._io import check_output_target
    from wholearm_tools.errors import OutputError

    if path.exists() and not path.is_dir():
        raise click.ClickException(f"{path}: exists and is not a folder")
    for name in names:
        try:
            check_output_target(path / name)
        except OutputError as exc:
            raise click.ClickException(str(exc)) from None
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
    compliance: tuple[float, ...] | str | None = None
    backlash: tuple[float, ...] | str | None = None

    @property
    def learn_compliance(self) -> bool:
        """``--joint-compliance auto``: learned from the map (``reconstruct``'s option)."""
        return self.compliance == "auto"

    @property
    def learn_backlash(self) -> bool:
        """``--joint-backlash auto``: learned from the map (``reconstruct``'s option)."""
        return self.backlash == "auto"

    def learning(self) -> dict[str, bool]:
        """``reconstruct``'s keywords for what ``auto`` asks to learn."""
        return {k: True for k, on in (("learn_compliance", self.learn_compliance),
                                      ("learn_backlash", self.learn_backlash)) if on}

    def read_kwargs(self, *, maps: bool = False) -> dict[str, Any]:
        """The ``read_run`` keywords; ``maps``: the command fits a map (it can learn the
        drives; other commands refuse ``--joint-compliance auto``, ``--joint-backlash
        auto``)."""
        def one_or_each(values: Any) -> Any:
            return values[0] if values and len(values) == 1 else values

        for option, what, learn in (("compliance", "compliance", self.learn_compliance),
                                    ("backlash", "play", self.learn_backlash)):
            if learn and not maps:
                raise click.UsageError(f"--joint-{option} auto learns the drives' {what} from "
                                       "a fitted map: reconstruct, report and compare take it")
        return {"robot": None if self.robot is None else str(self.robot),
                "base_link": self.base_link, "tip_link": self.tip_link,
                "package_paths": tuple(str(p) for p in self.package_paths),
                "effort": self.effort, "stiffness": one_or_each(self.stiffness),
                "joint_compliance": (None if self.learn_compliance
                                     else one_or_each(self.compliance)),
                "joint_backlash": (None if self.learn_backlash
                                   else one_or_each(self.backlash))}


def _per_joint(what: str, zero_ok: bool, auto: bool = False
               ) -> Callable[..., tuple[float, ...] | str | None]:
    """Click callback: one number, or one per joint separated by commas (or ``auto``)."""
    def parse(ctx: click.Context, param: click.Parameter, value: str | None
              ) -> tuple[float, ...] | str | None:
        if value is None:
            return None
        if auto and value.strip().lower() == "auto":
            return "auto"
        try:
            values = tuple(float(v) for v in value.split(","))
        except ValueError:
            raise click.BadParameter(f"expected a number or comma-separated numbers, got "
                                     f"{value!r}") from None
        if not all((v >= 0 if zero_ok else v > 0) and v != float("inf") for v in values):
            raise click.BadParameter(f"expected {what} values, got {value!r}")
        return values
    return parse


def rig_options(f: Callable[..., Any]) -> Callable[..., Any]:
    """``--robot``, ``--base-link``, ``--tip-link``, ``--package-path``, ``--effort``,
    ``--stiffness``, ``--joint-compliance`` and ``--joint-backlash``, handed to the command as
    one keyword ``rig`` (:class:`RigOptions`)."""
    from wholearm_tools.logs.records import TORQUE_SOURCES

    @functools.wraps(f)
    def command(*args: Any, robot_file: Path | None, base_link: str | None,
                tip_link: str | None, package_paths: tuple[Path, ...], effort: str,
                stiffness: tuple[float, ...] | None,
                compliance: tuple[float, ...] | str | None,
                backlash: tuple[float, ...] | str | None, **kwargs: Any) -> Any:
        rig = RigOptions(robot_file, base_link, tip_link, tuple(package_paths), effort,
                         stiffness, compliance, backlash)
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
        click.option("--stiffness", default=None, metavar="K[,K...]",
                     callback=_per_joint("positive stiffness", zero_ok=False),
                     help="Controller stiffness [N m/rad] for --effort position (one value, "
                          "or one per joint; default: the log's metadata)."),
        click.option("--joint-compliance", "compliance", default=None,
                     metavar="C[,C...]|auto",
                     callback=_per_joint("non-negative compliance", zero_ok=True, auto=True),
                     help="Transmission deflection at the effort limit [rad] for encoders on "
                          "the motor side (effort / torsional stiffness; one value, or one per "
                          "joint): contacts are placed at the links' angles. 'auto' learns it "
                          "from a first map (reconstruct, report, compare). Default: stiff."),
        click.option("--joint-backlash", "backlash", default=None, metavar="B[,B...]|auto",
                     callback=_per_joint("non-negative backlash", zero_ok=True, auto=True),
                     help="Lost motion of each transmission [rad] for encoders on the motor "
                          "side (one value, or one per joint): contacts are placed at the "
                          "links' angles, the play closed on the side each drive pushes. "
                          "'auto' learns it from a first map (reconstruct, report, "
                          "compare). Default: none."),
    ]
    for option in reversed(options):
        command = option(command)
    return command
