"""The ``wholearm`` click group.  Each command lives in its own module under ``cli/``."""

from __future__ import annotations

import importlib
import logging
import sys
import warnings

import click

from wholearm_tools import __version__

#: command modules, each exposing a click command named ``command``
COMMANDS = (
    "cli.demo",
    "cli.scenarios",
    "cli.simulate",
    "cli.inspect",
    "cli.robot",
    "cli.contacts",
    "cli.plot_ptip",
    "cli.reconstruct",
    "cli.fit",
    "cli.export",
    "cli.report",
    "cli.compare",
)


class StdoutClosed(Exception):  # noqa: N818 - a condition, not an error of the command
    """The reader of stdout went away (``| head``); raised past click's own handling so the
    entry point can end quietly with 128 + SIGPIPE."""


class WholearmGroup(click.Group):
    """Click group that turns toolkit errors into one-line messages (never a traceback).

    A closed stdout (``wholearm ... | head``) is not an error of the command: it leaves as
    :class:`StdoutClosed` for the entry point, which ends quietly."""

    def invoke(self, ctx: click.Context):  # type: ignore[override]
        from wholearm_tools.errors import WholearmError

        try:
            return super().invoke(ctx)
        except WholearmError as exc:
            raise click.ClickException(_one_line(str(exc))) from None
        except BrokenPipeError:
            raise StdoutClosed from None
        except MemoryError:
            raise click.ClickException("out of memory (the input is larger than this machine "
                                       "can hold)") from None
        except OSError as exc:  # e.g. unreadable input the command did not translate
            where = f"{exc.filename}: " if exc.filename else ""
            raise click.ClickException(f"{where}{exc.strerror or exc}") from None


def _one_line(text: str) -> str:
    """A message on one line (a library message never spans lines on the terminal)."""
    return " ".join(text.split())


@click.group(cls=WholearmGroup, context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, prog_name="wholearm")
@click.option("-v", "--verbose", count=True, help="More log output on stderr (repeatable).")
@click.option("-q", "--quiet", is_flag=True,
              help="No status or progress on stderr: results, --json and errors only.")
def cli(verbose: int, quiet: bool) -> None:
    """Whole-arm tactile exploration: simulate, inspect and reconstruct logged runs."""
    level = logging.ERROR if quiet else (logging.DEBUG if verbose > 1 else
                                         logging.INFO if verbose else logging.WARNING)
    logging.basicConfig(level=level, format="%(levelname)s: %(message)s", stream=sys.stderr,
                        force=True)
    warnings.showwarning = _log_warning


def _log_warning(message: Warning | str, category: type[Warning], filename: str, lineno: int,
                 file: object = None, line: str | None = None) -> None:
    """Warnings go to the log as one line, their message alone: the library's warnings name
    the file and the problem, and the source line that raised one means nothing to a user."""
    logging.getLogger("py.warnings").warning("%s", message)


for _name in COMMANDS:
    cli.add_command(importlib.import_module(_name).command)


def main() -> None:
    """Console-script entry point (see :mod:`cli._entry` for exit statuses)."""
    from cli._entry import main as entry

    entry()


if __name__ == "__main__":
    main()
