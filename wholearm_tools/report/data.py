"""What the PDF report needs, as one record, and the small file that keeps it beside map.json.

The report is a pure function of :class:`ReportData`: the map (map.json), the contact table
(contacts.csv) and what neither file holds, kept in ``report_data.json`` so that ``wholearm
report OUT/`` renders again without the log and without refitting:

``run``
    what the report says about the input: its path (relative to the output folder), sha256,
    kind (``log`` or ``contact table``), duration, rate, clock start (``t0_ns``), number of
    joints, planar or spatial, robot name and joint names, the torque source the contacts were
    detected from and where it was read, the log's joints the robot's chain does not drive
    (left out), the robot description (URDF of the capsule model used) and, for simulated
    runs, the ground truth (surfaces and per-contact truth, for the accuracy pages);
``contacts``
    the contact table's file (relative path) and sha256, checked on reading;
``assignment``
    per contact row: the primitive that explains it (-1 none), its residual [m], the tip
    probability, label and link refined by the fitted map (the columns the fit adds);
``fits``
    per primitive (map order): the parameter labels of its covariance, the free side, its tip
    and link residuals [m];
``ptip_history``
    the causal replay of every contact's P_T (paper, Fig. 4): ``times (S,)`` [s on the log
    clock] and ``p_tip (M, S)`` (``null`` before a contact happened), with the classification
    thresholds; absent when there is no log (a map fitted from a contact table);
``messages``
    the reconstruction's notes.

Every float is written in full (JSON numbers; NaN as ``null``), so a report rendered from the
files is the same whether ``reconstruct`` or ``report`` renders it; nothing in it depends on
the machine or the time (stage timings are left out), so the same run gives the same bytes.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from wholearm_tools.contact_table import ContactTable
from wholearm_tools.errors import InputError
from wholearm_tools.mapfile import SurfaceMap, jsonable

REPORT_DATA_FORMAT = "wholearm-report-data"
REPORT_DATA_VERSION = 1
#: replay times of the P_T-over-time page
PTIP_STEPS = 60
#: torque source assumed when the run does not say (logs read before the field existed)
DEFAULT_TORQUE_SOURCE = "commanded"


def sha256_of(path: str | Path) -> str:
    """Hex sha256 of a file; of a folder (a rosbag2 bag), of its files' names and hashes in
    sorted order."""
    path = Path(path)
    digest = hashlib.sha256()
    if path.is_dir():
        for child in sorted(p for p in path.rglob("*") if p.is_file()):
            digest.update(child.relative_to(path).as_posix().encode("utf-8") + b"\0")
            digest.update(bytes.fromhex(sha256_of(child)))
        return digest.hexdigest()
    with open(path, "rb") as handle:
        for block in iter(lambda: handle.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def torque_source_of(run: Any) -> str:
    """The torque signal the run's contacts were detected from (``commanded``, ``measured``,
    ``position``…), read from the log or the run; :data:`DEFAULT_TORQUE_SOURCE` when neither
    says."""
    for holder in (getattr(run, "log", None), run):
        value = getattr(holder, "torque_source", None)
        if value:
            return str(value)
    return DEFAULT_TORQUE_SOURCE


# ------------------------------------------------------------------------------ records


@dataclass(frozen=True, eq=False)
class FitInfo:
    """What the report uses of one primitive's fit (``wholearm_tools.fit.FitResult``)."""

    id: int
    param_labels: tuple[str, ...] = ()
    free_side: float = 1.0
    tip_residuals: NDArray[np.float64] = field(default_factory=lambda: np.zeros(0))
    link_residuals: NDArray[np.float64] = field(default_factory=lambda: np.zeros(0))


@dataclass(frozen=True, eq=False)
class RunInfo:
    """The input of a reconstruction as the report describes it.

    ``source`` is the path as recorded (relative to the output folder when it was written
    there); ``duration``, ``rate`` and ``dof`` are None for a map fitted from a contact table.
    """

    source: str
    kind: str = "log"
    sha256: str | None = None
    duration: float | None = None
    rate: float | None = None
    t0_ns: int = 0
    dof: int | None = None
    planar: bool = False
    robot_name: str | None = None
    joint_names: tuple[str, ...] = ()
    torque_source: str | None = None
    torque_note: str = ""
    ignored_joints: tuple[str, ...] = ()
    robot_urdf: str | None = None
    truth: Any = None          # wholearm_tools.logs.records.GroundTruth | None

    @property
    def name(self) -> str:
        return Path(self.source).name


@dataclass(frozen=True, eq=False)
class ReportData:
    """Everything the PDF report shows (see the module docstring)."""

    surface_map: SurfaceMap
    table: ContactTable
    run: RunInfo
    fits: tuple[FitInfo, ...] = ()
    messages: tuple[str, ...] = ()
    ptip_times: NDArray[np.float64] | None = None
    ptip_history: NDArray[np.float64] | None = None
    thresholds: tuple[float, float] = (0.2, 0.6)

    @property
    def parameters(self) -> dict[str, Any]:
        """The reconstruction's parameters as map.json records them (``meta.parameters``)."""
        return dict(self.surface_map.meta.get("parameters", {}))

    @property
    def B(self) -> float:  # noqa: N802 - the paper's name
        return float(self.surface_map.B)

    @property
    def planar(self) -> bool:
        return bool(self.surface_map.planar)


# ------------------------------------------------------------------------------ building


def _fit_info(pid: int, fit: Any) -> FitInfo:
    def arr(name: str) -> NDArray[np.float64]:
        return np.asarray(getattr(fit, name, np.zeros(0)), dtype=float).reshape(-1)

    return FitInfo(id=pid, param_labels=tuple(getattr(fit, "param_labels", ()) or ()),
                   free_side=float(getattr(fit, "free_side", 1.0)),
                   tip_residuals=arr("tip_residuals"), link_residuals=arr("link_residuals"))


def fit_infos(surface_map: SurfaceMap, fits: Any) -> tuple[FitInfo, ...]:
    """One :class:`FitInfo` per primitive of the map (fits are in map order)."""
    fits = tuple(fits or ())
    return tuple(_fit_info(p.id, fits[i]) if i < len(fits) and fits[i] is not None
                 else FitInfo(p.id) for i, p in enumerate(surface_map.primitives))


def run_info(run: Any, source: str | None = None, sha256: str | None = None) -> RunInfo:
    """:class:`RunInfo` of a :class:`~wholearm_tools.logs.records.Run`; ``source`` replaces the
    run's own path (e.g. with the path relative to the output folder)."""
    from wholearm_tools.robot.urdf import robot_to_urdf

    robot, log = run.robot, run.log
    return RunInfo(
        source=str(run.source if source is None else source), kind="log", sha256=sha256,
        duration=float(log.duration), rate=float(log.rate), t0_ns=int(log.t0_ns),
        dof=int(robot.dof), planar=bool(robot.planar), robot_name=str(robot.name),
        joint_names=tuple(robot.joint_names), torque_source=torque_source_of(run),
        torque_note=str(getattr(log, "torque_note", "") or ""),
        ignored_joints=tuple(getattr(log, "ignored_joints", ()) or ()),
        robot_urdf=robot_to_urdf(robot), truth=run.truth)


def ptip_history(rec: Any, steps: int = PTIP_STEPS) -> tuple[NDArray, NDArray]:
    """``(times (S,), p_tip (M, S))``: the causal replay of a reconstruction's contacts."""
    from wholearm_tools.classify import tip_probability_history

    if steps < 2:
        raise InputError(f"the P_T replay needs at least 2 times, got {steps}")
    log = rec.run.log
    times = np.linspace(float(log.t[0]), float(log.t[-1]), steps)
    if len(rec.contacts) == 0:
        return times, np.zeros((0, steps))
    return times, tip_probability_history(rec.run, rec.contacts, rec.params.B, times)


def report_data_from_reconstruction(rec: Any, *, surface_map: SurfaceMap | None = None,
                                    run: RunInfo | None = None, steps: int = PTIP_STEPS
                                    ) -> ReportData:
    """The :class:`ReportData` of a :class:`~wholearm_tools.pipeline.Reconstruction` (computes
    the P_T replay, the only costly part: the swept map at ``steps`` times)."""
    meta = getattr(rec.classification, "meta", {}) or {}
    times, hist = ptip_history(rec, steps)
    sm = rec.surface_map if surface_map is None else surface_map
    if "parameters" not in sm.meta:
        from wholearm_tools.outputs import (
            creation_time,
            reconstruction_parameters,
            tool_record,
        )

        sm = dataclasses.replace(sm, meta={
            **sm.meta, "tool": tool_record(), "created": creation_time(),
            "parameters": jsonable(reconstruction_parameters(rec))})
    return ReportData(
        surface_map=sm, table=rec.table, run=run_info(rec.run) if run is None else run,
        fits=fit_infos(sm, rec.fits), messages=tuple(rec.messages), ptip_times=times,
        ptip_history=hist,
        thresholds=(float(meta.get("link_threshold", 0.2)),
                    float(meta.get("tip_threshold", 0.6))))


# ------------------------------------------------------------------------------ JSON


def _truth_to_json(truth: Any) -> dict[str, Any] | None:
    if truth is None:
        return None
    return {f.name: jsonable(getattr(truth, f.name)) for f in dataclasses.fields(truth)}


def _truth_from_json(data: Any, source: str) -> Any:
    if data is None:
        return None
    from wholearm_tools.logs.records import GroundTruth

    names = {f.name for f in dataclasses.fields(GroundTruth)}
    try:
        kwargs = {k: v for k, v in data.items() if k in names}
        kwargs["surfaces"] = tuple(kwargs.get("surfaces", ()))
        kwargs["contact_point"] = np.asarray(kwargs.get("contact_point", []),
                                             float).reshape(-1, 3)
        return GroundTruth(**kwargs)
    except (AttributeError, TypeError, ValueError) as exc:
        raise InputError(f"{source}: malformed ground truth ({exc})") from None


def report_data_to_json(data: ReportData, contacts_path: str, contacts_sha256: str
                        ) -> dict[str, Any]:
    """The JSON document of ``report_data.json`` (the map and the table are referenced, not
    copied: the table by its path relative to the output folder and its sha256)."""
    t = data.table
    run = data.run
    history = None
    if data.ptip_times is not None and data.ptip_history is not None:
        history = {"times": data.ptip_times, "p_tip": data.ptip_history,
                   "link_threshold": data.thresholds[0], "tip_threshold": data.thresholds[1]}
    return jsonable({
        "format": REPORT_DATA_FORMAT, "version": REPORT_DATA_VERSION,
        "contacts": {"path": contacts_path, "sha256": contacts_sha256, "count": len(t)},
        "assignment": {"primitive": t.primitive, "residual": t.residual,
                       "p_tip_map": t.p_tip_map, "label_map": t.label_map.tolist(),
                       "link_by_map": t.link_by_map},
        "run": {"source": run.source, "kind": run.kind, "sha256": run.sha256,
                "duration": run.duration, "rate": run.rate, "t0_ns": run.t0_ns,
                "dof": run.dof, "planar": run.planar, "robot_name": run.robot_name,
                "joint_names": list(run.joint_names), "torque_source": run.torque_source,
                "torque_note": run.torque_note, "ignored_joints": list(run.ignored_joints),
                "robot_urdf": run.robot_urdf, "truth": _truth_to_json(run.truth)},
        "fits": [{"id": f.id, "param_labels": list(f.param_labels), "free_side": f.free_side,
                  "tip_residuals": f.tip_residuals, "link_residuals": f.link_residuals}
                 for f in data.fits],
        "ptip_history": history, "messages": list(data.messages),
    })


def _floats(value: Any, shape: tuple[int, ...] | None = None) -> NDArray[np.float64]:
    arr = np.array([np.nan if v is None else v for v in value] if shape is None or
                   len(shape) == 1 else
                   [[np.nan if v is None else v for v in row] for row in value], dtype=float)
    if shape is not None:
        arr = arr.reshape(shape)
    return arr


def report_data_from_json(doc: Any, surface_map: SurfaceMap, table: ContactTable,
                          source: str = "report_data.json") -> ReportData:
    """:class:`ReportData` from the JSON document, the map and the (unassigned or assigned)
    contact table it refers to; the assignment columns come from the document."""
    if not isinstance(doc, dict) or doc.get("format") != REPORT_DATA_FORMAT:
        raise InputError(f"{source}: not a wholearm report data file (expected \"format\": "
                         f"\"{REPORT_DATA_FORMAT}\")")
    if doc.get("version") != REPORT_DATA_VERSION:
        raise InputError(f"{source}: report data version {doc.get('version')!r} is not "
                         f"supported (this wholearm reads version {REPORT_DATA_VERSION})")
    try:
        m = len(table)
        a = doc["assignment"]
        table = dataclasses.replace(
            table, primitive=np.asarray(a["primitive"], dtype=np.int64).reshape(m),
            residual=_floats(a["residual"], (m,)),
            p_tip_map=_floats(a["p_tip_map"], (m,)),
            label_map=np.asarray(a["label_map"], dtype="<U9").reshape(m),
            link_by_map=np.asarray(a["link_by_map"], dtype=np.int64).reshape(m))
        r = doc["run"]
        run = RunInfo(
            source=str(r["source"]), kind=str(r.get("kind", "log")), sha256=r.get("sha256"),
            duration=None if r.get("duration") is None else float(r["duration"]),
            rate=None if r.get("rate") is None else float(r["rate"]),
            t0_ns=int(r.get("t0_ns") or 0),
            dof=None if r.get("dof") is None else int(r["dof"]),
            planar=bool(r.get("planar", surface_map.planar)),
            robot_name=r.get("robot_name"), joint_names=tuple(r.get("joint_names") or ()),
            torque_source=r.get("torque_source"), torque_note=str(r.get("torque_note") or ""),
            ignored_joints=tuple(r.get("ignored_joints") or ()), robot_urdf=r.get("robot_urdf"),
            truth=_truth_from_json(r.get("truth"), source))
        fits = tuple(FitInfo(id=int(f["id"]), param_labels=tuple(f.get("param_labels", ())),
                             free_side=float(f.get("free_side", 1.0)),
                             tip_residuals=_floats(f.get("tip_residuals", [])),
                             link_residuals=_floats(f.get("link_residuals", [])))
                     for f in doc.get("fits", []))
        h = doc.get("ptip_history")
        times = hist = None
        thresholds = (0.2, 0.6)
        if h is not None:
            times = _floats(h["times"])
            hist = _floats(h["p_tip"], (m, times.shape[0])) if m else np.zeros((0, len(times)))
            thresholds = (float(h["link_threshold"]), float(h["tip_threshold"]))
        return ReportData(
            surface_map=surface_map, table=table, run=run, fits=fits,
            messages=tuple(str(x) for x in doc.get("messages", [])), ptip_times=times,
            ptip_history=hist, thresholds=thresholds)
    except InputError:
        raise
    except (KeyError, TypeError, ValueError) as exc:
        raise InputError(f"{source}: malformed report data ({type(exc).__name__}: {exc})"
                         ) from None


def dumps(doc: Any) -> str:
    """JSON text of a report data document (compact, NaN-free, one trailing newline)."""
    text = json.dumps(doc, separators=(",", ":"), allow_nan=False)
    return text + "\n"


def finite_or_none(x: Any) -> float | None:
    """``float(x)`` when finite, else None."""
    try:
        value = float(x)
    except (TypeError, ValueError):
        return None
    return value if math.isfinite(value) else None


# ------------------------------------------------------------------------------ reading


def _checked(path: Path, recorded: Any, what: str, owner: Path) -> None:
    """Refuse a file whose sha256 differs from the one ``owner`` recorded for it."""
    if not path.is_file():
        raise InputError(f"{path}: not found ({owner.name} names it as its {what}; was the "
                         "output folder copied only in part?)")
    if recorded and sha256_of(path) != recorded:
        raise InputError(f"{path}: changed since {owner.name} was written (sha256 differs): "
                         "the folder does not hold one run's outputs (an interrupted or "
                         "mixed set; run the reconstruction again)")


def load_report_data(map_path: str | Path) -> ReportData:
    """The :class:`ReportData` of an output folder (or its ``map.json``), without the log and
    without refitting.

    Paths recorded in the files are relative to the map's folder, so the folder can be moved
    or opened from anywhere.  The files map.json was written with are checked by their sha256.
    A map fitted before report data existed, or without it, still gives a report: from the
    contact table beside it, without the pages that need the log.
    """
    from wholearm_tools._io import load_json, read_text_input
    from wholearm_tools.contact_table import read_contact_table
    from wholearm_tools.mapfile import read_map

    map_path = Path(map_path)
    if map_path.is_dir():
        map_path = map_path / "map.json"
    if not map_path.is_file():
        raise InputError(f"{map_path.parent}: no {map_path.name} (expected the output folder "
                         "of `wholearm reconstruct` or `wholearm fit`)")
    folder = map_path.parent
    surface_map = read_map(map_path)
    meta = surface_map.meta or {}
    outputs = meta.get("outputs") if isinstance(meta.get("outputs"), dict) else {}
    names = [n for n in outputs if n.endswith(".json") and "report_data" in n]
    data_name = names[0] if names else "report_data.json"
    data_path = folder / data_name
    if data_path.is_file():
        _checked(data_path, (outputs.get(data_name) or {}).get("sha256"), "report data",
                 map_path)
        doc = load_json(read_text_input(data_path, "report data"), str(data_path),
                        "report data")
        if not isinstance(doc, dict) or not isinstance(doc.get("contacts"), dict):
            raise InputError(f"{data_path}: malformed report data (no contacts entry)")
        table_path = folder / str(doc["contacts"].get("path", "contacts.csv"))
        _checked(table_path, doc["contacts"].get("sha256"), "contact table", data_path)
        return report_data_from_json(doc, surface_map, read_contact_table(table_path),
                                     source=str(data_path))
    # no report data: the contact table beside the map, or the one the map was fitted from
    candidates = [folder / "contacts.csv"]
    record = meta.get("input") if isinstance(meta.get("input"), dict) else {}
    if record.get("kind") == "contact table" and record.get("path"):
        candidates.insert(0, folder / str(record["path"]))
    table_path = next((p for p in candidates if p.is_file()), None)
    if table_path is None:
        raise InputError(f"{folder}: no report data and no contact table beside {map_path.name}"
                         "; run `wholearm report RUN.mcap` on the log instead")
    table = read_contact_table(table_path)
    run = RunInfo(source=str(record.get("path") or meta.get("source") or table_path.name),
                  kind=str(record.get("kind") or "log"), sha256=record.get("sha256"),
                  duration=finite_or_none(meta.get("duration")), planar=surface_map.planar)
    return ReportData(surface_map=surface_map, table=table, run=run,
                      fits=tuple(FitInfo(p.id) for p in surface_map.primitives))
