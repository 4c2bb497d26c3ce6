"""Every ``wholearm`` command x (missing file, bad option, ``-q``, ``--json``, stdout closed).

Not collected by pytest (it runs every command several times as a real process, a few
minutes); ``python tests/cli_habits.py`` prints a markdown table of exit statuses with what
each column checks:

* missing file: a missing input file (exit 2, usage error);
* bad option: an out-of-range option value (exit 2);
* ``-q``: the command succeeds (exit 0) and prints nothing on stderr;
* ``--json``: exit 0 and stdout is one JSON document, numbers typed;
* closed stdout: stdout closed before anything is printed (as ``| head`` does); exit 0 when
  the command prints nothing on stdout, 141 otherwise, and no error or traceback on stderr
  (status lines are still printed there).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

WHOLEARM = Path(sys.executable).with_name("wholearm")


def wholearm(args: list[str], *, closed_stdout: bool = False) -> tuple[int, str, str]:
    env = {**os.environ, "MPLBACKEND": "Agg"}
    if closed_stdout:
        read, write = os.pipe()
        os.close(read)
        proc = subprocess.run([str(WHOLEARM), *args], stdout=write, stderr=subprocess.PIPE,
                              text=True, env=env, timeout=900)
        os.close(write)
        return proc.returncode, "", proc.stderr
    proc = subprocess.run([str(WHOLEARM), *args], capture_output=True, text=True, env=env,
                          timeout=900)
    return proc.returncode, proc.stdout, proc.stderr


def typed(value: object) -> bool:
    """No number hidden in a string anywhere in a JSON document."""
    if isinstance(value, dict):
        return all(typed(v) for v in value.values())
    if isinstance(value, list):
        return all(typed(v) for v in value)
    if isinstance(value, str):
        try:
            float(value)
        except ValueError:
            return True
        return False
    return True


def main() -> None:
    with tempfile.TemporaryDirectory() as tmp:
        d = Path(tmp)
        run, csv, out = d / "run.mcap", d / "contacts.csv", d / "out"
        code, _, err = wholearm(["simulate", "lab_circle", "--duration", "20", "--seed", "1",
                                 "-o", str(run)])
        assert code == 0, err
        assert wholearm(["contacts", str(run), "-o", str(csv)])[0] == 0
        assert wholearm(["reconstruct", str(run), "-o", str(out)])[0] == 0
        urdf = d / "robot.urdf"
        urdf.write_text(_urdf())
        missing = str(d / "missing.mcap")
        # command: (success args builder(k), missing-file args, bad-option args)
        commands = {
            "scenarios": (lambda k: ["scenarios"], None, ["scenarios", "--bogus"]),
            "simulate": (lambda k: ["simulate", "lab_circle", "--duration", "2", "-o",
                                    str(d / f"sim{k}.mcap")],
                         ["simulate", str(d / "missing.yaml"), "-o", str(d / "m.mcap")],
                         ["simulate", "lab_circle", "--rate", "0", "-o", str(d / "m.mcap")]),
            "inspect": (lambda k: ["inspect", str(run)], ["inspect", missing],
                        ["inspect", str(run), "--bogus"]),
            "robot": (lambda k: ["robot", str(urdf), "--log", str(run)],
                      ["robot", str(d / "missing.urdf")],
                      ["robot", str(urdf), "--log", str(d / "missing.mcap")]),
            "contacts": (lambda k: ["contacts", str(run)], ["contacts", missing],
                         ["contacts", str(run), "--B", "-1"]),
            "plot-ptip": (lambda k: ["plot-ptip", str(run), "--steps", "20", "-o",
                                     str(d / f"p{k}.png")],
                          ["plot-ptip", missing, "-o", str(d / "p.png")],
                          ["plot-ptip", str(run), "--steps", "1", "-o", str(d / "p.png")]),
            "reconstruct": (lambda k: ["reconstruct", str(run), "-o", str(d / f"rec{k}")],
                            ["reconstruct", missing, "-o", str(d / "r")],
                            ["reconstruct", str(run), "--B", "nan", "-o", str(d / "r")]),
            "fit": (lambda k: ["fit", str(csv), "-o", str(d / f"fit{k}.json")],
                    ["fit", str(d / "missing.csv"), "-o", str(d / "f.json")],
                    ["fit", str(csv), "--loss", "square", "-o", str(d / "f.json")]),
            "export": (lambda k: ["export", str(out / "map.json"), "-f", "ply", "-o",
                                  str(_folder(d / f"exp{k}"))],
                       ["export", str(d / "missing.json")],
                       ["export", str(out / "map.json"), "-f", "dwg"]),
            "report": (lambda k: ["report", str(out), "-o", str(d / f"r{k}.pdf")],
                       ["report", missing, "-o", str(d / "r.pdf")],
                       ["report", str(out), "--B", "0", "-o", str(d / "r.pdf")]),
            "compare": (lambda k: ["compare", str(run), "--B", "0.02", "-o",
                                   str(d / f"cmp{k}")],
                        ["compare", missing, "-o", str(d / "c")],
                        ["compare", str(run), "--workers", "0", "-o", str(d / "c")]),
            "demo": (lambda k: ["demo", "--scenario", "lab_circle", "--seed", "1",
                                "--duration", "20", "-o", str(d / f"demo{k}")],
                     None, ["demo", "--duration", "-5"]),
        }
        print("| command | missing file | bad option | -q (stderr bytes) | --json "
              "| stdout closed |")
        print("|---|---|---|---|---|---|")
        for name, (ok, absent, bad) in commands.items():
            cells = []
            if absent is None:
                cells.append("n/a")
            else:
                code, _, err = wholearm(absent)
                cells.append(f"{code}" + ("" if "does not exist" in err else " (!)"))
            code, _, err = wholearm(bad)
            cells.append(f"{code}")
            code, _, err = wholearm(["-q", *ok(1)])
            cells.append(f"{code} ({len(err.encode())})")
            code, stdout, err = wholearm([*ok(2), "--json"])
            try:
                doc = json.loads(stdout)
                shape = "JSON, typed" if typed(doc) else "JSON, numbers as strings"
            except json.JSONDecodeError:
                shape = "not JSON"
            cells.append(f"{code} ({shape})")
            code, _, err = wholearm(ok(3), closed_stdout=True)
            noisy = "Error" in err or "Traceback" in err
            cells.append(f"{code} ({'error!' if noisy else 'quiet'})")
            print(f"| {name} | " + " | ".join(cells) + " |", flush=True)


def _urdf() -> str:
    from wholearm_tools.robot import robot_to_urdf
    from wholearm_tools.sim.scenarios import load_scenario

    return robot_to_urdf(load_scenario("lab_circle").robot)


def _folder(path: Path) -> Path:
    path.mkdir(exist_ok=True)
    return path


if __name__ == "__main__":
    main()
