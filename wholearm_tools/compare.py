"""Compare reconstructions of several runs over several values of B, side by side.

``compare_runs(paths, Bs)`` reconstructs every (log, B) pair — in parallel on local processes by
default, or on a Dask distributed cluster — and collects one flat row per pair into a
:class:`ComparisonTable`; ``write_comparison(out_dir, table)`` writes ``comparison.csv``,
``comparison.json`` and ``comparison.pdf``.

Every pair is an independent task :func:`comparison_row` ``(path, B, options) -> dict``: the
worker reads the log itself (only a path and a few options cross the process boundary) and
returns a plain dict of JSON-ready scalars.  Rows come back sorted by log name, log path and B
whatever the completion order, and a row is the same whichever executor computed it; only
``wall_time_s`` differs.  A pair that fails (unreadable log, nothing fitted) gives a row whose
``status`` is not ``"ok"`` and whose ``error`` says why; it never stops the comparison.

Row fields (``None`` where not applicable, e.g. every truth field of a real log)
-----------------------------------------------------------------------------
``log`` file name · ``B`` [m] · ``status`` ok | no-fit | error · ``contacts`` detected ·
``tip`` / ``link`` / ``ambiguous`` contacts per class (they add up to ``contacts``) ·
``unexplained`` contacts no primitive explains · ``primitives`` count · ``types`` e.g.
``"circle=1;line=3"`` · ``truth_contacts`` ground-truth contacts · ``matched`` /
``false_detections`` detections paired / not paired with a truth contact · ``stops`` /
``stops_found`` the arm's stops against contact (a physics run's truth also lists touches that
did not stop it; :func:`wholearm_tools.contacts.arm_stops`) and those detected ·
``link_accuracy`` ·
``class_accuracy`` (over decided labels) and ``ambiguous_fraction`` of eq. (2)'s labels,
``class_accuracy_map`` / ``ambiguous_fraction_map`` of the labels refined by the fitted map ·
``surfaces_touched`` / ``surfaces_found`` /
``surfaces_missed`` truth surfaces with a contact, and those recovered (or not) by a primitive
of the right type · ``<size>_err_<type>_mean|max`` absolute size error of the right-type
primitives: ``radius_err_circle|sphere|cylinder`` [m], ``major_radius_err_torus`` [m],
``half_angle_err_cone`` [deg] · ``axis_err_<type>_mean|max`` [deg] angle between fitted and true
direction/normal/axis (line, plane, cylinder, cone, torus) · ``wall_time_s`` read + reconstruct
time in the worker · ``error`` why the row failed · ``messages`` the log reader's warnings and
the reconstruction's notes · ``path`` the log as read (absolute).

All truth scoring is :func:`wholearm_tools.report.metrics.evaluate` (see there for the matching
rules).
"""

from __future__ import annotations

import contextlib
import csv
import functools
import io
import json
import math
import os
import time
import warnings
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from wholearm_tools._io import atomic_path, write_text_atomic
from wholearm_tools._parallel import available_cores, process_pool
from wholearm_tools.errors import InputError, WholearmError

#: output file names written by :func:`write_comparison`
OUTPUT_NAMES = ("comparison.csv", "comparison.json", "comparison.pdf")

#: fixed leading and trailing columns; per-type error columns go in between
LEADING_COLUMNS = (
    "log", "B", "status", "contacts", "tip", "link", "ambiguous", "unexplained", "primitives",
    "types", "truth_contacts", "matched", "false_detections", "stops", "stops_found",
    "link_accuracy", "class_accuracy", "ambiguous_fraction", "class_accuracy_map",
    "ambiguous_fraction_map", "surfaces_touched", "surfaces_found", "surfaces_missed",
)
TRAILING_COLUMNS = ("wall_time_s", "error", "messages", "path")

#: ground-truth columns (None for real logs)
TRUTH_COLUMNS = ("truth_contacts", "matched", "false_detections", "stops", "stops_found",
                 "link_accuracy", "class_accuracy", "ambiguous_fraction", "class_accuracy_map",
                 "ambiguous_fraction_map", "surfaces_touched", "surfaces_found",
                 "surfaces_missed")

ReconstructFn = Callable[..., Any]


# ------------------------------------------------------------------------------------- table


@dataclass(frozen=True, eq=False)
class ComparisonTable:
    """Rows of a comparison (one plain dict per (log, B) pair, sorted by log then B).

    rows : tuple of dict, JSON-ready scalars (see the module docstring for the fields)
    options : dict, the reconstruction and read options every row used
    """

    rows: tuple[dict[str, Any], ...]
    options: dict[str, Any] = field(default_factory=dict)

    def __len__(self) -> int:
        return len(self.rows)

    def __iter__(self):
        return iter(self.rows)

    @property
    def columns(self) -> tuple[str, ...]:
        """All columns present: the fixed ones, then per-type error columns, sorted."""
        extra = sorted({k for row in self.rows for k in row}
                       - set(LEADING_COLUMNS) - set(TRAILING_COLUMNS))
        return (*LEADING_COLUMNS, *extra, *TRAILING_COLUMNS)

    @property
    def logs(self) -> tuple[str, ...]:
        """Log names in row order, each once."""
        return tuple(dict.fromkeys(row["log"] for row in self.rows))

    @property
    def Bs(self) -> tuple[float, ...]:  # noqa: N802 - B is the paper's name
        """B values, sorted, each once."""
        return tuple(sorted({row["B"] for row in self.rows}))

    def results(self) -> list[dict[str, Any]]:
        """The rows without ``wall_time_s`` (what must agree between executors and reruns)."""
        return [{k: v for k, v in row.items() if k != "wall_time_s"} for row in self.rows]

    @property
    def failed(self) -> tuple[dict[str, Any], ...]:
        """Rows whose status is ``"error"`` (the log could not be read or reconstructed)."""
        return tuple(row for row in self.rows if row["status"] == "error")

    def to_json(self) -> dict[str, Any]:
        """``{"format": "wholearm-comparison", "version": 1, "options", "columns", "rows"}``."""
        return {"format": "wholearm-comparison", "version": 1, "options": self.options,
                "columns": list(self.columns),
                "rows": [{c: row.get(c) for c in self.columns} for row in self.rows]}

    def to_csv(self) -> str:
        """CSV text, one line per row; empty cells where a value does not apply."""
        buf = io.StringIO()
        writer = csv.writer(buf, lineterminator="\n")
        writer.writerow(self.columns)
        for row in self.rows:
            writer.writerow(["" if row.get(c) is None else _csv_cell(row[c])
                             for c in self.columns])
        return buf.getvalue()

    def summary_rows(self) -> tuple[list[str], list[list[str]]]:
        """Header and cells of the compact table printed by the CLI and drawn in the PDF."""
        header = ["log", "B [m]", "contacts", "tip", "link", "amb", "prims", "types", "link acc",
                  "class acc", "map acc", "map amb", "found/touched", "radius err [mm]",
                  "axis err [deg]", "time [s]", "status"]
        cells = []
        for row in self.rows:
            radius = _mean_of(row, "radius_err_", "_mean")
            axis = _mean_of(row, "axis_err_", "_mean")
            found = ("" if row.get("surfaces_touched") is None
                     else f"{row['surfaces_found']}/{row['surfaces_touched']}")
            status = row["status"] if row["status"] == "ok" else \
                f"{row['status']}: {row['error']}"
            cells.append([
                row["log"], f"{row['B']:g}", _fmt(row.get("contacts")), _fmt(row.get("tip")),
                _fmt(row.get("link")), _fmt(row.get("ambiguous")), _fmt(row.get("primitives")),
                row.get("types") or "", _fmt(row.get("link_accuracy"), ".2f"),
                _fmt(row.get("class_accuracy"), ".2f"),
                _fmt(row.get("class_accuracy_map"), ".2f"),
                _fmt(row.get("ambiguous_fraction_map"), ".2f"), found,
                _fmt(None if radius is None else radius * 1e3, ".2f"), _fmt(axis, ".2f"),
                _fmt(row.get("wall_time_s"), ".2f"), status,
            ])
        return header, cells

    def to_text(self) -> str:
        """Fixed-width text table (the compact columns), one line per row."""
        header, cells = self.summary_rows()
        widths = [max(len(h), *(len(r[i]) for r in cells)) if cells else len(h)
                  for i, h in enumerate(header)]
        lines = ["  ".join(h.ljust(w) for h, w in zip(header, widths, strict=True)).rstrip()]
        lines += ["  ".join(c.ljust(w) for c, w in zip(r, widths, strict=True)).rstrip()
                  for r in cells]
        return "\n".join(lines)


def _csv_cell(value: Any) -> Any:
    return repr(value) if isinstance(value, float) else value


def _fmt(value: Any, spec: str = "d") -> str:
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return "-"
    return format(value, spec)


def _mean_of(row: Mapping[str, Any], prefix: str, suffix: str) -> float | None:
    """Mean of the per-type columns ``prefix<type>suffix`` present in ``row`` (None if none)."""
    vals = [v for k, v in row.items()
            if k.startswith(prefix) and k.endswith(suffix) and v is not None]
    return float(np.mean(vals)) if vals else None


# ------------------------------------------------------------------------------- one row


def comparison_row(path: str, B: float, options: Mapping[str, Any] | None = None, *,
                   reconstruct: ReconstructFn | None = None) -> dict[str, Any]:
    """Read the log at ``path``, reconstruct it with ``B`` and return its comparison row.

    The task every executor runs.  Never raises for a bad log or a failed reconstruction: the
    row then has ``status`` ``"error"`` (or ``"no-fit"`` when nothing was fitted) and an
    ``error`` message.

    Parameters
    ----------
    path : str, MCAP log
    B : float, smallest expected surface curvature radius [m]
    options : ``{"read": read_run keyword arguments, "reconstruct": reconstruct keyword
        arguments}`` (both optional)
    reconstruct : function ``(run, B=..., **options) -> Reconstruction``; default
        :func:`wholearm_tools.pipeline.reconstruct`
    """
    options = dict(options or {})
    row = _blank_row(path, B)
    clock = time.perf_counter()
    try:
        from wholearm_tools.logs import read_run

        if reconstruct is None:
            from wholearm_tools.pipeline import reconstruct
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            run = read_run(path, **dict(options.get("read") or {}))
            rec = reconstruct(run, B=float(B), **dict(options.get("reconstruct") or {}))
        notes = [str(w.message) for w in caught] + [str(m) for m in rec.messages]
        row["messages"] = " | ".join(dict.fromkeys(notes)) or None
        row.update(reconstruction_summary(rec))
        row["status"] = "ok" if row["primitives"] else "no-fit"
        if not row["primitives"]:
            row["error"] = "nothing fitted: " + ("; ".join(rec.messages) or
                                                 "no primitive explains the contacts")
    except (WholearmError, OSError) as exc:
        row["error"] = _one_line(str(exc) or type(exc).__name__)
    except Exception as exc:  # a crash in one reconstruction must not lose the others
        row["error"] = _one_line(f"{type(exc).__name__}: {exc}")
    row["wall_time_s"] = time.perf_counter() - clock
    return {k: _scalar(v) for k, v in row.items()}


def _scalar(value: Any) -> Any:
    """Plain Python scalar; NaN becomes None (JSON has no NaN)."""
    if isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def _blank_row(path: str, B: float) -> dict[str, Any]:
    """A row with every fixed column, status ``"error"`` until filled."""
    row: dict[str, Any] = dict.fromkeys((*LEADING_COLUMNS, *TRAILING_COLUMNS))
    row.update(log=Path(path).name, B=float(B), status="error", path=str(path))
    return row


def _one_line(text: str) -> str:
    return " ".join(text.split())


def reconstruction_summary(rec: Any) -> dict[str, Any]:
    """Counts, primitives and (when the run has ground truth) errors of one reconstruction."""
    labels = np.asarray(rec.table.label).astype(str)
    kinds = [p.kind for p in rec.surface_map.primitives]
    out: dict[str, Any] = {
        "contacts": len(labels),
        "tip": int(np.sum(labels == "tip")),
        "link": int(np.sum(labels == "link")),
        "ambiguous": int(np.sum(labels == "ambiguous")),
        "unexplained": int(np.sum(np.asarray(rec.table.primitive) < 0)),
        "primitives": len(kinds),
        "types": ";".join(f"{k}={kinds.count(k)}" for k in sorted(set(kinds))),
    }
    out.update(truth_errors(rec))
    return out


def truth_errors(rec: Any) -> dict[str, Any]:
    """Errors against the run's ground truth (:func:`wholearm_tools.report.metrics.evaluate`);
    every field ``None`` for a real log."""
    from wholearm_tools.report.metrics import evaluate

    report = evaluate(rec)
    if report is None:
        return dict.fromkeys(TRUTH_COLUMNS)
    cls = report.classification
    touched = [s for s in report.surfaces if s.touched]
    out: dict[str, Any] = {
        "truth_contacts": cls.n_truth,
        "matched": cls.n_matched,
        "false_detections": cls.n_false,
        "stops": cls.n_stops,
        "stops_found": cls.n_stops_found,
        "link_accuracy": cls.link_accuracy,
        "class_accuracy": cls.class_accuracy,
        "ambiguous_fraction": cls.ambiguous_fraction,
        "class_accuracy_map": (report.classification_map.class_accuracy
                               if report.classification_map is not None else None),
        "ambiguous_fraction_map": (report.classification_map.ambiguous_fraction
                                   if report.classification_map is not None else None),
        "surfaces_touched": len(touched),
        "surfaces_found": sum(s.found for s in touched),
        "surfaces_missed": sum(not s.found for s in touched),
    }
    errors: dict[str, list[float]] = {}
    for acc in report.primitives:
        if not acc.type_correct:
            continue
        if acc.size_error is not None:
            errors.setdefault(f"{acc.size_name}_err_{acc.kind}", []).append(abs(acc.size_error))
        if acc.axis_angle_deg is not None:
            errors.setdefault(f"axis_err_{acc.kind}", []).append(acc.axis_angle_deg)
    for name, vals in sorted(errors.items()):
        out[f"{name}_mean"] = float(np.mean(vals))
        out[f"{name}_max"] = float(np.max(vals))
    return out


# ---------------------------------------------------------------------------- the sweep


def compare_runs(paths: Iterable[str | os.PathLike[str]], Bs: Iterable[float], *,
                 scheduler: Any = None, workers: int | None = None,
                 read_options: Mapping[str, Any] | None = None,
                 reconstruct: ReconstructFn | None = None,
                 progress: Callable[[int, int], None] | None = None,
                 **reconstruct_options: Any) -> ComparisonTable:
    """Reconstruct every (log, B) pair and tabulate the results.

    Parameters
    ----------
    paths : MCAP logs (each read by the worker that reconstructs it; duplicates dropped)
    Bs : B values [m], positive (duplicates dropped)
    scheduler : None (local processes), a Dask scheduler address ``"tcp://host:port"``, or a
        ``distributed.Client``.  Dask workers must see the logs at the same (absolute) paths.
    workers : local processes, default ``min(pairs, cores this process may use)``; 1 runs in
        this process.
        Ignored with a Dask scheduler (the cluster decides).
    read_options : keyword arguments of :func:`wholearm_tools.logs.read_run` (robot, topics)
    reconstruct : the reconstruction function (default :func:`wholearm_tools.pipeline
        .reconstruct`); must be picklable (a module-level function) for parallel runs
    progress : called as ``progress(done, total)`` each time a pair is finished (in the
        calling process, in completion order)
    **reconstruct_options : keyword arguments of the reconstruction (``causal``, ``loss``, ...)

    Returns
    -------
    ComparisonTable with one row per pair, sorted by log name, log path, B.

    Raises
    ------
    InputError
        No logs, no B values, a B that is not a positive length, ``workers < 1``, or a
        scheduler that is neither an address nor a client.
    """
    logs = sorted(dict.fromkeys(os.path.abspath(os.fspath(p)) for p in paths),
                  key=lambda p: (Path(p).name, p))
    values = _check_Bs(Bs)
    if not logs:
        raise InputError("no logs to compare")
    if workers is not None and (int(workers) != workers or workers < 1):
        raise InputError(f"workers must be a positive integer, got {workers!r}")
    options = {"read": dict(read_options or {}), "reconstruct": dict(reconstruct_options)}
    pairs = [(p, b) for p in logs for b in values]
    task: Callable[..., dict[str, Any]] = (
        comparison_row if reconstruct is None
        else functools.partial(comparison_row, reconstruct=reconstruct))
    done = _Counter(len(pairs), progress)
    if scheduler is not None:
        rows = _run_dask(task, pairs, options, scheduler, done)
    else:
        rows = _run_local(task, pairs, options, workers, done)
    return ComparisonTable(rows=tuple(rows), options=_jsonable(options))


def _check_Bs(Bs: Iterable[float]) -> list[float]:  # noqa: N802
    try:
        values = [float(b) for b in Bs]
    except (TypeError, ValueError):
        raise InputError(f"B values must be numbers, got {Bs!r}") from None
    if not values:
        raise InputError("no B values to compare")
    bad = [b for b in values if not (math.isfinite(b) and b > 0)]
    if bad:
        raise InputError(f"B must be a positive length in metres, got {bad[0]}")
    return sorted(set(values))


class _Counter:
    """Counts finished pairs and reports them to an optional ``progress(done, total)``."""

    def __init__(self, total: int, progress: Callable[[int, int], None] | None) -> None:
        self.total, self.done, self.progress = total, 0, progress

    def tick(self, *_: Any) -> None:
        self.done += 1
        if self.progress is not None:
            self.progress(self.done, self.total)


def _run_local(task: Callable[..., dict[str, Any]], pairs: Sequence[tuple[str, float]],
               options: dict[str, Any], workers: int | None, done: _Counter
               ) -> list[dict[str, Any]]:
    from concurrent.futures import as_completed

    cores = available_cores()
    n = min(len(pairs), workers or cores, cores)
    if n <= 1:
        rows = []
        for p, b in pairs:
            rows.append(task(p, b, options))
            done.tick()
        return rows
    # the platform's default start method (fork on Linux): workers need no re-import of the
    # caller's script, so a plain script without a ``__main__`` guard works; workers ignore
    # Ctrl-C and are stopped when the main process is interrupted
    with process_pool(n) as pool:
        futures = [pool.submit(task, p, b, options) for p, b in pairs]
        for _ in as_completed(futures):
            done.tick()
        return [_result_or_error(f.result, p, b) for f, (p, b) in
                zip(futures, pairs, strict=True)]


def _run_dask(task: Callable[..., dict[str, Any]], pairs: Sequence[tuple[str, float]],
              options: dict[str, Any], scheduler: Any, done: _Counter
              ) -> list[dict[str, Any]]:
    from distributed import Client, as_completed

    if isinstance(scheduler, Client):
        client, owned = scheduler, False
    elif isinstance(scheduler, str):
        try:
            client, owned = Client(scheduler, timeout="10s"), True
        except (OSError, TimeoutError) as exc:
            raise InputError(f"cannot connect to the Dask scheduler at {scheduler} "
                             f"({_one_line(str(exc))})") from None
    else:
        raise InputError(f"scheduler must be an address like 'tcp://host:port' or a "
                         f"distributed.Client, got {scheduler!r}")
    try:
        paths = [p for p, _ in pairs]
        Bs = [b for _, b in pairs]
        futures = client.map(task, paths, Bs, [options] * len(pairs), pure=False)
        try:
            for _ in as_completed(futures):
                done.tick()
            return [_result_or_error(f.result, p, b) for f, (p, b) in
                    zip(futures, pairs, strict=True)]
        except BaseException:  # Ctrl-C: do not leave the cluster working for nobody
            with contextlib.suppress(Exception):
                client.cancel(futures)
            raise
    finally:
        if owned:
            client.close()


def _result_or_error(result: Callable[[], dict[str, Any]], path: str, B: float
                     ) -> dict[str, Any]:
    """The task's row, or an error row when the worker itself died."""
    try:
        return result()
    except Exception as exc:
        row = _blank_row(path, B)
        row["error"] = _one_line(f"worker failed: {type(exc).__name__}: {exc}")
        return row


def _jsonable(value: Any) -> Any:
    return json.loads(json.dumps(value, default=str))


# -------------------------------------------------------------------------------- outputs


def write_comparison(out_dir: str | os.PathLike[str], table: ComparisonTable
                     ) -> dict[str, Path]:
    """Write ``comparison.csv``, ``comparison.json`` and ``comparison.pdf`` into ``out_dir``
    (created if needed), each atomically.  Returns ``{"csv", "json", "pdf"}`` paths."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths = {"csv": out / OUTPUT_NAMES[0], "json": out / OUTPUT_NAMES[1],
             "pdf": out / OUTPUT_NAMES[2]}
    write_text_atomic(paths["csv"], table.to_csv())
    write_text_atomic(paths["json"], json.dumps(table.to_json(), indent=1, allow_nan=False)
                      + "\n")
    with atomic_path(paths["pdf"], suffix=".pdf") as tmp:
        write_comparison_pdf(tmp, table)
    return paths


def write_comparison_pdf(path: str | os.PathLike[str], table: ComparisonTable) -> None:
    """Two-page PDF: the compact table, then contacts per class and errors against B."""
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt
    from matplotlib.backends.backend_pdf import PdfPages

    with PdfPages(path, metadata={"Title": "wholearm B comparison", "Creator": "wholearm"}) \
            as pdf:
        for fig in (_table_figure(plt, table), _plots_figure(plt, table)):
            pdf.savefig(fig)
            plt.close(fig)


def _table_figure(plt: Any, table: ComparisonTable) -> Any:
    header, cells = table.summary_rows()
    cells = [[*c[:-1], c[-1] if len(c[-1]) <= 40 else c[-1][:37] + "..."] for c in cells]
    fig = plt.figure(figsize=(11.69, 8.27))
    fig.suptitle(f"B comparison: {len(table.logs)} log(s) x {len(table.Bs)} B value(s)",
                 fontsize=12)
    ax = fig.add_axes((0.02, 0.05, 0.96, 0.85))
    ax.axis("off")
    if cells:
        tab = ax.table(cellText=cells, colLabels=header, loc="upper center", cellLoc="center")
        tab.auto_set_font_size(False)
        tab.set_fontsize(7 if len(cells) <= 30 else 5)
        tab.auto_set_column_width(list(range(len(header))))
    else:
        ax.text(0.5, 0.5, "no rows", ha="center", va="center")
    return fig


def _plots_figure(plt: Any, table: ComparisonTable) -> Any:
    from matplotlib.ticker import MaxNLocator

    fig, axes = plt.subplots(2, 2, figsize=(11.69, 8.27), constrained_layout=True)
    colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    styles = {"tip": ("o", "-"), "link": ("s", "--"), "ambiguous": ("^", ":")}
    ok_rows = [r for r in table.rows if r["status"] != "error"]
    for k, log in enumerate(table.logs):
        colour = colours[k % len(colours)]
        rows = sorted((r for r in ok_rows if r["log"] == log), key=lambda r: r["B"])
        if not rows:
            continue
        B = [r["B"] for r in rows]
        for cls, (marker, line) in styles.items():
            axes[0, 0].plot(B, [r[cls] for r in rows], marker=marker, linestyle=line,
                            color=colour, label=f"{log}: {cls}")
        axes[0, 1].plot(B, [r["primitives"] for r in rows], marker="o", color=colour,
                        label=f"{log}: primitives")
        if any(r.get("surfaces_touched") is not None for r in rows):
            axes[0, 1].plot(B, [r.get("surfaces_found") for r in rows], marker="x",
                            linestyle="--", color=colour, label=f"{log}: surfaces found")
        for key, marker, line in (("class_accuracy", "o", "-"), ("link_accuracy", "s", "--"),
                                  ("class_accuracy_map", "^", ":")):
            ys = [_nan(r.get(key)) for r in rows]
            if not all(math.isnan(y) for y in ys):
                axes[1, 0].plot(B, ys, marker=marker, linestyle=line, color=colour,
                                label=f"{log}: {key.replace('_', ' ')}")
        radius = [_nan(_mean_of(r, "radius_err_", "_mean")) for r in rows]
        axis = [_nan(_mean_of(r, "axis_err_", "_mean")) for r in rows]
        if not all(math.isnan(y) for y in radius):
            axes[1, 1].plot(B, [y * 1e3 for y in radius], marker="o", color=colour,
                            label=f"{log}: radius [mm]")
        if not all(math.isnan(y) for y in axis):
            axes[1, 1].plot(B, axis, marker="s", linestyle="--", color=colour,
                            label=f"{log}: axis [deg]")
    titles = (("contacts per class", "contacts"), ("primitives", "count"),
              ("accuracy vs ground truth", "fraction"), ("mean fit errors vs ground truth",
                                                         "mm / deg"))
    for ax, (title, ylabel) in zip(axes.ravel(), titles, strict=True):
        ax.set_title(title, fontsize=10)
        ax.set_xlabel("B [m]")
        ax.set_ylabel(ylabel)
        if len(table.Bs) > 1 and table.Bs[-1] / table.Bs[0] >= 5:
            ax.set_xscale("log")
        ax.set_xticks(table.Bs, [f"{b:g}" for b in table.Bs])
        ax.minorticks_off()
        ax.grid(True, alpha=0.3)
        if ylabel in ("contacts", "count"):  # whole numbers: no 1.2 primitives on the axis
            ax.yaxis.set_major_locator(MaxNLocator(integer=True))
        if ax.lines:
            ax.legend(fontsize=6)
        else:
            ax.text(0.5, 0.5, "no data", ha="center", va="center", transform=ax.transAxes)
    return fig


def _nan(value: Any) -> float:
    return float("nan") if value is None else float(value)
