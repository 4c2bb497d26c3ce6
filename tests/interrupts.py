"""Ctrl-C and kill -9 against a real ``wholearm reconstruct``: what the user sees, what is left.

Not collected by pytest (a reconstruction takes tens of seconds; the fast cases are in
``test_bad_input_cli.py``).  Run ``python tests/interrupts.py [RUN.mcap]``: it simulates 20 s
of lab_circle (seed 1) unless a run is given, then interrupts ``wholearm reconstruct RUN -o OUT`` at
fixed times and at events (pool workers started = the seed fits are running; the output
folder or map.json appeared), and prints one markdown row per try: the signal, when, the exit
status, the lines on stderr, the files left in OUT, and processes of the group still alive a
second later.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import psutil

WHOLEARM = Path(sys.executable).with_name("wholearm")


def _as_from_a_terminal() -> None:
    """In the child: SIGINT as a command started from a terminal has it (a script started in
    the background ignores it, and children inherit that)."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)
    signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})


def _group_alive(pgid: int) -> list[int]:
    alive = []
    for proc in psutil.process_iter(["pid"]):
        try:
            if os.getpgid(proc.pid) == pgid and proc.status() != psutil.STATUS_ZOMBIE:
                alive.append(proc.pid)
        except (ProcessLookupError, psutil.Error):
            continue
    return alive


def _workers_started(proc: subprocess.Popen, out: Path) -> bool:
    try:
        return bool(psutil.Process(proc.pid).children())
    except psutil.Error:
        return False


def _staging(proc: subprocess.Popen, out: Path) -> bool:
    """The output set is being written (its staging folder beside the output folder)."""
    return any(out.parent.glob(f".{out.name}.*"))


def _exists(name: str) -> Callable[[subprocess.Popen, Path], bool]:
    def check(proc: subprocess.Popen, out: Path) -> bool:
        return (out / name).exists() if name else out.exists()
    return check


def interrupt(run: Path, out: Path, sig: signal.Signals, *, after: float | None = None,
              when: Callable[[subprocess.Popen, Path], bool] | None = None
              ) -> tuple[str, int | str, str, list[str], int]:
    """Start a reconstruction, send ``sig`` to its process group ``after`` seconds or as soon
    as ``when`` holds; return (when it was sent, exit status, stderr, files left, processes
    of the group alive 1 s later)."""
    env = {**os.environ, "MPLBACKEND": "Agg"}
    start = time.monotonic()
    proc = subprocess.Popen([str(WHOLEARM), "reconstruct", str(run), "-o", str(out)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env,
                            start_new_session=True, preexec_fn=_as_from_a_terminal)
    sent = "never (finished first)"
    while proc.poll() is None:
        now = time.monotonic() - start
        if (after is not None and now >= after) or (when is not None and when(proc, out)):
            os.killpg(proc.pid, sig)
            sent = f"{now:.2f} s"
            break
        time.sleep(0.005)
    _, stderr = proc.communicate(timeout=300)
    time.sleep(1.0)
    left = sorted(str(p.relative_to(out.parent)) for p in [out, *out.rglob("*")]
                  if p.exists()) if out.exists() else []
    left += sorted(p.name + "/ (beside)" for p in out.parent.glob(f".{out.name}.*"))
    alive = len(_group_alive(proc.pid))
    code: int | str = proc.returncode if proc.returncode >= 0 else \
        f"killed by {signal.Signals(-proc.returncode).name}"
    return sent, code, stderr.strip(), left, alive


def main() -> None:
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        if len(sys.argv) > 1:
            run = Path(sys.argv[1])
        else:
            run = folder / "run.mcap"
            subprocess.run([str(WHOLEARM), "-q", "simulate", "lab_circle", "--duration", "20",
                            "--seed", "1", "-o", str(run)], check=True)
        tries = [
            (signal.SIGINT, "0.1 s", {"after": 0.1}),
            (signal.SIGINT, "1 s", {"after": 1.0}),
            (signal.SIGINT, "during the fit (pool workers running)",
             {"when": _workers_started}),
            (signal.SIGKILL, "1 s", {"after": 1.0}),
            (signal.SIGKILL, "during the fit (pool workers running)",
             {"when": _workers_started}),
            (signal.SIGKILL, "while the set is written (staging folder exists)",
             {"when": _staging}),
            (signal.SIGKILL, "as soon as the output folder exists", {"when": _exists("")}),
            (signal.SIGKILL, "as soon as map.json exists", {"when": _exists("map.json")}),
            (None, "not interrupted", {}),
        ]
        print("| signal | when | sent at | exit | stderr | left in the output folder "
              "| processes alive 1 s later |")
        print("|---|---|---|---|---|---|---|")
        for i, (sig, label, kw) in enumerate(tries):
            out = folder / f"out{i}"
            if sig is None:
                sent, code, err, left, alive = interrupt(run, out, signal.SIGINT,
                                                         when=lambda p, o: False)
                name = "-"
            else:
                sent, code, err, left, alive = interrupt(run, out, sig, **kw)
                name = sig.name
            err = " / ".join(ln for ln in err.splitlines() if ln.strip())
            if len(err) > 90:
                err = err[:87] + "..."
            shown = ", ".join(p.removeprefix(out.name + "/") for p in left
                              if p != out.name) or ("(empty folder)" if left else "(none)")
            shown = shown.replace(out.name, "OUT")
            print(f"| {name} | {label} | {sent} | {code} | {err or '(nothing)'} | {shown} "
                  f"| {alive} |")


if __name__ == "__main__":
    main()
