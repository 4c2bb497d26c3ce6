"""Bad inputs and faults against the command line: one ``Error:`` line naming the file (and
the field), the documented exit status, no traceback, no hang, nothing half-written.

Every input is built in ``tmp_path`` from one short simulated run.  :data:`CASES` run in this
process through click's runner; the signal, pipe and file-size cases run ``wholearm`` as a
real process.  ``python tests/test_bad_input_cli.py`` prints the table of every case (class,
case, exit status, the line the user sees, OK) from the same definitions.
"""

from __future__ import annotations

import json
import os
import re
import signal
import stat
import subprocess
import sys
import textwrap
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from cli.main import cli

WHOLEARM = Path(sys.executable).with_name("wholearm")


# ------------------------------------------------------------------------------ inputs


@dataclass(frozen=True)
class Base:
    """A short simulated run and what is derived from it."""

    run: Path
    urdf: str

    def read(self):
        from wholearm_tools.logs import read_run

        return read_run(self.run)


def make_base(folder: Path) -> Base:
    """Simulate 6 s of lab_circle into ``folder/run.mcap``."""
    from wholearm_tools.logs import write_run
    from wholearm_tools.robot import robot_to_urdf
    from wholearm_tools.sim.scenarios import load_scenario

    sc = load_scenario("lab_circle")
    path = folder / "run.mcap"
    write_run(path, sc.simulate(duration=6.0, seed=3).run)
    return Base(run=path, urdf=robot_to_urdf(sc.robot))


def _log_variant(base: Base, folder: Path, name: str, edit: Callable[[dict], None]) -> Path:
    """The base run with its joint log's arrays edited by ``edit`` (a dict of copies)."""
    from wholearm_tools.logs import JointLog, Run, write_run

    run = base.read()
    log = run.log
    cols = {k: None if getattr(log, k) is None else np.array(getattr(log, k))
            for k in ("t", "q", "qd", "tau_cmd", "q_cmd")}
    edit(cols)
    new = JointLog(log.joint_names, cols["t"], cols["q"], cols["qd"], cols["tau_cmd"],
                   cols["q_cmd"], t0_ns=log.t0_ns)
    path = folder / name
    write_run(path, Run(robot=run.robot, log=new))
    return path


def _map(folder: Path, name: str = "map.json", edit: Callable[[dict], None] | None = None,
         planar: bool = True) -> Path:
    """A valid one-circle planar map (or a sphere map), edited by ``edit``."""
    data = {"format": "wholearm-map", "version": 1, "frame": "base_link", "planar": planar,
            "B": 0.02,
            "primitives": [{"id": 0, "type": "circle", "params": {"center": [0.4, 0.2],
                                                                  "radius": 0.06},
                            "support": {"tip": 4, "link": 2}, "rms_residual": 0.0004}]
            if planar else [{"id": 0, "type": "sphere",
                             "params": {"center": [0.4, 0.2, 0.1], "radius": 0.06},
                             "support": {"tip": 4, "link": 2}}],
            "contacts": {"count": 6}, "meta": {"source": "run.mcap"}}
    if edit is not None:
        edit(data)
    path = folder / name
    path.write_text(json.dumps(data))
    return path


def _contacts_csv(folder: Path, name: str = "contacts.csv") -> Path:
    rows = ["t,link,p_tip,label,variance,used_as,tip_x,tip_y,tip_radius,a_x,a_y,b_x,b_y,"
            "link_radius"]
    for i in range(6):
        angle = i * 0.5
        x, y = 0.4 + 0.08 * np.cos(angle), 0.2 + 0.08 * np.sin(angle)
        rows.append(f"{i * 0.5},1,0.9,tip,1e-6,tip,{x},{y},0.02,0,0,{x},{y},0.01")
    path = folder / name
    path.write_text("\n".join(rows) + "\n")
    return path


def _urdf(base: Base, folder: Path, name: str, old: str, new: str) -> Path:
    assert old in base.urdf
    path = folder / name
    path.write_text(base.urdf.replace(old, new, 1))
    return path


def _zstd_bomb(base: Base, folder: Path) -> Path:
    """The base run with its first chunk declaring 256 MiB of records."""
    from mcap.reader import make_reader

    with base.run.open("rb") as handle:
        start = make_reader(handle).get_summary().chunk_indexes[0].chunk_start_offset
    data = bytearray(base.run.read_bytes())
    # chunk record: opcode, length, start time, end time, then the uncompressed size
    data[start + 25:start + 33] = (256 * 2**20).to_bytes(8, "little")
    path = folder / "bomb.mcap"
    path.write_bytes(bytes(data))
    return path


def _deep_map(folder: Path) -> Path:
    path = folder / "deep.json"
    path.write_text('{"format": "wholearm-map", "version": 1, "x": ' + "[" * 100_000
                    + "]" * 100_000 + "}")
    return path


def _source_beside(folder: Path, target: str) -> Path:
    """An output folder whose map.json names ``target`` (in the folder) as its run."""
    out = folder / "out"
    out.mkdir()
    _map(out, edit=lambda d: d["meta"].update(source=target))
    return out


def _secret(folder: Path) -> Path:
    out = _source_beside(folder, "notes.txt")
    (out / "notes.txt").write_text("SECRET-PASSWORD-1234\n")
    return out


def _fifo_source(folder: Path) -> Path:
    out = _source_beside(folder, "pipe.mcap")
    os.mkfifo(out / "pipe.mcap")
    return out


def _laughs(folder: Path) -> Path:
    entities = ['<!ENTITY lol0 "lol">'] + [
        f'<!ENTITY lol{i} "{("&lol" + str(i - 1) + ";") * 10}">' for i in range(1, 10)]
    path = folder / "laughs.urdf"
    path.write_text('<?xml version="1.0"?>\n<!DOCTYPE robot [' + "".join(entities)
                    + ']>\n<robot name="&lol9;"><link name="base_link"/></robot>\n')
    return path


def _nan_origin(base: Base, folder: Path) -> Path:
    return _urdf(base, folder, "nan.urdf",
                 '<child link="link_2" />\n    <origin xyz="0.35 0 0"',
                 '<child link="link_2" />\n    <origin xyz="nan 0 0"')


def _negative_radius(base: Base, folder: Path) -> Path:
    return _urdf(base, folder, "neg.urdf", '<cylinder radius="0.02"',
                 '<cylinder radius="-0.02"')


# ------------------------------------------------------------------------------ cases


@dataclass(frozen=True)
class Case:
    """One bad input: ``args(base, folder)`` builds it and returns the command line;
    ``message`` is a regex the user's line must match (the ``Error:`` line, or with
    ``warning=True`` a ``WARNING:`` line of a run that succeeds)."""

    kind: str
    name: str
    args: Callable[[Base, Path], list[str]]
    code: int
    message: str
    warning: bool = False
    check: Callable[[Path], None] | None = None


def _no_secret(folder: Path) -> None:
    assert (folder / "out" / "notes.txt").read_text().startswith("SECRET")


def _dev_null_kept(folder: Path) -> None:
    assert stat.S_ISCHR(os.stat("/dev/null").st_mode)


def _nothing_written(folder: Path) -> None:
    assert not (folder / "m.json").exists()


CASES = [
    # a traceback before
    Case("traceback", "URDF not UTF-8",
         lambda b, f: ["contacts", str(b.run), "--robot", str(_write(f / "bad.urdf",
                                                                    b"<robot \xff>"))],
         1, r"bad\.urdf: not a text file \(a URDF is UTF-8 XML\)"),
    Case("traceback", "contacts.csv not UTF-8",
         lambda b, f: ["fit", str(_write(f / "bad.csv", b"t,link\n\xfe\xff")), "-o",
                       str(f / "m.json")],
         1, r"bad\.csv: table is not UTF-8 text \(byte 0xfe", check=_nothing_written),
    Case("traceback", "map.json nested 100,000 deep",
         lambda b, f: ["export", str(_deep_map(f))],
         1, r"deep\.json: JSON nested too deeply \(at most 64 levels\)"),
    Case("traceback", "--B 1e-300",
         lambda b, f: ["contacts", str(b.run), "--B", "1e-300"],
         1, r"--B = 1e-300 m is below 4e-06 m, what the joint encoders resolve at the "
            r"robot's reach \(0\.67 m\)"),
    Case("traceback", "--robot /dev/zero",
         lambda b, f: ["contacts", str(b.run), "--robot", "/dev/zero"],
         2, r"'/dev/zero' is not a regular file"),
    Case("traceback", "simulate --rate 1e9",
         lambda b, f: ["simulate", "lab_circle", "--rate", "1e9", "-o", str(f / "x.mcap")],
         2, r"--rate.*1000000000\.0 is not in the range"),
    Case("traceback", "simulate rate x duration",
         lambda b, f: ["simulate", "lab_circle", "--rate", "50000", "--duration", "100", "-o",
                       str(f / "x.mcap")],
         2, r"50000 Hz for 100 s is 5e\+06 samples; at most 2,000,000"),
    # a hang before
    Case("hang", "contacts --B 1e9",
         lambda b, f: ["contacts", str(b.run), "--B", "1e9"],
         1, r"--B = 1e\+09 m is larger than the robot's reach \(0\.67 m\)"),
    Case("hang", "reconstruct --B 10",
         lambda b, f: ["reconstruct", str(b.run), "--B", "10", "-o", str(f / "out")],
         1, r"--B = 10 m is larger than the robot's reach",
         check=lambda f: _absent(f / "out")),
    # messages that named no file
    Case("names no file", "1-sample log",
         lambda b, f: ["contacts", str(_log_variant(b, f, "one.mcap", _first_sample))],
         1, r"one\.mcap: topic '/joint_states' has 1 sample\(s\) at distinct stamps; a run "
            r"needs at least 3"),
    Case("names no file", "NaN origin in a URDF",
         lambda b, f: ["contacts", str(b.run), "--robot", str(_nan_origin(b, f))],
         1, r"^Error: \S*nan\.urdf: "),
    Case("names no file", "negative radius in a URDF",
         lambda b, f: ["contacts", str(b.run), "--robot", str(_negative_radius(b, f))],
         1, r"^Error: \S*neg\.urdf: "),
    Case("names no file", "map: negative radius",
         lambda b, f: ["export", str(_map(f, edit=lambda d: d["primitives"][0]["params"]
                                          .update(radius=-0.06)))],
         1, r"map\.json: primitives\[0\] \(circle\): circle radius must be finite and > 0"),
    Case("names no file", "map: null centre",
         lambda b, f: ["export", str(_map(f, edit=lambda d: d["primitives"][0]["params"]
                                          .update(center=[None, 0.2])))],
         1, r"map\.json: primitives\[0\] \(circle\): 'params' holds a non-finite number"),
    Case("names no file", "map: unknown type",
         lambda b, f: ["export", str(_map(f, edit=lambda d: d["primitives"][0]
                                          .update(type="blob")))],
         1, r"map\.json: primitives\[0\] \(blob\): unknown primitive type 'blob'"),
    Case("names no file", "map: 3-D type in a planar map",
         lambda b, f: ["export", str(_map(f, edit=lambda d: d["primitives"][0]
                                          .update(type="sphere")))],
         1, r"map\.json: primitives\[0\] \(sphere\): a 3-D type in a 2-D map"),
    Case("names no file", "map: no params",
         lambda b, f: ["export", str(_map(f, edit=lambda d: d["primitives"][0]
                                          .pop("params")))],
         1, r"map\.json: primitives\[0\] \(circle\): no 'params' object"),
    Case("names no file", "map: extent of 1e300 m",
         lambda b, f: ["export", str(_map(f, edit=lambda d: d["primitives"][0].update(
             extent={"angle": {"reference": [1e300, 0], "start": 0, "sweep": 1,
                               "full": False}})))],
         1, r"map\.json: primitives\[0\] \(circle\): 'extent' holds 1e\+300, beyond 1000 m"),
    Case("names no file", "map: bad B",
         lambda b, f: ["export", str(_map(f, edit=lambda d: d.update(B=-1)))],
         1, r"map\.json: field 'B' must be a positive length in metres"),
    Case("names no file", "map: bad B (report OUT/)",
         lambda b, f: ["report", str(_map_beside_run(b, f, B=-5.0))],
         1, r"out/map\.json: field 'B' must be a positive length in metres"),
    # outputs
    Case("outputs", "-o /dev/null --overwrite",
         lambda b, f: ["contacts", str(b.run), "-o", "/dev/null", "--overwrite"],
         1, r"/dev/null: exists and is not a regular file", check=_dev_null_kept),
    Case("outputs", "-o a folder for a file output",
         lambda b, f: ["contacts", str(b.run), "-o", str(f)],
         2, r"is a directory"),
    # trust
    Case("trust", "a text file given as the log",
         lambda b, f: ["contacts", str(_write(f / "notes.mcap", b"SECRET-PASSWORD-1234\n"))],
         1, r"^(?!.*SECRET)Error: \S*notes\.mcap: not an MCAP file \(no MCAP magic\)$"),
    Case("trust", "meta.source names a text file (report OUT/)",
         lambda b, f: ["report", str(_secret(f))],
         1, r"^(?!.*SECRET)Error: \S*out: no report data and no contact table beside map\.json",
         check=_no_secret),
    Case("trust", "meta.source names a FIFO (report OUT/)",
         lambda b, f: ["report", str(_fifo_source(f))],
         1, r"^Error: \S*out: no report data and no contact table beside map\.json"),
    # resources
    Case("resource", "a chunk declaring 256 MiB",
         lambda b, f: ["contacts", str(_zstd_bomb(b, f))],
         1, r"bomb\.mcap: corrupt chunk \(\d+ compressed bytes declare 268435456 bytes"),
    Case("resource", "URDF entity expansion",
         lambda b, f: ["contacts", str(b.run), "--robot", str(_laughs(f))],
         1, r"^Error: \S*laughs\.urdf: "),
    # also seen
    Case("also seen", "an infinite position",
         lambda b, f: ["contacts", str(_log_variant(b, f, "inf.mcap", _inf_position))],
         1, r"inf\.mcap: topic '/joint_states': 1 infinite positions \(first: joint "
            r"'elbow' at t = 0\.020000 s\)"),
    Case("also seen", "NaN commanded effort",
         lambda b, f: ["contacts", str(_log_variant(b, f, "effort.mcap", _nan_effort))],
         1, r"effort\.mcap: command topic '/joint_commands': 1 NaN commanded torques "
            r"\(effort; first: joint 'shoulder'"),
    Case("also seen", "five NaN velocities",
         lambda b, f: ["contacts", str(_log_variant(b, f, "qd.mcap", _nan_velocities)),
                       "-o", str(f / "c.csv")],
         0, r"qd\.mcap: topic '/joint_states': 5 NaN velocities of \d+ \(first: joint "
            r"'shoulder' at t = 0\.100000 s\); every logged velocity is replaced",
         warning=True),
    Case("also seen", "radius 1e300 in map.json",
         lambda b, f: ["export", str(_map(f, edit=lambda d: d["primitives"][0]["params"]
                                          .update(radius=1e300)))],
         1, r"map\.json: primitives\[0\] \(circle\): 'params' holds 1e\+300, beyond 1000 m"),
    Case("also seen", "a 10-minute gap in the stamps",
         lambda b, f: ["contacts", str(_log_variant(b, f, "gap.mcap", _gap)), "-o",
                       str(f / "c.csv")],
         0, r"gap\.mcap: topic '/joint_states': 1 gap\(s\) in the stamps longer than 1 s, "
            r"the longest 600 s after t = 3\.000 s", warning=True),
    # usage
    Case("usage", "missing log",
         lambda b, f: ["reconstruct", str(f / "nope.mcap"), "-o", str(f / "out")],
         2, r"'RUN': Path '\S*nope\.mcap' does not exist"),
    Case("usage", "an unknown --kind",
         lambda b, f: ["fit", str(_contacts_csv(f)), "--kind", "blob", "-o", str(f / "m.json")],
         2, r"'--kind': unknown primitive type 'blob' \(known: circle, cone"),
    Case("usage", "a FIFO as the log",
         lambda b, f: ["inspect", str(_fifo(f / "fifo.mcap"))],
         2, r"fifo\.mcap' is not a regular file"),
]


def _write(path: Path, data: bytes) -> Path:
    path.write_bytes(data)
    return path


def _fifo(path: Path) -> Path:
    os.mkfifo(path)
    return path


def _absent(path: Path) -> None:
    assert not path.exists()


def _first_sample(cols: dict) -> None:
    for k, v in cols.items():
        if v is not None:
            cols[k] = v[:1]


def _inf_position(cols: dict) -> None:
    cols["q"][10, 1] = np.inf


def _nan_effort(cols: dict) -> None:
    cols["tau_cmd"][30, 0] = np.nan


def _nan_velocities(cols: dict) -> None:
    cols["qd"][50:55, 0] = np.nan


def _gap(cols: dict) -> None:
    cols["t"][cols["t"] > 3.0] += 600.0


def _map_beside_run(base: Base, folder: Path, B: float) -> Path:
    out = folder / "out"
    out.mkdir()
    (out / "run.mcap").write_bytes(base.run.read_bytes())
    _map(out, edit=lambda d: d.update(B=B))
    return out


# ------------------------------------------------------------------------------ running


@dataclass(frozen=True)
class Outcome:
    code: int
    line: str
    output: str


def run_case(case: Case, base: Base, folder: Path) -> Outcome:
    """Run one case in this process; ``line`` is what the user reads about it."""
    args = case.args(base, folder)
    res = CliRunner().invoke(cli, args)
    stderr = res.stderr
    lines = [ln for ln in stderr.splitlines() if ln.strip()]
    if case.warning:
        found = [ln for ln in lines if ln.startswith("WARNING: ")]
    else:
        found = [ln for ln in lines if ln.startswith("Error: ")]
    return Outcome(res.exit_code, found[0] if len(found) == 1 else " | ".join(found),
                   res.output + (repr(res.exception) if res.exception is not None
                                 and not isinstance(res.exception, SystemExit) else ""))


def judge(case: Case, out: Outcome, folder: Path) -> list[str]:
    """What is wrong with an outcome (empty when the case is handled as promised)."""
    problems = []
    if out.code != case.code:
        problems.append(f"exit {out.code}, expected {case.code}")
    if not re.search(case.message, out.line):
        problems.append(f"message {out.line!r} does not match {case.message!r}")
    if "Traceback" in out.output:
        problems.append("traceback")
    if case.check is not None:
        try:
            case.check(folder)
        except AssertionError as exc:
            problems.append(f"check failed {exc}")
    return problems


@pytest.fixture(scope="module")
def base(tmp_path_factory: pytest.TempPathFactory) -> Base:
    return make_base(tmp_path_factory.mktemp("base"))


@pytest.mark.parametrize("case", CASES, ids=[f"{c.kind}: {c.name}" for c in CASES])
def test_bad_input(case: Case, base: Base, tmp_path: Path) -> None:
    out = run_case(case, base, tmp_path)
    assert judge(case, out, tmp_path) == [], out.output


# -------------------------------------------------------------------- real processes


def _as_from_a_terminal() -> None:
    """In the child: SIGINT as a command started from a terminal has it (a test runner
    started in the background may ignore it, and children inherit that)."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)
    signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})


def wholearm(*args: str, limit_bytes: int | None = None, **kwargs) -> subprocess.Popen:
    """``wholearm args`` as a real process in its own process group (a terminal's Ctrl-C
    goes to a whole group), optionally with files limited to ``limit_bytes``."""
    env = {**os.environ, "MPLBACKEND": "Agg", "PYTHONDONTWRITEBYTECODE": "1"}

    def prepare() -> None:
        _as_from_a_terminal()
        if limit_bytes is not None:
            import resource

            signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
            resource.setrlimit(resource.RLIMIT_FSIZE, (limit_bytes, limit_bytes))

    return subprocess.Popen([str(WHOLEARM), *args], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, env=env,
                            start_new_session=True, preexec_fn=prepare, **kwargs)


def _finish(proc: subprocess.Popen) -> Outcome:
    out, err = proc.communicate(timeout=120)  # a guard against a hang, not a measurement
    lines = [ln for ln in err.splitlines() if ln.strip()]
    return Outcome(proc.returncode, lines[-1] if lines else "", out + err)


def full_disk(base: Base, folder: Path) -> Outcome:
    """The output cannot grow past 64 KiB (the file-size limit stands in for a full disk):
    one line naming the output, nothing left behind."""
    proc = wholearm("simulate", "lab_circle", "--duration", "5", "-o", str(folder / "x.mcap"),
                    limit_bytes=64 * 1024)
    out = _finish(proc)
    assert list(folder.iterdir()) == [], list(folder.iterdir())
    return out


def sigint_during_reconstruct(base: Base, folder: Path) -> Outcome:
    """Ctrl-C (SIGINT to the process group) once the command is reading its input: one line,
    and no output folder."""
    proc = wholearm("-v", "reconstruct", str(base.run), "-o", str(folder / "out"))
    assert proc.stderr is not None
    proc.stderr.readline()  # 'INFO: reading ...': the command is running
    os.killpg(proc.pid, signal.SIGINT)
    out = _finish(proc)
    assert not (folder / "out").exists()
    return out


def sigint_at_start(base: Base, folder: Path) -> Outcome:
    """Ctrl-C 0.1 s after the start, while the interpreter or the entry point is still
    importing: the process ends with one line at most (a SIGINT that arrives before Python
    installs its handler ends it as the signal does, silently: the shell reports 130 too).
    The command is one that cannot finish in that time (a short simulation), so the signal
    always finds it running, and it leaves no output behind."""
    proc = wholearm("simulate", "lab_circle", "--duration", "5", "-o", str(folder / "x.mcap"))
    time.sleep(0.1)
    os.killpg(proc.pid, signal.SIGINT)
    out = _finish(proc)
    assert list(folder.iterdir()) == [], list(folder.iterdir())
    if out.code == -signal.SIGINT:
        return Outcome(128 + signal.SIGINT, "(no output: ended by SIGINT itself)", out.output)
    return out


def sigint_in_a_pool(base: Base, folder: Path) -> Outcome:
    """Ctrl-C to a process whose pool workers are busy: one line from the main process."""
    script = textwrap.dedent("""
        import sys, time
        from wholearm_tools._parallel import process_pool
        try:
            with process_pool(2) as pool:
                futures = [pool.submit(time.sleep, 60) for _ in range(4)]
                print("ready", flush=True)
                [f.result() for f in futures]
        except KeyboardInterrupt:
            print("Interrupted.", file=sys.stderr)
            sys.exit(130)
    """)
    proc = subprocess.Popen([sys.executable, "-c", script], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, start_new_session=True,
                            preexec_fn=_as_from_a_terminal)
    assert proc.stdout is not None
    proc.stdout.readline()
    os.killpg(proc.pid, signal.SIGINT)
    return _finish(proc)


def broken_pipe(base: Base, folder: Path) -> Outcome:
    """stdout closed before the result is printed (``| head``)."""
    read, write = os.pipe()
    os.close(read)
    env = {**os.environ, "MPLBACKEND": "Agg"}
    proc = subprocess.Popen([str(WHOLEARM), "inspect", str(base.run)], stdout=write,
                            stderr=subprocess.PIPE, text=True, env=env)
    os.close(write)
    _, err = proc.communicate(timeout=120)
    return Outcome(proc.returncode, err.strip(), err)


PROCESS_CASES = [
    (Case("traceback", "full disk while writing", lambda b, f: [], 1,
          r"x\.mcap: cannot write output \(File too large\)"), full_disk),
    (Case("Ctrl-C", "at 0.1 s (while importing)", lambda b, f: [], 130,
          r"^(Interrupted\.|\(no output: ended by SIGINT itself\))$"),
     sigint_at_start),
    (Case("Ctrl-C", "during a command", lambda b, f: [], 130, r"^Interrupted\.$"),
     sigint_during_reconstruct),
    (Case("Ctrl-C", "pool workers busy", lambda b, f: [], 130, r"^Interrupted\.$"),
     sigint_in_a_pool),
    (Case("CLI habits", "stdout closed early (head)", lambda b, f: [], 141, r"^$"), broken_pipe),
]


@pytest.mark.parametrize(("case", "runner"), PROCESS_CASES,
                         ids=[f"{c.kind}: {c.name}" for c, _ in PROCESS_CASES])
def test_fault_in_a_real_process(case: Case, runner: Callable[[Base, Path], Outcome],
                                 base: Base, tmp_path: Path) -> None:
    out = runner(base, tmp_path)
    assert judge(case, out, tmp_path) == [], out.output
    # one line for the user, whatever the workers did
    assert len([ln for ln in out.output.splitlines() if ln.strip()]) <= 1, out.output


# ------------------------------------------------------------------------------ table


def table(folder: Path) -> list[tuple[str, str, int, str, str]]:
    """``(class, case, exit status, line, OK or the problems)`` for every case."""
    base = make_base(folder)
    rows = []
    everything = [(c, None) for c in CASES] + PROCESS_CASES
    for i, (case, runner) in enumerate(everything):
        sub = folder / f"case{i}"
        sub.mkdir()
        out = runner(base, sub) if runner is not None else run_case(case, base, sub)
        problems = judge(case, out, sub)
        rows.append((case.kind, case.name, out.code, out.line.replace(str(sub) + "/", ""),
                     "OK" if not problems else "; ".join(problems)))
    return rows


if __name__ == "__main__":
    import tempfile

    with tempfile.TemporaryDirectory() as tmp:
        rows = table(Path(tmp))
    print("| class | case | exit | what the user sees | |")
    print("|---|---|---|---|---|")
    for kind, name, code, line, ok in rows:
        print(f"| {kind} | {name} | {code} | `{line}` | {ok} |")
    sys.exit(0 if all(r[-1] == "OK" for r in rows) else 1)

