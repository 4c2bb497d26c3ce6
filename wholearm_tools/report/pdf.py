"""The PDF report of a reconstruction (matplotlib ``PdfPages``; pyvista for 3-D views).

``write_report(path, data)`` renders a :class:`~wholearm_tools.report.data.ReportData` (what an
output folder holds: map.json, contacts.csv, report_data.json) into an A4-landscape PDF,
atomically (a complete PDF or nothing).  Pages:

1. **Summary** — first the answer in plain words: for a well junction the main and lateral
   diameters, the angle between them and where the window is, each ± its 95 % half-width; for
   other scenes every surface found with its size ± 95 %; or why nothing could be fitted.  Then
   the run: input file and its sha256, duration, contacts, the torque source they were detected
   from, every parameter, tool version and date; notes and warnings; and a 3-D view (planar
   runs: the 2-D map).
2. **Map** — four views of the fitted surfaces (parallel projection, each with a scale bar,
   surfaces labelled ``#id`` in their fixed colours and named in the legend, the robot base with
   its axes), tip contacts as points and link contacts as segments coloured by P_T; planar
   runs: the 2-D drawing with the true surfaces dashed.
3. **Details**, flowing over as many pages as they fill: the junction's quantities (with truth
   and error when known), every parameter ± 95 %, the residual histograms, P_T over the
   exploration (the paper's Figure 4; runs with a log) and, with ground truth only, the
   accuracy of the primitives and of the contacts.

Numbers are printed to the digits their uncertainty supports (two significant digits of the
95 % half-width), never as "± 0.0" or "-0.0".  The same data give the same bytes on the same
machine and library versions (no creation date in the PDF; 3-D views come from the local
OpenGL implementation, so another Mesa version may change their pixels).
"""

from __future__ import annotations

import math
import os
import textwrap
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from wholearm_tools._io import atomic_path
from wholearm_tools.mesh.style import surface_colour, surface_label
from wholearm_tools.report.junction import JunctionSummary, junction_summary, main_bore
from wholearm_tools.report.metrics import AccuracyReport, evaluate, true_surfaces

PAGE_SIZE = (11.69, 8.27)            # A4 landscape, inches
MARGIN = 0.45                        # inches, every side
CMAP = "coolwarm"                    # P_T: blue = link body (0), red = tip (1)
HISTS_PER_ROW = 4
VIEWS = (("isometric", (1.0, -1.4, 0.9)), ("front (x–z)", (0.0, -1.0, 0.0)),
         ("side (y–z)", (1.0, 0.0, 0.0)), ("top (x–y)", (0.0, 0.0, 1.0)))
VIEW_SIZE = (800, 620)               # pixels of one rendered view
SIZE_KEYS = ("radius", "major_radius", "minor_radius", "half_angle")
MONO = "DejaVu Sans Mono"
MONO_WIDTH = 0.602                   # advance of one DejaVu Sans Mono glyph, in em


@dataclass(frozen=True, slots=True)
class ReportInfo:
    """What :func:`write_report` wrote: the file and the title of every page, in order."""

    path: Path
    pages: tuple[str, ...]
    accuracy: AccuracyReport | None
    junction: JunctionSummary | None

    @property
    def n_pages(self) -> int:
        return len(self.pages)


# ------------------------------------------------------------------------------ numbers


def _decimals(half: float, scale: float, lo: int = 0, hi: int = 4) -> int:
    """Decimals that show two significant digits of ``half * scale`` (within [lo, hi])."""
    h = abs(half * scale)
    if not math.isfinite(h) or h == 0.0:
        return lo
    return int(min(max(1 - math.floor(math.log10(h)), lo), hi))


def _num(x: float, dec: int) -> str:
    """``x`` with ``dec`` decimals, never ``-0``."""
    text = f"{x:.{dec}f}"
    if text.startswith("-") and float(text) == 0.0:
        text = text[1:]
    return text


def _sig2(h: float) -> str:
    """A half-width to two significant digits: fixed point when that stays readable
    (``0.0042``, ``12``), else scientific (``6.8e-09``)."""
    if not math.isfinite(h):
        return "–"
    if h == 0.0:
        return "0"
    if 1e-4 <= abs(h) < 1e4:
        return _num(h, max(1 - math.floor(math.log10(abs(h))), 0))
    return f"{h:.1e}"


def fmt_pm(value: float, half: float | None, *, scale: float = 1.0, unit: str = "",
           default_dec: int = 1, hi: int = 4) -> str:
    """``value ± half`` scaled to display units, to the digits the half-width supports
    (two significant digits of the half-width, the value to the same decimal, at most ``hi``
    decimals), e.g. ``320.0013 ± 0.0042 mm``; without a finite half-width the value alone
    (``default_dec`` decimals)."""
    unit = f" {unit}" if unit and unit != "°" else unit
    if half is None or not math.isfinite(half):
        return f"{_num(value * scale, default_dec)}{unit}"
    dec = _decimals(half, scale, 0, hi)
    return f"{_num(value * scale, dec)} ± {_sig2(abs(half) * scale)}{unit}"


def _detected(c: Any) -> str:
    """How many true contacts were detected: where some did not stop the arm (a physics run's
    slides and grazes, which joint positions cannot show), of the arm's stops against
    contact, with the contacts that held them and the touches that did not said apart."""
    if c.n_stopped == c.n_truth:
        return f"{c.n_matched} of {c.n_truth} true contacts detected ({c.n_false} false)"
    return (f"{c.n_stops_found} of the arm's {c.n_stops} stops against contact detected "
            f"({c.n_stopped} true contacts held them, {c.n_truth - c.n_stopped} more touches "
            f"did not stop it; {c.n_false} false detections)")


def _pct(x: float) -> str:
    return f"{100 * x:.0f} %" if math.isfinite(x) else "n/a"


def _opt(x: float | None, fmt: str, scale: float = 1.0) -> str:
    if x is None or not math.isfinite(x):
        return "–"
    text = fmt.format(x * scale)
    return text[1:] if text.startswith("-") and not any(c in "123456789" for c in text) \
        else text


def _placement_text(p: Any) -> str:
    """Where a line or plane lies: its distance from the robot base (± 95 %, from the point's
    half-widths along the normal) and its direction or normal."""
    point = np.asarray(p.params.get("point", ()), float)
    if p.kind == "line" and point.size == 2:
        d = np.asarray(p.params["direction"], float)
        normal = np.array([-d[1], d[0]]) / max(float(np.linalg.norm(d)), 1e-300)
        heading = math.degrees(math.atan2(d[1], d[0])) % 180.0
        orient = f"running at {_num(heading, 1)}° from x"
    elif p.kind == "plane" and point.size == 3:
        normal = np.asarray(p.params["normal"], float)
        normal = normal / max(float(np.linalg.norm(normal)), 1e-300)
        orient = "normal (" + ", ".join(_num(x, 3) for x in normal) + ")"
    else:
        return ""
    ci = np.asarray(p.ci95.get("point", np.full(point.shape, np.nan)), float) if p.ci95 \
        else np.full(point.shape, np.nan)
    half = float(np.sqrt(np.sum((normal * ci) ** 2))) if ci.shape == point.shape else math.nan
    dist = abs(float(normal @ point))
    return f"{fmt_pm(dist, half, scale=1e3, unit='mm')} from the robot base, {orient}"


def _size_text(p: Any) -> str:
    """Key size of a primitive with its 95 % half-width: diameters in mm, half-angle in °;
    for lines and planes, where they lie."""
    if p.kind in ("line", "plane"):
        return _placement_text(p)
    parts = []
    for k in SIZE_KEYS:
        if k not in p.params:
            continue
        v = float(p.params[k])
        half = p.ci95.get(k) if p.ci95 else None
        h = float(np.asarray(half)) if half is not None else float("nan")
        if k == "half_angle":
            parts.append("half-angle " + fmt_pm(math.degrees(v), math.degrees(h), unit="°"))
        else:
            name = {"radius": "Ø", "major_radius": "major Ø", "minor_radius": "minor Ø"}[k]
            parts.append(f"{name} " + fmt_pm(2 * v, 2 * h, scale=1e3, unit="mm"))
    return ", ".join(parts)


# ------------------------------------------------------------------------------ text


def _answer(data: Any, junction: JunctionSummary | None) -> list[str]:
    """The answer in plain words, one paragraph per item."""
    m = data.surface_map
    if junction is not None:
        j = junction
        mm = {"scale": 1e3, "unit": "mm"}
        out = [
            f"Well junction found. The main bore (surface #{j.main_id}) is "
            f"{fmt_pm(j.main_diameter.value, j.main_diameter.half95, **mm)} across; the lateral "
            f"branch (#{j.lateral_id}) is "
            f"{fmt_pm(j.lateral_diameter.value, j.lateral_diameter.half95, **mm)} across and "
            f"leaves the main bore at "
            f"{fmt_pm(j.angle_deg.value, j.angle_deg.half95, unit='°')} to its axis.",
            f"The window (where the lateral's axis crosses the main axis) is "
            f"{fmt_pm(j.window_position.value, j.window_position.half95, **mm)} along the main "
            f"bore from the robot base, at an azimuth of "
            f"{fmt_pm(j.window_azimuth_deg.value, j.window_azimuth_deg.half95, unit='°')} "
            "from the base x axis (around the main axis).",
        ]
        if math.isfinite(j.axis_offset.value) and j.axis_offset.value > 1e-3:
            out.append(f"The two axes miss each other by "
                       f"{fmt_pm(j.axis_offset.value, j.axis_offset.half95, **mm)}.")
        out.append("± = 95 % interval from the fits' covariances.")
        return out
    if not m.primitives:
        why = "; ".join(data.messages) or "no primitive explains the contacts"
        return [f"No surface could be fitted: {why}."]
    n = len(m.primitives)
    out = [f"{n} surface{'s' if n > 1 else ''} found (± = 95 % interval):"]
    for p in m.primitives:
        size = _size_text(p)
        sup = p.support.get("tip", 0) + p.support.get("link", 0)
        out.append(f"• {surface_label(p.id, p.kind)}: {size + ', ' if size else ''}"
                   f"from {sup} contacts, RMS residual {_sig2(p.rms_residual * 1e3)} mm")
    bore = main_bore(m.primitives) if not m.planar else None
    if bore is not None:
        out.append(f"Surface #{bore.id} is a bore around the robot base ({_size_text(bore)}); "
                   "no lateral branch was found.")
    return out


def _parameter_text(data: Any) -> list[str]:
    prm = data.parameters
    det = prm.get("detection") or {}
    settings = det.get("settings") or {}
    cls = prm.get("classification") or {}
    items = [f"B = {data.B:g} m (smallest expected curvature radius)",
             f"fit loss {prm.get('loss', '?')}",
             "classification " + ("causal (map up to each contact)" if prm.get("causal")
                                  else "with the whole run's swept map")]
    if cls.get("tip_threshold") is not None:
        items.append(f"tip if P_T ≥ {cls['tip_threshold']:g}, link if P_T ≤ "
                     f"{cls.get('link_threshold', float('nan')):g}")
    if settings:
        items.append(f"detection: stopped below {settings.get('k_velocity', '?')} σ of joint "
                     f"speed, loaded above {settings.get('k_torque', '?')} σ of torque, for "
                     f"≥ {settings.get('min_stop_time', '?')} s")
    return items


def summary_lines(data: Any, accuracy: AccuracyReport | None,
                  junction: JunctionSummary | None) -> list[str]:
    """Page one as plain text (also printed by ``wholearm report``)."""
    m = data.surface_map
    meta = m.meta or {}
    run = data.run
    table = data.table
    labels = np.asarray(table.label)
    n = len(labels)
    n_tip, n_link = int(np.sum(labels == "tip")), int(np.sum(labels == "link"))
    lines = [*_answer(data, junction), ""]
    record = meta.get("input") or {}
    sha = record.get("sha256") or run.sha256
    lines.append(f"Input: {run.source}" + (f" (sha256 {sha[:16]}…)" if sha else ""))
    if run.kind == "log":
        robot = f" '{run.robot_name}'" if run.robot_name else ""
        parts = [f"{run.duration:.1f} s" + (f" at {run.rate:.0f} Hz" if run.rate else "")]\
            if run.duration is not None else []
        parts.append(f"{'planar' if m.planar else 'spatial'} arm{robot}"
                     + (f", {run.dof} joints" if run.dof else ""))
        lines.append("Run: " + "; ".join(parts))
    else:
        lines.append(f"Fitted from a contact table ({run.kind}); no log behind this map")
    if run.torque_source:
        plain = {"commanded": "commanded torques (command topic)",
                 "measured": "measured effort (joint-state topic)",
                 "position": "commanded position × controller stiffness"}
        what = f"{run.torque_source}: {run.torque_note}" if run.torque_note else \
            plain.get(run.torque_source, run.torque_source)
        lines.append(f"Torque evidence: {what}")
    drives = []
    for what, unit in (("compliance", " at the effort limit"), ("backlash", "")):
        values = meta.get(f"joint_{what}") or []
        learned = bool(meta.get(f"joint_{what}_std"))
        if any(values) or learned:
            each = sorted(set(values)) if len(set(values)) == 1 else values
            drives.append(f"{what} " + ", ".join(f"{v * 1e3:.3g}" for v in each) + f" mrad{unit}"
                          + (" (learned from the map)" if learned else ""))
    if drives:
        lines.append("Transmissions: " + ", ".join(drives) + "; contacts at the links' angles")
    if run.ignored_joints:
        lines.append("Log joints off the arm's chain (not used): "
                     + ", ".join(run.ignored_joints))
    lines.append(f"Contacts: {n} (tip {n_tip}, link {n_link}, ambiguous {n - n_tip - n_link})")
    lab = np.asarray(table.label_map).astype(str)
    if n and np.all(lab != ""):
        lines.append(f"  refined by the fitted map: tip {int(np.sum(lab == 'tip'))}, link "
                     f"{int(np.sum(lab == 'link'))}, ambiguous {int(np.sum(lab == 'ambiguous'))}")
    p_link = np.asarray(table.p_link, dtype=float)
    group = np.isfinite(p_link) & (p_link < 1.0)
    if n and np.any(np.isfinite(p_link)):
        text = f"Links: {int(np.sum(p_link >= 1.0))} named by the joint signals alone"
        if np.any(group):
            text += (f", {int(np.sum(group))} left among the links of a rigid group (the "
                     f"named link's probability {p_link[group].min():.2f}-"
                     f"{p_link[group].max():.2f}")
            if np.all(table.link_by_map >= 0):      # fitted: the map may have moved some
                moved = int(np.sum(group & (table.link_by_map != table.link)))
                text += f"; the fitted map moved {moved}"
            text += ")"
        lines.append(text)
    lines.append("Parameters: " + "; ".join(_parameter_text(data)))
    tool = meta.get("tool") or {}
    if tool or meta.get("created"):
        lines.append(f"Written by {tool.get('name', 'wholearm_tools')} "
                     f"{tool.get('version', '')} on {meta.get('created', '?')}")
    if accuracy is not None:
        c = accuracy.classification
        lines += ["", "Against the simulator's ground truth: " + _detected(c) + "; "
                  f"link right {_pct(c.link_accuracy)}; tip/link right "
                  f"{_pct(c.class_accuracy)} of decided ({_pct(c.ambiguous_fraction)} "
                  f"ambiguous); {accuracy.n_found} of {len(accuracy.surfaces)} true surfaces "
                  f"found ({accuracy.n_touched} touched)."]
        sizes = [a for a in accuracy.primitives if a.size_error_pct is not None
                 and a.kind != "cone"]
        if sizes:
            worst = max(sizes, key=lambda a: abs(a.size_error_pct or 0.0))
            lines[-1] += (f" Largest size error {_opt(worst.size_error_pct, '{:+.2f}')} % "
                          f"(#{worst.primitive_id} {worst.kind}).")
    warnings = list(data.messages) if m.primitives else []
    unexplained = int(np.sum(np.asarray(table.primitive) < 0)) if n else 0
    if n and unexplained:
        warnings.append(f"{unexplained} contact(s) explained by no surface")
    if accuracy is not None:
        for s in accuracy.missed:
            warnings.append(f"true surface {s.truth_id} ({s.kind}, {s.n_truth_contacts} "
                            "contacts) not found")
        for a in accuracy.primitives:
            if a.truth_id is not None and not a.type_correct:
                warnings.append(f"#{a.primitive_id} is a {a.kind} but true surface "
                                f"{a.truth_id} is a {a.truth_kind}")
    if warnings:
        lines += ["", "Notes:"] + [f"! {w}" for w in warnings]
    return lines


# ------------------------------------------------------------------------------ layout


class _Flow:
    """Pages filled top to bottom: blocks of known height go on the current page when they
    fit and on a new page (same title, "continued") when they do not."""

    def __init__(self, title: str, subtitle: str = "") -> None:
        self.title, self.subtitle = title, subtitle
        self.pages: list[Any] = []
        self.new_page()

    @property
    def width(self) -> float:
        return PAGE_SIZE[0] - 2 * MARGIN

    def new_page(self) -> None:
        cont = " (continued)" if self.pages else ""
        self.fig = _page(self.title + cont, self.subtitle if not cont else "")
        self.pages.append(self.fig)
        self.y = 0.95 if self.subtitle and not cont else 0.75     # inches used from the top

    def room(self) -> float:
        return PAGE_SIZE[1] - 2 * MARGIN - self.y

    def take(self, height: float, *, min_height: float | None = None) -> tuple[float, float]:
        """Reserve ``height`` inches (on a new page if this one has less than
        ``min_height`` left); returns (top, height) in inches from the page top."""
        need = height if min_height is None else min_height
        if self.room() < need - 1e-9 and self.y > 1.0:
            self.new_page()
        height = min(height, self.room())
        top = MARGIN + self.y
        self.y += height
        return top, height

    def axes(self, height: float, left: float = 0.0, width: float | None = None,
             *, advance: bool = True) -> Any:
        top, h = self.take(height) if advance else (MARGIN + self.y, height)
        pw, ph = PAGE_SIZE
        w = self.width if width is None else width
        return self.fig.add_axes(((MARGIN + left) / pw, 1 - (top + h) / ph, w / pw, h / ph))

    def heading(self, text: str, keep: float = 1.0) -> None:
        """A section heading, on a new page unless ``keep`` inches follow it here."""
        size = 10.5
        lines = textwrap.wrap(text, int(self.width * 72 / (0.55 * size)))
        h = 0.22 + 0.2 * len(lines)
        top, _ = self.take(h, min_height=h + keep)
        self.fig.text(MARGIN / PAGE_SIZE[0], 1 - (top + 0.12) / PAGE_SIZE[1],
                      "\n".join(lines), fontsize=size, weight="bold", va="top")

    def text(self, lines: list[str], fontsize: float = 8.5, mono: bool = False) -> None:
        chars = int(self.width * 72 / (MONO_WIDTH * fontsize)) if mono else \
            int(self.width * 72 / (0.52 * fontsize))
        wrapped = [w for ln in lines for w in (textwrap.wrap(ln, chars) or [""])]
        line_h = fontsize * 1.45 / 72
        while wrapped:
            top, h = self.take(line_h * len(wrapped) + 0.1, min_height=line_h * 3)
            k = max(int((h - 0.1) / line_h), 1)
            self.fig.text(MARGIN / PAGE_SIZE[0], 1 - top / PAGE_SIZE[1],
                          "\n".join(wrapped[:k]), fontsize=fontsize, va="top",
                          family=MONO if mono else None, linespacing=1.35)
            wrapped = wrapped[k:]

    def table(self, header: list[str], rows: list[list[str]], widths: list[float],
              row_in: float = 0.21) -> None:
        """A table over the page width (``widths`` sum to 1), split over pages as needed."""
        while rows:
            fits = max(int(self.room() / row_in) - 1, 0)
            if fits < min(3, len(rows)):
                self.new_page()
                fits = max(int(self.room() / row_in) - 1, 1)
            chunk, rows = rows[:fits], rows[fits:]
            ax = self.axes((len(chunk) + 1) * row_in)
            ax.set_axis_off()
            _table(ax, header, chunk, widths)
            self.y += 0.12


def _page(title: str, subtitle: str = "") -> Any:
    from matplotlib.figure import Figure

    fig = Figure(figsize=PAGE_SIZE)
    x = MARGIN / PAGE_SIZE[0]
    fig.text(x, 1 - (MARGIN + 0.05) / PAGE_SIZE[1], title, fontsize=15, weight="bold",
             va="top")
    if subtitle:
        fig.text(x, 1 - (MARGIN + 0.5) / PAGE_SIZE[1], subtitle, fontsize=8.5, color="0.35",
                 va="top", wrap=True)
    return fig


def _table(ax: Any, header: list[str], rows: list[list[str]], widths: list[float]) -> None:
    tab = ax.table(cellText=rows, colLabels=header, colWidths=widths, bbox=(0, 0, 1, 1),
                   cellLoc="left", colLoc="left")
    tab.auto_set_font_size(False)
    tab.set_fontsize(8)
    for (r, _), cell in tab.get_celld().items():
        cell.set_linewidth(0.3)
        cell.PAD = 0.02
        if r == 0:
            cell.set_facecolor("#e8e8e8")
            cell.set_text_props(weight="bold")


# ------------------------------------------------------------------------------ 2-D map


def _link_contact_segments(data: Any) -> tuple[np.ndarray, np.ndarray]:
    """Short segments for link contacts: 30 % of the link, centred at the fitted contact
    position (latent t on the primitive that explains the contact; the link middle
    otherwise).  Returns ``(segments (K, 2, d), row index (K,))``."""
    table = data.table
    rows = np.flatnonzero(~np.asarray(table.used_as_tip))
    if rows.size == 0:
        return np.zeros((0, 2, table.dim)), rows
    a = np.asarray(table.seg_a)[rows]
    b = np.asarray(table.seg_b)[rows]
    t = np.full(rows.size, 0.5)
    prim_of = np.asarray(table.primitive)[rows]
    side = {f.id: f.free_side for f in data.fits}
    by_id = {p.id: p for p in data.surface_map.primitives}
    for pid in np.unique(prim_of[prim_of >= 0]):
        sel = prim_of == pid
        if int(pid) not in by_id:
            continue
        try:
            _, t[sel] = by_id[int(pid)].primitive.segment_signed_distance(
                a[sel], b[sel], free_side=side.get(int(pid), 1.0))
        except Exception:
            continue
    centre = a + t[:, None] * (b - a)
    half = 0.15 * (b - a)
    return np.stack([centre - half, centre + half], axis=1), rows


def _bounds(points: list[np.ndarray], pad: float = 0.05) -> tuple[np.ndarray, np.ndarray]:
    pts = np.concatenate([p.reshape(-1, p.shape[-1]) for p in points if p.size], axis=0)
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    span = max(float(np.max(hi - lo)), 0.1)
    return lo - pad * span, hi + pad * span


def _clip_line(p0: np.ndarray, d: np.ndarray, lo: np.ndarray, hi: np.ndarray
               ) -> np.ndarray | None:
    """Segment of the infinite 2-D line inside the box [lo, hi]."""
    s0, s1 = -np.inf, np.inf
    for k in range(2):
        if abs(d[k]) < 1e-12:
            if not lo[k] <= p0[k] <= hi[k]:
                return None
            continue
        a, b = (lo[k] - p0[k]) / d[k], (hi[k] - p0[k]) / d[k]
        s0, s1 = max(s0, min(a, b)), min(s1, max(a, b))
    if s0 >= s1:
        return None
    return np.stack([p0 + s0 * d, p0 + s1 * d])


def draw_planar_map(ax: Any, data: Any, *, legend_cols: int = 2) -> None:
    """Draw a planar reconstruction on a matplotlib axis: surfaces in their fixed colours
    (legend below the axes, with their sizes), tip contacts as points and link contacts as
    segments coloured by P_T, true surfaces dashed, the robot base."""
    import matplotlib as mpl
    from matplotlib.collections import LineCollection

    from wholearm_tools.mesh import polyline

    table = data.table
    cmap = mpl.colormaps[CMAP]
    norm = mpl.colors.Normalize(0.0, 1.0)
    curves = []
    for p in data.surface_map.primitives:
        try:
            curves.append((p, polyline(p.kind, p.params, p.extent, 0.005)))
        except Exception:
            continue
    segs, seg_rows = _link_contact_segments(data)
    tips = np.flatnonzero(np.asarray(table.used_as_tip))
    arm = [np.asarray(table.seg_a), np.asarray(table.seg_b), np.zeros((1, 2))]
    lo, hi = _bounds([c for _, c in curves] + arm)
    truth = data.run.truth
    if truth is not None:
        first = True
        for s in true_surfaces(truth):
            prm = s.params
            if s.kind == "line":
                pts = _clip_line(np.asarray(prm["point"], float),
                                 np.asarray(prm["direction"], float), lo, hi)
            elif s.kind == "circle":
                phi = np.linspace(0.0, 2.0 * np.pi, 181)
                pts = np.asarray(prm["center"], float) + float(prm["radius"]) * np.stack(
                    [np.cos(phi), np.sin(phi)], axis=1)
            else:
                pts = None
            if pts is not None:
                ax.plot(pts[:, 0], pts[:, 1], "--", color="0.55", lw=1.0,
                        label="true surface" if first else None, zorder=1)
                first = False
    for p, pts in curves:
        size = _size_text(p)
        ax.plot(pts[:, 0], pts[:, 1], "-", lw=2.6, color=surface_colour(p.id),
                label=surface_label(p.id, p.kind) + (f": {size}" if size else ""), zorder=2,
                alpha=0.9)
    p_tip = np.asarray(table.p_tip)
    if len(segs):
        lc = LineCollection(segs[:, :, :2], cmap=cmap, norm=norm, linewidths=2.2, zorder=4)
        lc.set_array(p_tip[seg_rows])
        ax.add_collection(lc)
        ax.plot([], [], "-", color="0.3", lw=2.2, label="link contact")
    ax.scatter(np.asarray(table.tip_center)[tips, 0], np.asarray(table.tip_center)[tips, 1],
               c=p_tip[tips], cmap=cmap, norm=norm, s=22, edgecolors="k", linewidths=0.4,
               zorder=5, label="tip contact")
    ax.plot([0.0], [0.0], "k^", ms=8, zorder=6, label="robot base")
    ax.set_xlim(lo[0], hi[0])
    ax.set_ylim(lo[1], hi[1])
    ax.set_aspect("equal", adjustable="box")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.grid(True, lw=0.3, alpha=0.6)
    if legend_cols:
        ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.14), fontsize=7, frameon=False,
                  ncols=legend_cols)


# ------------------------------------------------------------------------------ 3-D map


@dataclass(frozen=True, slots=True)
class View:
    """One rendered view: title, RGB image (H, W, 3) and metres per pixel (parallel
    projection, for the scale bar)."""

    title: str
    image: np.ndarray
    metres_per_pixel: float


def render_views(data: Any, *, size: tuple[int, int] = VIEW_SIZE,
                 views: tuple[tuple[str, tuple[float, float, float]], ...] = VIEWS
                 ) -> list[View]:
    """Off-screen pyvista renders of a spatial map (parallel projection), one per view."""
    os.environ.setdefault("VTK_DEFAULT_OPENGL_WINDOW", "vtkEGLRenderWindow")
    import matplotlib as mpl
    import pyvista as pv

    from wholearm_tools.mesh import primitive_mesh

    table = data.table
    meshes = []
    for p in data.surface_map.primitives:
        try:
            m = primitive_mesh(p, resolution=0.01)
        except Exception:
            continue
        if m.n_vertices:
            faces = np.hstack([np.full((len(m.triangles), 1), 3), m.triangles]).ravel()
            mesh = pv.PolyData(np.asarray(m.vertices), faces)
            anchor = m.vertices[int(np.argmin(np.linalg.norm(
                m.vertices - m.vertices.mean(axis=0), axis=1)))]
            meshes.append((p, mesh, anchor))
    p_tip = np.asarray(table.p_tip)
    tips = np.flatnonzero(np.asarray(table.used_as_tip))
    segs, seg_rows = _link_contact_segments(data)
    lut = mpl.colormaps[CMAP]
    lo, hi = _bounds([np.asarray(table.tip_center), np.asarray(table.seg_b), np.zeros((1, 3))],
                     0.0)
    axis_len = 0.08 * max(float(np.max(hi - lo)), 0.2)
    pl = pv.Plotter(off_screen=True, window_size=list(size))
    try:
        pl.set_background("white")
        for p, mesh, _ in meshes:
            pl.add_mesh(mesh, color=surface_colour(p.id), opacity=0.5, smooth_shading=True,
                        show_edges=False)
            # the patch's border in its colour: a surface seen edge-on stays visible
            pl.add_mesh(mesh.extract_feature_edges(boundary_edges=True, feature_edges=False,
                                                   manifold_edges=False,
                                                   non_manifold_edges=False),
                        color=surface_colour(p.id), line_width=2)
        if tips.size:
            cloud = pv.PolyData(np.asarray(table.tip_center)[tips])
            cloud["P_T"] = p_tip[tips]
            pl.add_mesh(cloud, scalars="P_T", cmap=lut, clim=(0.0, 1.0),
                        render_points_as_spheres=True, point_size=9, show_scalar_bar=False)
        if len(segs):
            pts = segs.reshape(-1, 3)
            lines = np.hstack([np.full((len(segs), 1), 2),
                               np.arange(2 * len(segs)).reshape(-1, 2)]).ravel()
            poly = pv.PolyData(pts, lines=lines)
            poly.cell_data["P_T"] = p_tip[seg_rows]
            pl.add_mesh(poly, scalars="P_T", cmap=lut, clim=(0.0, 1.0), line_width=5,
                        show_scalar_bar=False)
        if meshes:
            pl.add_point_labels(np.array([a for _, _, a in meshes]),
                                [f"#{p.id}" for p, _, _ in meshes], font_size=18,
                                text_color="black", shape_opacity=0.6, shape_color="white",
                                always_visible=True, show_points=False)
        pl.add_mesh(pv.Sphere(radius=0.015, center=(0.0, 0.0, 0.0)), color="black")
        for axis, colour in zip(np.eye(3), ("red", "green", "blue"), strict=True):
            pl.add_mesh(pv.Arrow(start=(0.0, 0.0, 0.0), direction=axis, scale=axis_len,
                                 tip_radius=0.08, shaft_radius=0.025), color=colour)
        pl.enable_parallel_projection()
        out = []
        for title, direction in views:          # one scene, one camera per view
            pl.camera_position = _camera(data, direction)
            pl.reset_camera()           # fit every actor (meshes and contacts) in the view
            pl.camera.zoom(1.15)
            mpp = 2.0 * float(pl.camera.parallel_scale) / size[1]
            img = pl.screenshot(return_img=True)
            out.append(View(title, _crop(np.asarray(img)[:, :, :3]), mpp))
    finally:
        pl.close()
    return out


def _crop(img: np.ndarray, pad: int = 12) -> np.ndarray:
    """The image cut to its non-white content plus ``pad`` pixels (the scale is kept)."""
    ink = np.any(img < 250, axis=2)
    rows, cols = np.flatnonzero(ink.any(axis=1)), np.flatnonzero(ink.any(axis=0))
    if rows.size == 0:
        return img
    r0, r1 = max(rows[0] - pad, 0), min(rows[-1] + pad + 1, img.shape[0])
    c0, c1 = max(cols[0] - pad, 0), min(cols[-1] + pad + 1, img.shape[1])
    return img[r0:r1, c0:c1]


def _camera(data: Any, direction: tuple[float, float, float]) -> list[tuple[float, ...]]:
    table = data.table
    pts = [np.asarray(table.tip_center), np.asarray(table.seg_a), np.asarray(table.seg_b),
           np.zeros((1, 3))]
    lo, hi = _bounds(pts, 0.0)
    centre = 0.5 * (lo + hi)
    dist = 1.9 * max(float(np.linalg.norm(hi - lo)), 0.2)
    d = np.asarray(direction, float)
    d = d / np.linalg.norm(d)
    up = (0.0, 1.0, 0.0) if abs(d[2]) > 0.9 else (0.0, 0.0, 1.0)
    return [tuple(centre + dist * d), tuple(centre), up]


def _nice_length(x: float) -> float:
    """The largest 1, 2 or 5 × 10^k not above ``x``."""
    k = math.floor(math.log10(x))
    for m in (5.0, 2.0, 1.0):
        if m * 10.0 ** k <= x:
            return m * 10.0 ** k
    return 10.0 ** k


def _show_view(ax: Any, view: View, title: str | None = None) -> None:
    """A rendered view with its scale bar (surfaces are named by the page's legend)."""
    h, w = view.image.shape[:2]
    ax.imshow(view.image, interpolation="none")
    ax.set_title(title or view.title, fontsize=9)
    ax.set_xticks([])
    ax.set_yticks([])
    for spine in ax.spines.values():
        spine.set_color("0.85")
    length = _nice_length(0.3 * w * view.metres_per_pixel)
    px = length / view.metres_per_pixel
    x0, y0 = w - 12 - px, h - 14
    ax.plot([x0, x0 + px], [y0, y0], "-", color="k", lw=2.5, solid_capstyle="butt")
    ax.text(x0 + px / 2, y0 - 6, f"{length * 1e3:g} mm" if length < 1 else f"{length:g} m",
            ha="center", va="bottom", fontsize=8)
    ax.set_xlim(-0.5, w - 0.5)
    ax.set_ylim(h - 0.5, -0.5)


LEGEND_SIZE = 7.5


def _legend_labels(data: Any, width: float) -> list[str]:
    """Every surface's label and size, wrapped to ``width`` inches of legend."""
    chars = max(int((width - 0.4) * 72 / (0.55 * LEGEND_SIZE)), 12)
    return ["\n".join(textwrap.wrap(f"{surface_label(p.id, p.kind)}  {_size_text(p)}", chars,
                                    subsequent_indent="  "))
            for p in data.surface_map.primitives]


def _legend_height(data: Any, width: float) -> float:
    """Inches the surface legend takes at ``width``."""
    lines = sum(label.count("\n") + 1 for label in _legend_labels(data, width))
    return 0.35 + 0.16 * lines if lines else 0.0


def _surface_legend(fig: Any, data: Any, loc: tuple[float, float], width: float) -> None:
    """The surfaces named in their fixed colours, with their sizes, wrapped to ``width``
    inches."""
    from matplotlib.patches import Patch

    handles = [Patch(color=surface_colour(p.id), alpha=0.75, label=label)
               for p, label in zip(data.surface_map.primitives, _legend_labels(data, width),
                                   strict=True)]
    if handles:
        fig.legend(handles=handles, loc="upper left", bbox_to_anchor=loc, fontsize=LEGEND_SIZE,
                   frameon=False, title="surfaces (± 95 %)", title_fontsize=8,
                   alignment="left", borderaxespad=0.0)


def _ptip_colorbar(fig: Any, rect: tuple[float, float, float, float]) -> None:
    import matplotlib as mpl

    cax = fig.add_axes(rect)
    cb = fig.colorbar(mpl.cm.ScalarMappable(norm=mpl.colors.Normalize(0, 1),
                                            cmap=mpl.colormaps[CMAP]), cax=cax)
    cb.set_label("tip probability $P_T$ of contacts", fontsize=8)
    cb.ax.tick_params(labelsize=7)


# ------------------------------------------------------------------------------ pages


def _summary_page(data: Any, title: str, accuracy: AccuracyReport | None,
                  junction: JunctionSummary | None, views: list[View] | None) -> Any:
    meta = data.surface_map.meta or {}
    tool = meta.get("tool") or {}
    fig = _page(title, f"{tool.get('name', 'wholearm_tools')} {tool.get('version', '')} "
                       f"reconstruction report · {meta.get('created', '')}")
    pw, ph = PAGE_SIZE
    text_w = 5.5                                        # inches of the text column
    answer = _answer(data, junction)
    rest = summary_lines(data, accuracy, junction)[len(answer) + 1:]
    y = MARGIN + 0.95
    chars = int((text_w - 0.2) * 72 / (0.53 * 10.5))
    ans = "\n\n".join("\n".join(textwrap.wrap(p, chars)) for p in answer)
    fig.text((MARGIN + 0.1) / pw, 1 - (y + 0.1) / ph, ans, fontsize=10.5, va="top",
             linespacing=1.3,
             bbox={"boxstyle": "round,pad=0.5", "fc": "#fff6d8", "ec": "#c9a227"})
    y += (ans.count("\n") + 1) * 10.5 * 1.3 / 72 + 0.55
    chars = int(text_w * 72 / (MONO_WIDTH * 8))
    body = [w for ln in rest for w in (textwrap.wrap(ln, chars, subsequent_indent="  ")
                                       or [""])]
    room = int((PAGE_SIZE[1] - MARGIN - y) / (8 * 1.2 / 72))
    if len(body) > room:
        body = [*body[:room - 1], "… (more in the pages that follow)"]
    fig.text(MARGIN / pw, 1 - y / ph, "\n".join(body), fontsize=8, family=MONO, va="top",
             linespacing=1.2)
    left = MARGIN + text_w + 0.3
    width = pw - left - MARGIN - 0.55
    top = MARGIN + 0.95
    legend_h = _legend_height(data, pw - left - MARGIN)
    height = ph - top - MARGIN - legend_h
    if data.surface_map.planar:
        ax = fig.add_axes(((left + 0.45) / pw, (MARGIN + 1.3) / ph, (width - 0.45) / pw,
                           (ph - top - MARGIN - 1.6) / ph))
        draw_planar_map(ax, data, legend_cols=1)
        ax.set_title("map (true surfaces dashed)", fontsize=9)
    elif views:
        ax = fig.add_axes((left / pw, (MARGIN + legend_h) / ph, width / pw, height / ph))
        _show_view(ax, views[0], f"map, {views[0].title} view")
        _surface_legend(fig, data, (left / pw, (MARGIN + legend_h) / ph), pw - left - MARGIN)
    if data.surface_map.planar or views:
        _ptip_colorbar(fig, ((pw - MARGIN - 0.35) / pw, 0.35, 0.1 / pw, 0.35))
    return fig


def _map_pages(data: Any, views: list[View] | None) -> list[Any]:
    pw, ph = PAGE_SIZE
    if data.surface_map.planar:
        fig = _page("Map", "fitted surfaces over their extents in their colours; tip contacts "
                    "as points, link contacts as segments, coloured by P_T; true surfaces "
                    "dashed; ▲ robot base")
        ax = fig.add_axes((0.07, 0.2, 0.80, 0.66))
        draw_planar_map(ax, data)
        _ptip_colorbar(fig, (0.92, 0.3, 0.1 / pw, 0.4))
        return [fig]
    fig = _page("Map", "parallel projections; surfaces labelled #id in their colours; contacts "
                "coloured by P_T (points: tip, segments: link); robot base black, with its x, "
                "y, z axes")
    legend_w = 2.2
    top = MARGIN + 0.95
    w = (pw - 2 * MARGIN - legend_w - 0.15) / 2
    h = (ph - top - MARGIN - 0.25) / 2
    for k, view in enumerate(views or []):
        col, row = k % 2, k // 2
        rect = ((MARGIN + col * (w + 0.15)) / pw, (MARGIN + (1 - row) * (h + 0.25)) / ph,
                w / pw, h / ph)
        _show_view(fig.add_axes(rect), view)
    x = pw - MARGIN - legend_w + 0.1
    _surface_legend(fig, data, (x / pw, 1 - top / ph), pw - MARGIN - x)
    _ptip_colorbar(fig, ((x + 0.1) / pw, 0.12, 0.1 / pw, 0.35))
    return [fig]


def _primitive_rows(data: Any) -> list[list[str]]:
    """One row per parameter; each component to the digits its own half-width supports."""
    rows = []
    for p in data.surface_map.primitives:
        first = True
        for k, v in p.params.items():
            arr = np.atleast_1d(np.asarray(v, float))
            half = np.atleast_1d(np.asarray(p.ci95.get(k, np.full(arr.shape, np.nan)), float)
                                 if p.ci95 else np.full(arr.shape, np.nan))
            if half.shape != arr.shape:
                half = np.full(arr.shape, np.nan)
            if k == "half_angle":
                scale, unit, dflt, hi = 180.0 / math.pi, "°", 2, 4
            elif k in ("direction", "normal", "axis"):
                scale, unit, dflt, hi = 1.0, "", 4, 6
            else:
                scale, unit, dflt, hi = 1e3, "mm", 1, 4
            vs = ", ".join(_num(x * scale, _decimals(h, scale, 1, hi) if np.isfinite(h)
                                else dflt) for x, h in zip(arr, half, strict=True))
            hs = ", ".join(_sig2(h * scale) for h in half)
            if np.asarray(v).ndim:
                vs, hs = f"({vs})", f"({hs})"
            rows.append([surface_label(p.id, p.kind) if first else "",
                         f"{k}{' [' + unit + ']' if unit else ''}", vs, hs,
                         f"{p.support.get('tip', 0)} / {p.support.get('link', 0)}" if first
                         else "", _num(p.rms_residual * 1e3, 3) if first else ""])
            first = False
    return rows


def _junction_rows(j: JunctionSummary) -> list[list[str]]:
    rows = []
    for _, label, e in j.rows():
        scale, unit = (1e3, "mm") if e.unit == "m" else (1.0, "°")
        rows.append([label, fmt_pm(e.value, e.half95, scale=scale, unit=unit),
                     _opt(e.truth, "{:.2f} " + unit, scale),
                     "–" if e.error is None else
                     fmt_pm(e.error, float("nan"), scale=scale, unit=unit, default_dec=3)])
    return rows


def _residuals(data: Any, pid: int) -> tuple[np.ndarray, np.ndarray]:
    fit = next((f for f in data.fits if f.id == pid), None)
    if fit is not None and (fit.tip_residuals.size or fit.link_residuals.size):
        return fit.tip_residuals, fit.link_residuals
    table = data.table
    sel = np.asarray(table.primitive) == pid
    r = np.asarray(table.residual, float)
    tip = np.asarray(table.used_as_tip)
    return r[sel & tip], r[sel & ~tip]


def _detail_pages(data: Any, junction: JunctionSummary | None,
                  accuracy: AccuracyReport | None) -> list[Any]:
    """The junction's details, every parameter, the residuals, the P_T replay and the
    accuracy against ground truth, flowing over as many pages as they fill."""
    flow = _Flow("Details", "parameters ± 95 % half-widths (weighted Gauss–Newton "
                 "covariance at the stated kinematic error, or at the fit's residuals where "
                 "larger); support = tip / link contacts; robot base frame, millimetres and "
                 "degrees")
    if junction is not None:
        flow.heading(f"Well junction: main bore #{junction.main_id}, lateral "
                     f"#{junction.lateral_id} (± = 95 % from {junction.samples} Monte Carlo "
                     "draws of the fit covariances)", keep=1.9)
        flow.table(["quantity", "estimate ± 95 %", "truth", "error"],
                   _junction_rows(junction), [0.34, 0.30, 0.18, 0.18])
        ref = ", ".join(_num(x, 3) for x in junction.reference)
        flow.text([
            "Window position: distance along the main axis, from the robot base's projection "
            "on it, to where the lateral's axis crosses it (closest approach of the two axes). "
            "Window azimuth: angle of the lateral's direction around the main axis "
            f"(right-handed) from the reference direction ({ref}), the base x axis projected "
            "perpendicular to the main axis. Angle: between the main axis (from the base to "
            "the window) and the lateral axis (into the branch)."], fontsize=8)
    rows = _primitive_rows(data)
    flow.heading("Primitives", keep=1.2)
    if rows:
        flow.table(["surface", "parameter", "value", "± 95 %", "tip / link", "rms [mm]"],
                   rows, [0.13, 0.13, 0.34, 0.26, 0.07, 0.07])
    else:
        flow.text(["(no primitive)"])
    prims = data.surface_map.primitives
    if prims:
        flow.heading("Fit residuals: distance to the fitted surface minus the contact radius "
                     "(negative = penetration)", keep=2.1)
        gap = 0.45
        w = (flow.width - gap * (HISTS_PER_ROW - 1)) / HISTS_PER_ROW
        for start in range(0, len(prims), HISTS_PER_ROW):
            flow.take(0.0, min_height=2.1)
            for i, p in enumerate(prims[start:start + HISTS_PER_ROW]):
                ax = flow.axes(1.55, left=0.1 + i * (w + gap), width=w - 0.1, advance=False)
                _residual_hist(ax, data, p)
            flow.take(2.1)
    if data.ptip_history is not None and data.ptip_times is not None:
        flow.heading("Tip probability over the exploration: causal replay (paper, Fig. 4), each "
                     "contact's P_T with the swept map up to each time; ● at the contact, ■ "
                     "final offline value", keep=2.8)
        top, h = flow.take(4.4, min_height=2.8)
        pw, ph = PAGE_SIZE
        ax = flow.fig.add_axes(((MARGIN + 0.6) / pw, 1 - (top + h - 0.45) / ph,
                                (flow.width - 0.7) / pw, (h - 0.75) / ph))
        _ptip_axes(ax, data)
    if accuracy is not None:
        _accuracy_blocks(flow, accuracy)
    return flow.pages


def _residual_hist(ax: Any, data: Any, p: Any) -> None:
    from matplotlib.ticker import MaxNLocator

    rt, rl = _residuals(data, p.id)
    rt, rl = rt[np.isfinite(rt)] * 1e3, rl[np.isfinite(rl)] * 1e3
    both = np.concatenate([rt, rl])
    if both.size:
        span = max(float(np.max(np.abs(both))), 1e-3)
        bins = np.linspace(-span, span, 21)
        ax.hist([rt, rl], bins=bins, stacked=True, color=["tab:red", "tab:blue"],
                label=[f"tip ({rt.size})", f"link ({rl.size})"])
        ax.legend(fontsize=6.5)
    else:
        ax.text(0.5, 0.5, "no residuals", transform=ax.transAxes, ha="center")
    ax.set_title(f"{surface_label(p.id, p.kind)}: rms {_num(p.rms_residual * 1e3, 3)} mm",
                 fontsize=8.5, color=surface_colour(p.id))
    ax.xaxis.set_major_locator(MaxNLocator(5, symmetric=True))
    ax.yaxis.set_major_locator(MaxNLocator(4, integer=True))
    ax.set_xlabel("residual [mm]", fontsize=7.5)
    ax.set_ylabel("contacts", fontsize=7.5)
    ax.tick_params(labelsize=7)


def _ptip_axes(ax: Any, data: Any) -> None:
    table = data.table
    n = len(table)
    lo_t, hi_t = data.thresholds
    times = np.asarray(data.ptip_times)
    hist = np.asarray(data.ptip_history)
    ax.axhspan(100 * lo_t, 100 * hi_t, color="0.92", zorder=0)
    ax.text(0.005, 50 * (lo_t + hi_t), "ambiguous", fontsize=8, color="0.4", va="center",
            transform=ax.get_yaxis_transform())
    ax.set_xlim(float(times[0]), float(times[-1]) + 0.01 * float(times[-1] - times[0]))
    if n:
        truth_tip = None
        if data.run.truth is not None:
            from wholearm_tools.contacts import pair_events

            idx = pair_events(table.t, table.t_end, table.link, data.run.truth,
                              at=table.t_settle)
            truth_tip = np.where(idx >= 0, data.run.truth.is_tip[np.maximum(idx, 0)], -1)
        final = np.asarray(table.p_tip)
        for k in range(n):
            live = ~np.isnan(hist[k])
            if truth_tip is not None:
                colour = {1: "tab:red", 0: "tab:blue"}.get(int(truth_tip[k]), "0.5")
            else:
                colour = {"tip": "tab:red", "link": "tab:blue"}.get(str(table.label[k]), "0.5")
            if live.any():
                ax.plot(times[live], 100 * hist[k, live], "-", color=colour, lw=0.8, alpha=0.7)
                ax.plot([times[live][0]], [100 * hist[k, live][0]], "o", ms=3, color=colour)
            ax.plot([times[-1]], [100 * final[k]], "s", ms=4, color=colour)
        key = ("true tip/joint", "true body", "not matched") if truth_tip is not None else \
            ("labelled tip", "labelled link", "ambiguous")
        for c, lab in zip(("tab:red", "tab:blue", "0.5"), key, strict=True):
            ax.plot([], [], "-", color=c, label=lab)
        ax.legend(loc="lower right", bbox_to_anchor=(1.0, 1.0), fontsize=8, ncols=3,
                  frameon=False)
    else:
        ax.text(0.5, 0.5, "no contacts", transform=ax.transAxes, ha="center")
    ax.set_xlabel("time [s]", fontsize=8)
    ax.set_ylabel("tip probability $P_T$ [%]", fontsize=8)
    ax.tick_params(labelsize=7.5)
    ax.set_ylim(-3, 103)
    ax.grid(True, lw=0.3)


def _accuracy_blocks(flow: _Flow, acc: AccuracyReport) -> None:
    flow.heading("Accuracy against ground truth: primitives (each matched to the true surface "
                 "most of its contacts touched, else the nearest; size = radius, cone: "
                 "half-angle; (n) = supporting contacts)", keep=1.2)
    rows = []
    for a in acc.primitives:
        is_angle = a.size_name == "half_angle"
        unit_scale, unit = (1.0, "°") if is_angle else (1e3, " mm")
        rows.append([
            f"{surface_label(a.primitive_id, a.kind)} ({a.n_support})",
            "none" if a.truth_id is None else f"{a.truth_id} {a.truth_kind} ({a.matched_by})",
            "–" if a.truth_id is None else ("right" if a.type_correct else "WRONG"),
            _opt(a.size_fit, "{:.2f}" + unit, unit_scale),
            _opt(a.size_true, "{:.2f}" + unit, unit_scale),
            "–" if a.size_error is None else
            f"{_opt(a.size_error, '{:+.3f}' + unit, unit_scale)} "
            f"({_opt(a.size_error_pct, '{:+.2f}')} %)",
            _opt(a.axis_angle_deg, "{:.3f}°"),
            _opt(a.position_error, "{:.2f} mm", 1e3),
            f"{_opt(a.surface_rms, '{:.2f}', 1e3)} / {_opt(a.surface_max, '{:.2f}', 1e3)} mm",
        ])
    if rows:
        flow.table(["primitive", "true surface", "type", "size fit", "size true", "error",
                    "axis err", "position err", "surface RMS / max"], rows,
                   [0.13, 0.14, 0.06, 0.09, 0.09, 0.16, 0.08, 0.10, 0.15])
    else:
        flow.text(["(no primitives)"])
    srows = [[f"{s.truth_id}", s.kind, str(s.n_truth_contacts),
              ("found by " + ", ".join(f"#{i}" for i in s.found_by)) if s.found else
              ("MISSED" if s.touched else "not touched")] for s in acc.surfaces]
    if srows:
        flow.heading("True surfaces", keep=1.0)
        flow.table(["true surface", "type", "true contacts", "status"], srows,
                   [0.15, 0.15, 0.15, 0.55])
    c = acc.classification
    flow.heading("Accuracy against ground truth: contacts (detections paired with true contacts "
                 "by time; truth 'tip' = tip or joint sphere, 'body' = side of the link)",
                 keep=2.95)
    cm_map = acc.classification_map
    text = [
        f"detected contacts        {c.n_detected}",
        f"true contacts            {c.n_truth}",
        f"paired                   {c.n_matched}",
        f"false detections         {c.n_false}",
        f"missed true contacts     {c.n_missed}",
        f"stops of the arm found   {c.n_stops_found} of {c.n_stops} "
        f"(held by {c.n_stopped} contacts)",
        f"link identified right    {_pct(c.link_accuracy)} ({c.link_correct}/{c.n_matched})",
        f"tip/link labels right    {_pct(c.class_accuracy)} of {c.n_decided} decided",
        f"ambiguous                {_pct(c.ambiguous_fraction)}",
        f"Brier score of P_T       {_opt(c.brier, '{:.3f}')}",
        *([f"refined by the map:      {_pct(cm_map.class_accuracy)} right of "
           f"{cm_map.n_decided} decided,",
           f"                         {_pct(cm_map.ambiguous_fraction)} ambiguous, "
           f"Brier {_opt(cm_map.brier, '{:.3f}')}"] if cm_map is not None else [])]
    top, h = flow.take(2.95, min_height=2.95)
    pw, ph = PAGE_SIZE
    fig = flow.fig
    fig.text(MARGIN / pw, 1 - (top + 0.1) / ph, "\n".join(text), fontsize=8, family=MONO,
             va="top", linespacing=1.35)
    ax = fig.add_axes(((MARGIN + 4.5) / pw, 1 - (top + h - 0.45) / ph, 2.4 / pw,
                       (h - 0.8) / ph))
    cm = np.asarray(c.confusion)
    ax.imshow(cm, cmap="Blues", vmin=0, vmax=max(int(cm.max()), 1), aspect="auto")
    for (r, k), v in np.ndenumerate(cm):
        ax.text(k, r, str(v), ha="center", va="center", fontsize=11,
                color="white" if v > 0.6 * max(int(cm.max()), 1) else "black")
    ax.set_xticks(range(3), ["tip", "link", "ambiguous"], fontsize=7.5)
    ax.set_yticks(range(2), ["tip / joint", "body"], fontsize=7.5)
    ax.set_xlabel("predicted label", fontsize=8)
    ax.set_ylabel("truth", fontsize=8)
    ax.set_title("confusion matrix", fontsize=9)
    ax = fig.add_axes(((MARGIN + 7.8) / pw, 1 - (top + h - 0.45) / ph, 2.7 / pw,
                       (h - 0.8) / ph))
    ok = np.asarray(c.bin_count) > 0
    ax.plot([0, 1], [0, 1], ":", color="0.5", label="perfect calibration")
    counts = np.asarray(c.bin_count)[ok]
    ax.scatter(np.asarray(c.bin_mean_p)[ok], np.asarray(c.bin_tip_fraction)[ok],
               s=20 + 180 * counts / max(int(counts.max(initial=1)), 1), color="tab:red",
               zorder=3, label="observed (area ∝ contacts)")
    for x, y, nb in zip(np.asarray(c.bin_mean_p)[ok], np.asarray(c.bin_tip_fraction)[ok],
                        np.asarray(c.bin_count)[ok], strict=True):
        ax.annotate(f"n={nb}", (x, y), textcoords="offset points", xytext=(4, -10),
                    fontsize=6.5)
    ax.set_xticks(np.asarray(c.bins))
    ax.tick_params(labelsize=7)
    ax.set_xlim(0, 1)
    ax.set_ylim(-0.03, 1.03)
    ax.set_xlabel("mean P_T in bin", fontsize=8)
    ax.set_ylabel("fraction truly tip / joint", fontsize=8)
    ax.set_title("P_T calibration", fontsize=9)
    ax.grid(True, lw=0.3)
    ax.legend(fontsize=6.5, loc="lower right")


# ------------------------------------------------------------------------------ writer


def _as_report_data(data: Any, ptip_steps: int) -> Any:
    """A :class:`~wholearm_tools.report.data.ReportData` from itself or a Reconstruction."""
    from wholearm_tools.report.data import ReportData, report_data_from_reconstruction

    if isinstance(data, ReportData):
        return data
    return report_data_from_reconstruction(data, steps=ptip_steps)


def build_pages(data: Any, *, title: str | None = None
                ) -> tuple[list[tuple[str, Any]], AccuracyReport | None,
                           JunctionSummary | None]:
    """All report pages as ``(title, matplotlib Figure)``, with the accuracy and junction
    records they show."""
    accuracy = evaluate(data)
    junction = junction_summary(data)
    title = title or f"Reconstruction report — {data.run.name}"
    views = None if data.surface_map.planar or (not data.surface_map.primitives and \
        not len(data.table)) else render_views(data)
    pages: list[tuple[str, Any]] = [("Summary", _summary_page(data, title, accuracy, junction,
                                                             views))]
    pages += [("Map", f) for f in _map_pages(data, views)]
    pages += [("Details", f) for f in _detail_pages(data, junction, accuracy)]
    return pages, accuracy, junction


def write_report(path: str | os.PathLike[str], data: Any, *, title: str | None = None,
                 ptip_steps: int = 60) -> ReportInfo:
    """Write the PDF report to ``path`` atomically.

    Parameters
    ----------
    path : output PDF file (its folder must exist)
    data : ReportData (``wholearm_tools.report.data.load_report_data`` of an output folder) or a
        Reconstruction (``wholearm_tools.pipeline.reconstruct``; the P_T replay is computed)
    title : page-one title (default: from the input's file name)
    ptip_steps : number of replay times of the P_T-over-time page (Reconstruction only)

    Returns
    -------
    ReportInfo (path, page titles, accuracy and junction records)
    """
    from matplotlib.backends.backend_pdf import PdfPages

    if ptip_steps < 2:
        raise ValueError(f"ptip_steps must be >= 2, got {ptip_steps}")
    path = Path(path)
    with atomic_path(path, ".pdf") as tmp:   # fails fast on a missing folder
        data = _as_report_data(data, ptip_steps)
        meta = {"Title": title or f"wholearm report {data.run.name}",
                "Creator": "wholearm_tools", "Producer": "wholearm_tools (matplotlib)",
                "CreationDate": None}
        pages, accuracy, junction = build_pages(data, title=title)
        with PdfPages(tmp, metadata=meta) as pdf:
            for _, fig in pages:
                pdf.savefig(fig)
    return ReportInfo(path, tuple(name for name, _ in pages), accuracy, junction)
