"""The ``wholearm`` console script: runs the click group and owns how the process ends.

Only the standard library is imported at module level, so a Ctrl-C pressed while the group and
its libraries are still being imported is handled like any other: one line, exit status 130,
and no output put in place (:mod:`wholearm_tools._interrupt`).
Exit statuses: 0 success, 1 an error in the input or the work (one ``Error:`` line), 2 a usage
error (bad option, missing input file), 130 interrupted, 141 stdout closed early (``| head``),
which ends the command quietly.
"""

from __future__ import annotations

import contextlib
import os
import sys

#: exit status after Ctrl-C (128 + SIGINT, as shells report it)
EXIT_INTERRUPTED = 130
#: exit status when the reader of stdout went away (128 + SIGPIPE)
EXIT_BROKEN_PIPE = 141


def _silence_stdout() -> None:
    """Point stdout at /dev/null, so the interpreter's final flush of a closed pipe is quiet."""
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        os.close(devnull)
    except (OSError, ValueError, AttributeError):
        pass


def _interrupted() -> int:
    with contextlib.suppress(OSError):
        sys.stderr.write("\nInterrupted.\n")
    return EXIT_INTERRUPTED


def run(args: list[str] | None = None) -> int:
    """Run ``wholearm`` with ``args`` (default: the command line); return the exit status.

    A Ctrl-C ends the command as interrupted even where a library swallowed the
    KeyboardInterrupt or turned it into another error (:mod:`wholearm_tools._interrupt`)."""
    pressed = None
    try:
        from wholearm_tools import _interrupt

        _interrupt.install()
        pressed = _interrupt.pressed
        status = _run(args)
    except BaseException as exc:
        if isinstance(exc, KeyboardInterrupt) or (pressed is not None and pressed()):
            return _interrupted()
        raise
    finally:
        if pressed is not None:
            _interrupt.release()
    return _interrupted() if pressed() and status != EXIT_INTERRUPTED else status


def _run(args: list[str] | None) -> int:
    try:
        import click

        from cli.main import StdoutClosed, cli

        try:
            rv = cli.main(args, prog_name="wholearm", standalone_mode=False)
            sys.stdout.flush()
        except click.exceptions.Abort:  # click's form of KeyboardInterrupt and EOF
            click.echo("Interrupted.", err=True)
            return EXIT_INTERRUPTED
        except click.ClickException as exc:
            exc.show()
            return exc.exit_code
        except StdoutClosed:
            _silence_stdout()
            return EXIT_BROKEN_PIPE
        return rv if isinstance(rv, int) else 0
    except BrokenPipeError:
        _silence_stdout()
        return EXIT_BROKEN_PIPE


def main() -> None:
    """Console-script entry point."""
    sys.exit(run())
