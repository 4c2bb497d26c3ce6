"""The PDF accuracy report of a reconstruction (matplotlib ``PdfPages``; pyvista for 3-D views).

``write_report(path, rec)`` writes, atomically (a complete PDF or nothing):

1. **Summary** — run, duration, contacts and their tip/link/ambiguous split, B, the primitives
   with type and key size, headline accuracy (runs with ground truth), the junction box (maps
   with two cylinders), warnings; and the map picture.
2. **Map** — planar runs: the 2-D drawing (fitted primitives over their extents, tip contacts as
   points, link contacts as short segments along the link at the fitted contact position, all
   coloured by P_T; true surfaces dashed).  Spatial runs: four off-screen pyvista views of the
   fitted meshes with tip contacts (spheres) and link contacts (segments) coloured by P_T.
3. **Primitives** — parameters ± 95 % half-widths, support, RMS residual (continued over more
   pages when long).
4. **P_T over the exploration** — the paper's Figure 4: causal replay of every contact's P_T.
5. **Residuals** — histogram per primitive (tip and link residuals).
6. With ground truth only: **accuracy of the primitives** (parameter errors, surface deviation,
   surfaces found/missed) and **accuracy of the contacts** (detection, link identification,
   confusion matrix, P_T calibration).
7. Maps with two cylinders: **well junction** (diameters, inter-axis angle, window position and
   azimuth, each ± 95 %, with truth and error when known).

Determinism: the PDF's ``CreationDate`` is omitted and the Monte Carlo seed is fixed, so the same
reconstruction gives the same bytes on the same machine and library versions (3-D views come
from the local OpenGL implementation; another Mesa version may change their pixels).
"""

from __future__ import annotations

import contextlib
import math
import os
import textwrap
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from wholearm_tools._io import atomic_path
from wholearm_tools.report.junction import JunctionSummary, junction_summary, main_bore
from wholearm_tools.report.metrics import AccuracyReport, evaluate, true_surfaces

PAGE_SIZE = (11.69, 8.27)            # A4 landscape, inches
CMAP = "coolwarm"                    # P_T: blue = link body (0), red = tip (1)
ROWS_PER_TABLE_PAGE = 26
HISTS_PER_PAGE = 6
VIEWS = (("isometric", (1.0, -1.4, 0.9)), ("front (x–z)", (0.0, -1.0, 0.0)),
         ("side (y–z)", (1.0, 0.0, 0.0)), ("top (x–y)", (0.0, 0.0, 1.0)))
WRAP = 76                           # characters per summary line
SIZE_KEYS = ("radius", "major_radius", "minor_radius", "half_angle")


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


# ------------------------------------------------------------------------------ helpers


def _colours() -> list[Any]:
    import matplotlib as mpl

    return list(mpl.colormaps["tab10"].colors)


def _fmt_len(x: float) -> str:
    return f"{x * 1e3:.1f} mm" if abs(x) < 1.0 else f"{x:.3f} m"


def _key_size(p: Any) -> str:
    parts = []
    for k in SIZE_KEYS:
        if k in p.params:
            v = float(p.params[k])
            if k == "half_angle":
                parts.append(f"half-angle {math.degrees(v):.1f}°")
            else:
                half = p.ci95.get(k) if p.ci95 else None
                pm = f" ± {float(np.asarray(half)) * 2e3:.1f}" if half is not None and \
                    np.isfinite(np.asarray(half, float)).all() else ""
                name = {"radius": "Ø", "major_radius": "major Ø", "minor_radius": "minor Ø"}[k]
                parts.append(f"{name} {v * 2e3:.1f}{pm} mm")
    return ", ".join(parts)


def _link_contact_segments(rec: Any) -> tuple[np.ndarray, np.ndarray]:
    """Short segments for link contacts: 30 % of the link, centred at the fitted contact
    position (latent t on the primitive that explains the contact; the link middle
    otherwise).  Returns ``(segments (K, 2, d), row index (K,))``."""
    table = rec.table
    rows = np.flatnonzero(~np.asarray(table.used_as_tip))
    if rows.size == 0:
        return np.zeros((0, 2, table.dim)), rows
    a = np.asarray(table.seg_a)[rows]
    b = np.asarray(table.seg_b)[rows]
    t = np.full(rows.size, 0.5)
    prim_of = np.asarray(table.primitive)[rows]
    fits = rec.fits or ()
    by_id = {p.id: p for p in rec.surface_map.primitives}
    for pid in np.unique(prim_of[prim_of >= 0]):
        sel = prim_of == pid
        free_side = float(getattr(fits[pid], "free_side", 1.0)) if pid < len(fits) else 1.0
        with contextlib.suppress(Exception):   # a drawing aid only: keep the link middle
            _, t[sel] = by_id[int(pid)].primitive.segment_signed_distance(
                a[sel], b[sel], free_side=free_side)
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


# ----------------------------------------------------------------------------- 2-D map


def draw_planar_map(ax: Any, rec: Any, *, legend: bool = True, colorbar: bool = True) -> None:
    """Draw a planar reconstruction on a matplotlib axis (see the module docstring)."""
    import matplotlib as mpl
    from matplotlib.collections import LineCollection

    from wholearm_tools.mesh import polyline

    table = rec.table
    cmap = mpl.colormaps[CMAP]
    norm = mpl.colors.Normalize(0.0, 1.0)
    colours = _colours()
    curves = []
    for p in rec.surface_map.primitives:
        try:
            curves.append((p, polyline(p.kind, p.params, p.extent, 0.005)))
        except Exception:
            continue
    segs, seg_rows = _link_contact_segments(rec)
    tips = np.flatnonzero(np.asarray(table.used_as_tip))
    arm = [np.asarray(table.seg_a), np.asarray(table.seg_b), np.zeros((1, 2))]
    lo, hi = _bounds([c for _, c in curves] + arm)
    truth = rec.run.truth
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
    for i, (p, pts) in enumerate(curves):
        ax.plot(pts[:, 0], pts[:, 1], "-", lw=2.4, color=colours[i % len(colours)],
                label=f"#{p.id} {p.kind}", zorder=2, alpha=0.85)
    p_tip = np.asarray(table.p_tip)
    if len(segs):
        lc = LineCollection(segs[:, :, :2], cmap=cmap, norm=norm, linewidths=2.2, zorder=4)
        lc.set_array(p_tip[seg_rows])
        ax.add_collection(lc)
        ax.plot([], [], "-", color="0.3", lw=2.2, label="link contact")
    sc = ax.scatter(np.asarray(table.tip_center)[tips, 0], np.asarray(table.tip_center)[tips, 1],
                    c=p_tip[tips], cmap=cmap, norm=norm, s=22, edgecolors="k", linewidths=0.4,
                    zorder=5, label="tip contact")
    ax.plot([0.0], [0.0], "k^", ms=8, zorder=6, label="robot base")
    ax.set_xlim(lo[0], hi[0])
    ax.set_ylim(lo[1], hi[1])
    ax.set_aspect("equal", adjustable="box")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.grid(True, lw=0.3, alpha=0.6)
    if legend:
        ax.legend(loc="upper left", bbox_to_anchor=(1.02 if not colorbar else 1.25, 1.0),
                  fontsize=7, frameon=False)
    if colorbar:
        cb = ax.figure.colorbar(mpl.cm.ScalarMappable(norm=norm, cmap=cmap), ax=ax,
                                fraction=0.04, pad=0.02)
        cb.set_label("tip probability $P_T$")
    del sc


# ----------------------------------------------------------------------------- 3-D map


def render_views(rec: Any, *, size: tuple[int, int] = (900, 700),
                 views: tuple[tuple[str, tuple[float, float, float]], ...] = VIEWS
                 ) -> list[tuple[str, np.ndarray]]:
    """Off-screen pyvista renders ``(title, RGB image (H, W, 3) uint8)`` of a spatial map."""
    os.environ.setdefault("VTK_DEFAULT_OPENGL_WINDOW", "vtkEGLRenderWindow")
    import matplotlib as mpl
    import pyvista as pv

    from wholearm_tools.mesh import primitive_mesh

    table = rec.table
    colours = _colours()
    meshes = []
    for p in rec.surface_map.primitives:
        try:
            m = primitive_mesh(p, resolution=0.01)
        except Exception:
            continue
        if m.n_vertices:
            faces = np.hstack([np.full((len(m.triangles), 1), 3), m.triangles]).ravel()
            meshes.append((p, pv.PolyData(np.asarray(m.vertices), faces)))
    p_tip = np.asarray(table.p_tip)
    tips = np.flatnonzero(np.asarray(table.used_as_tip))
    segs, seg_rows = _link_contact_segments(rec)
    lut = mpl.colormaps[CMAP]
    out = []
    for title, direction in views:
        pl = pv.Plotter(off_screen=True, window_size=list(size))
        pl.set_background("white")
        for i, (p, mesh) in enumerate(meshes):
            pl.add_mesh(mesh, color=colours[i % len(colours)], opacity=0.45,
                        smooth_shading=True, show_edges=False, label=f"#{p.id} {p.kind}")
        if tips.size:
            cloud = pv.PolyData(np.asarray(table.tip_center)[tips])
            cloud["P_T"] = p_tip[tips]
            pl.add_mesh(cloud, scalars="P_T", cmap=lut, clim=(0.0, 1.0),
                        render_points_as_spheres=True, point_size=11, show_scalar_bar=False)
        if len(segs):
            pts = segs.reshape(-1, 3)
            lines = np.hstack([np.full((len(segs), 1), 2),
                               np.arange(2 * len(segs)).reshape(-1, 2)]).ravel()
            poly = pv.PolyData(pts, lines=lines)
            poly.cell_data["P_T"] = p_tip[seg_rows]
            pl.add_mesh(poly, scalars="P_T", cmap=lut, clim=(0.0, 1.0), line_width=5,
                        show_scalar_bar=False)
        pl.add_mesh(pv.Sphere(radius=0.015, center=(0.0, 0.0, 0.0)), color="black")
        pl.show_axes()
        pl.camera_position = _camera(rec, direction)
        pl.reset_camera()               # fit every actor (meshes and contacts) in the view
        pl.camera.zoom(1.1)
        img = pl.screenshot(return_img=True)
        pl.close()
        out.append((title, np.asarray(img)[:, :, :3]))
    return out


def _camera(rec: Any, direction: tuple[float, float, float]) -> list[tuple[float, ...]]:
    table = rec.table
    pts = [np.asarray(table.tip_center), np.asarray(table.seg_a), np.asarray(table.seg_b),
           np.zeros((1, 3))]
    lo, hi = _bounds(pts, 0.0)
    centre = 0.5 * (lo + hi)
    dist = 1.9 * max(float(np.linalg.norm(hi - lo)), 0.2)
    d = np.asarray(direction, float)
    d = d / np.linalg.norm(d)
    up = (0.0, 1.0, 0.0) if abs(d[2]) > 0.9 else (0.0, 0.0, 1.0)
    return [tuple(centre + dist * d), tuple(centre), up]


def _show_image(ax: Any, img: np.ndarray, title: str) -> None:
    ax.imshow(img, interpolation="lanczos")
    ax.set_title(title, fontsize=9)
    ax.set_axis_off()


def _ptip_colorbar(fig: Any, rect: tuple[float, float, float, float]) -> None:
    import matplotlib as mpl

    cax = fig.add_axes(rect)
    cb = fig.colorbar(mpl.cm.ScalarMappable(norm=mpl.colors.Normalize(0, 1),
                                            cmap=mpl.colormaps[CMAP]), cax=cax)
    cb.set_label("tip probability $P_T$", fontsize=8)
    cb.ax.tick_params(labelsize=7)


# ----------------------------------------------------------------------------- summary


def _map_label_line(table: Any) -> list[str]:
    """Page-one line with the labels refined by the fitted map (none before fitting)."""
    lab = np.asarray(table.label_map).astype(str)
    if len(lab) == 0 or np.any(lab == ""):
        return []
    return [f"  refined by the fitted map: tip {int(np.sum(lab == 'tip'))}, link "
            f"{int(np.sum(lab == 'link'))}, ambiguous {int(np.sum(lab == 'ambiguous'))}"]


def summary_lines(rec: Any, accuracy: AccuracyReport | None,
                  junction: JunctionSummary | None) -> list[str]:
    """The text of page one (also printed by the CLI)."""
    m = rec.surface_map
    table = rec.table
    labels = np.asarray(table.label)
    n = len(labels)
    n_tip, n_link = int(np.sum(labels == "tip")), int(np.sum(labels == "link"))
    n_amb = n - n_tip - n_link
    kind = "planar" if m.planar else "spatial"
    lines = [*textwrap.wrap(f"Run: {rec.run.source}", WRAP, subsequent_indent="     "),
             f"{kind} arm, {rec.run.robot.dof} joints; log {rec.run.log.duration:.1f} s "
             f"at {rec.run.log.rate:.0f} Hz",
             f"B = {rec.params.B:g} m (smallest expected curvature radius)"
             + ("; causal classification" if rec.params.causal else ""),
             f"Contacts: {n}  (tip {n_tip}, link {n_link}, ambiguous {n_amb})",
             *_map_label_line(table),
             "", f"Primitives found: {len(m.primitives)}"]
    shown = m.primitives[:10]
    for p in shown:
        size = _key_size(p)
        sup = f"{p.support.get('tip', 0)} tip + {p.support.get('link', 0)} link"
        lines.append(f"  #{p.id} {p.kind:<8} {size + ';' if size else ''} {sup}, "
                     f"rms {p.rms_residual * 1e3:.2f} mm")
    if len(m.primitives) > len(shown):
        lines.append(f"  … {len(m.primitives) - len(shown)} more (see the primitives table)")
    bore = main_bore(m.primitives) if junction is None and not m.planar else None
    if bore is not None:
        lines += ["", *textwrap.wrap(f"Bore: #{bore.id} cylinder around the robot base, "
                                     f"{_key_size(bore)}; no lateral branch found", WRAP,
                                     subsequent_indent="  ")]
    unexplained = int(np.sum(np.asarray(table.primitive) < 0)) if n else 0
    if accuracy is not None:
        c = accuracy.classification
        lines += ["", "Accuracy against ground truth:",
                  f"  contacts detected {c.n_matched} of {c.n_truth} true "
                  f"({c.n_false} false, {c.n_missed} missed)",
                  f"  link identified right: {_pct(c.link_accuracy)}",
                  f"  tip/link labels right: {_pct(c.class_accuracy)} of decided "
                  f"({_pct(c.ambiguous_fraction)} ambiguous)",
                  *([f"  refined by the map: {_pct(cm.class_accuracy)} of decided "
                     f"({_pct(cm.ambiguous_fraction)} ambiguous)"]
                    if (cm := accuracy.classification_map) is not None else []),
                  f"  true surfaces found: {accuracy.n_found} of {len(accuracy.surfaces)} "
                  f"({accuracy.n_touched} touched by the arm)"]
        untouched = [f"{s.truth_id} ({s.kind})" for s in accuracy.surfaces if not s.touched]
        if untouched:
            lines += textwrap.wrap("never touched: " + ", ".join(untouched), WRAP,
                                   initial_indent="  ", subsequent_indent="    ")
        sizes = [a for a in accuracy.primitives if a.size_error_pct is not None
                 and a.kind != "cone"]
        if sizes:
            worst = max(sizes, key=lambda a: abs(a.size_error_pct or 0.0))
            lines.append(f"  worst size error: {worst.size_error_pct:+.1f} % (#{worst.primitive_id}"
                         f" {worst.kind})")
        rms = [a.surface_rms for a in accuracy.primitives if a.surface_rms is not None
               and a.truth_id is not None]
        if rms:
            lines.append(f"  surface deviation: RMS up to {max(rms) * 1e3:.1f} mm")
    warnings = list(rec.messages)
    if n and unexplained:
        warnings.append(f"{unexplained} contact(s) explained by no primitive")
    if not m.primitives:
        warnings.append("no primitive could be fitted")
    if accuracy is not None:
        for s in accuracy.missed:
            warnings.append(f"true surface {s.truth_id} ({s.kind}, {s.n_truth_contacts} "
                            "contacts) not found")
        wrong = [a for a in accuracy.primitives if a.truth_id is not None and not a.type_correct]
        for a in wrong:
            warnings.append(f"#{a.primitive_id} is a {a.kind} but true surface {a.truth_id} "
                            f"is a {a.truth_kind}")
    if warnings:
        lines += ["", "Warnings:"]
        for w in warnings[:8]:
            lines += textwrap.wrap(w, WRAP, initial_indent="  ! ", subsequent_indent="    ")
        if len(warnings) > 8:
            lines.append(f"  ! … {len(warnings) - 8} more")
    return lines


def junction_lines(j: JunctionSummary) -> list[str]:
    """Junction box text: one line per quantity, value ± 95 % (truth)."""
    out = [f"Well junction: main bore #{j.main_id}, lateral #{j.lateral_id}"]
    for key, label, e in j.rows():
        if key == "axis_offset":
            continue
        out.append(f"  {label:<32} {_est(e)}")
    return out


def _est(e: Any, with_truth: bool = True) -> str:
    if e.unit == "m":
        scale, unit, dec = 1e3, "mm", 1
    else:
        scale, unit, dec = 1.0, "°", 1
    s = f"{e.value * scale:.{dec}f}"
    if math.isfinite(e.half95):
        s += f" ± {e.half95 * scale:.{dec}f}"
    s += f" {unit}"
    if with_truth and e.truth is not None:
        s += f"   (true {e.truth * scale:.{dec}f}, error {e.error * scale:+.{dec}f})"
    return s


def _pct(x: float) -> str:
    return f"{100 * x:.0f} %" if math.isfinite(x) else "n/a"


# ----------------------------------------------------------------------------- pages


def _page(title: str, subtitle: str = "") -> Any:
    from matplotlib.figure import Figure

    fig = Figure(figsize=PAGE_SIZE)
    fig.text(0.04, 0.955, title, fontsize=15, weight="bold", va="top")
    if subtitle:
        fig.text(0.04, 0.915, subtitle, fontsize=9, color="0.35", va="top")
    return fig


def _summary_page(rec: Any, title: str, accuracy: AccuracyReport | None,
                  junction: JunctionSummary | None, views: list[tuple[str, np.ndarray]] | None
                  ) -> Any:
    fig = _page(title, "wholearm_tools accuracy report — summary")
    text = "\n".join(summary_lines(rec, accuracy, junction))
    fig.text(0.04, 0.88, text, fontsize=8.6, family="DejaVu Sans Mono", va="top", ha="left")
    if junction is not None:
        box = "\n".join(junction_lines(junction))
        fig.text(0.04, 0.05, box, fontsize=8.6, family="DejaVu Sans Mono", va="bottom",
                 ha="left", bbox={"boxstyle": "round,pad=0.6", "fc": "#fff6d8", "ec": "#c9a227"})
    if rec.surface_map.planar:
        ax = fig.add_axes((0.53, 0.08, 0.40, 0.80))
        draw_planar_map(ax, rec, legend=False, colorbar=True)
        ax.set_title("map (true surfaces dashed)", fontsize=9)
    elif views:
        ax = fig.add_axes((0.50, 0.10, 0.45, 0.78))
        _show_image(ax, views[0][1], f"map, {views[0][0]} view (contacts coloured by P_T)")
        _ptip_colorbar(fig, (0.965, 0.3, 0.01, 0.4))
    return fig


def _map_pages(rec: Any, views: list[tuple[str, np.ndarray]] | None) -> list[Any]:
    if rec.surface_map.planar:
        fig = _page("Map", "fitted primitives over their extents; tip contacts as points, link "
                    "contacts as segments, coloured by P_T; true surfaces dashed; ▲ robot base")
        ax = fig.add_axes((0.06, 0.07, 0.62, 0.80))
        draw_planar_map(ax, rec)
        return [fig]
    fig = _page("Map", "fitted primitive meshes; tip contacts as spheres, link contacts as "
                "segments, coloured by P_T; black sphere = robot base")
    rects = ((0.03, 0.46, 0.45, 0.41), (0.50, 0.46, 0.45, 0.41),
             (0.03, 0.02, 0.45, 0.41), (0.50, 0.02, 0.45, 0.41))
    for rect, (name, img) in zip(rects, views or [], strict=False):
        _show_image(fig.add_axes(rect), img, name)
    _ptip_colorbar(fig, (0.965, 0.3, 0.01, 0.4))
    return [fig]


def _primitive_rows(rec: Any) -> list[list[str]]:
    rows = []
    for p in rec.surface_map.primitives:
        first = True
        for k, v in p.params.items():
            arr = np.asarray(v, float)
            half = np.asarray(p.ci95.get(k, np.full(arr.shape, np.nan)), float) if p.ci95 \
                else np.full(arr.shape, np.nan)
            if k in ("half_angle",):
                val, hw, unit = np.degrees(arr), np.degrees(half), "°"
            elif k in ("direction", "normal", "axis"):
                val, hw, unit = arr, half, ""
            else:
                val, hw, unit = arr * 1e3, half * 1e3, "mm"
            fmt = "{:.4f}" if unit == "" else "{:.1f}"
            vs = ", ".join(fmt.format(x) for x in np.atleast_1d(val))
            hs = ", ".join(fmt.format(x) if np.isfinite(x) else "–" for x in np.atleast_1d(hw))
            if arr.ndim:
                vs, hs = f"({vs})", f"({hs})"
            rows.append([f"#{p.id}" if first else "", p.kind if first else "",
                         f"{k}{' [' + unit + ']' if unit else ''}", vs, hs,
                         f"{p.support.get('tip', 0)} / {p.support.get('link', 0)}" if first
                         else "", f"{p.rms_residual * 1e3:.2f}" if first else ""])
            first = False
    return rows


def _table_pages(title: str, subtitle: str, header: list[str], rows: list[list[str]],
                 col_widths: list[float]) -> list[Any]:
    pages = []
    chunks = [rows[i:i + ROWS_PER_TABLE_PAGE] for i in range(0, len(rows), ROWS_PER_TABLE_PAGE)]
    for i, chunk in enumerate(chunks or [[]]):
        fig = _page(title + (f" ({i + 1}/{len(chunks)})" if len(chunks) > 1 else ""), subtitle)
        ax = fig.add_axes((0.04, 0.05, 0.92, 0.82))
        ax.set_axis_off()
        if chunk:
            _table(ax, header, chunk, col_widths)
        else:
            ax.text(0.0, 1.0, "(none)", va="top")
        pages.append(fig)
    return pages


def _table(ax: Any, header: list[str], rows: list[list[str]], col_widths: list[float],
           row_in: float = 0.24) -> None:
    """A plain table at the top of ``ax``, every row ``row_in`` inches high."""
    fig = ax.figure
    row_h = row_in / (ax.get_position().height * fig.get_size_inches()[1])
    tab = ax.table(cellText=rows, colLabels=header, colWidths=col_widths, loc="upper left",
                   cellLoc="left", colLoc="left")
    tab.auto_set_font_size(False)
    tab.set_fontsize(8)
    for (r, _), cell in tab.get_celld().items():
        cell.set_height(row_h)
        cell.set_linewidth(0.3)
        if r == 0:
            cell.set_facecolor("#e8e8e8")
            cell.set_text_props(weight="bold")


def _ptip_page(rec: Any, steps: int) -> Any:
    from wholearm_tools.classify import tip_probability_history

    fig = _page("Tip probability over the exploration",
                "causal replay (paper, Fig. 4): each contact's P_T with the swept map up to "
                "each time; ● at the contact, ■ final offline value")
    ax = fig.add_axes((0.07, 0.10, 0.88, 0.76))
    contacts, log = rec.contacts, rec.run.log
    n = len(contacts)
    meta = getattr(rec.classification, "meta", {}) or {}
    lo_t, hi_t = float(meta.get("link_threshold", 0.3)), float(meta.get("tip_threshold", 0.7))
    ax.axhspan(100 * lo_t, 100 * hi_t, color="0.92", zorder=0)
    ax.text(float(log.t[0]), 50 * (lo_t + hi_t), " ambiguous", fontsize=8, color="0.4",
            va="center")
    if n:
        times = np.linspace(float(log.t[0]), float(log.t[-1]), steps)
        hist = tip_probability_history(rec.run, contacts, rec.params.B, times)
        truth_tip = None
        if rec.run.truth is not None:
            from wholearm_tools.report.metrics import match_contacts

            idx = match_contacts(np.asarray(rec.table.t), rec.run.truth)
            truth_tip = np.where(idx >= 0, rec.run.truth.is_tip[np.maximum(idx, 0)], -1)
        final = np.asarray(rec.classification.p_tip)
        for k in range(n):
            live = ~np.isnan(hist[k])
            if truth_tip is not None:
                colour = {1: "tab:red", 0: "tab:blue"}.get(int(truth_tip[k]), "0.5")
            else:
                colour = {"tip": "tab:red", "link": "tab:blue"}.get(str(rec.table.label[k]),
                                                                   "0.5")
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
    ax.set_xlabel("time [s]")
    ax.set_ylabel("tip probability $P_T$ [%]")
    ax.set_ylim(-3, 103)
    ax.grid(True, lw=0.3)
    return fig


def _residuals(rec: Any, pid: int) -> tuple[np.ndarray, np.ndarray]:
    fits = rec.fits or ()
    if pid < len(fits) and fits[pid] is not None:
        f = fits[pid]
        return (np.asarray(getattr(f, "tip_residuals", np.zeros(0)), float),
                np.asarray(getattr(f, "link_residuals", np.zeros(0)), float))
    table = rec.table
    sel = np.asarray(table.primitive) == pid
    r = np.asarray(table.residual, float)
    tip = np.asarray(table.used_as_tip)
    return r[sel & tip], r[sel & ~tip]


def _residual_pages(rec: Any) -> list[Any]:
    prims = rec.surface_map.primitives
    pages = []
    chunks = [prims[i:i + HISTS_PER_PAGE] for i in range(0, len(prims), HISTS_PER_PAGE)]
    for ci, chunk in enumerate(chunks or [()]):
        fig = _page("Fit residuals" + (f" ({ci + 1}/{len(chunks)})" if len(chunks) > 1 else ""),
                    "distance to the fitted surface minus the contact radius, per primitive "
                    "(negative = penetration)")
        if not chunk:
            fig.text(0.5, 0.5, "no primitives", ha="center")
        for i, p in enumerate(chunk):
            ax = fig.add_axes((0.07 + 0.32 * (i % 3), 0.53 - 0.45 * (i // 3), 0.25, 0.32))
            rt, rl = _residuals(rec, p.id)
            rt, rl = rt[np.isfinite(rt)] * 1e3, rl[np.isfinite(rl)] * 1e3
            both = np.concatenate([rt, rl])
            if both.size:
                span = max(float(np.max(np.abs(both))), 1e-3)
                bins = np.linspace(-span, span, 21)
                ax.hist([rt, rl], bins=bins, stacked=True, color=["tab:red", "tab:blue"],
                        label=[f"tip ({rt.size})", f"link ({rl.size})"])
                ax.legend(fontsize=7)
            else:
                ax.text(0.5, 0.5, "no residuals", transform=ax.transAxes, ha="center")
            ax.set_title(f"#{p.id} {p.kind}: rms {p.rms_residual * 1e3:.2f} mm", fontsize=9)
            ax.set_xlabel("residual [mm]", fontsize=8)
            ax.set_ylabel("contacts", fontsize=8)
            ax.tick_params(labelsize=7)
        pages.append(fig)
    return pages


def _opt(x: float | None, fmt: str, scale: float = 1.0) -> str:
    return "–" if x is None or not math.isfinite(x) else fmt.format(x * scale)


def _accuracy_pages(rec: Any, acc: AccuracyReport) -> list[Any]:
    header = ["primitive", "true surface", "type", "size fit", "size true", "error",
              "axis err", "position err", "surface RMS / max"]
    rows = []
    for a in acc.primitives:
        is_angle = a.size_name == "half_angle"
        unit_scale, unit = (1.0, "°") if is_angle else (1e3, " mm")
        rows.append([
            f"#{a.primitive_id} {a.kind} ({a.n_support})",
            "none" if a.truth_id is None else f"{a.truth_id} {a.truth_kind} ({a.matched_by})",
            "–" if a.truth_id is None else ("right" if a.type_correct else "WRONG"),
            _opt(a.size_fit, "{:.1f}" + unit, unit_scale),
            _opt(a.size_true, "{:.1f}" + unit, unit_scale),
            "–" if a.size_error is None else
            f"{a.size_error * unit_scale:+.1f}{unit} ({_opt(a.size_error_pct, '{:+.1f}')} %)",
            _opt(a.axis_angle_deg, "{:.2f}°"),
            _opt(a.position_error, "{:.1f} mm", 1e3),
            f"{_opt(a.surface_rms, '{:.1f}', 1e3)} / {_opt(a.surface_max, '{:.1f}', 1e3)} mm",
        ])
    widths = [0.13, 0.14, 0.06, 0.09, 0.09, 0.14, 0.08, 0.10, 0.13]
    fig = _page("Accuracy: primitives",
                "each primitive is matched to the true surface most of its contacts touched "
                "(else the nearest); size = radius (cone: half-angle)\nsurface deviation = "
                "distance of the fitted surface, over its extent, to the true surface; "
                "(n) = supporting contacts")
    ax = fig.add_axes((0.04, 0.42, 0.92, 0.44))
    ax.set_axis_off()
    if rows:
        _table(ax, header, rows[:12], widths)
    else:
        ax.text(0, 1, "no primitives", va="top")
    ax2 = fig.add_axes((0.04, 0.04, 0.92, 0.33))
    ax2.set_axis_off()
    ax2.set_title("True surfaces", fontsize=10, loc="left")
    srows = [[f"{s.truth_id}", s.kind, str(s.n_truth_contacts),
              ("found by " + ", ".join(f"#{i}" for i in s.found_by)) if s.found else
              ("MISSED" if s.touched else "not touched")] for s in acc.surfaces]
    if srows:
        _table(ax2, ["true surface", "type", "true contacts", "status"], srows[:8],
               [0.12, 0.12, 0.12, 0.3])
    pages = [fig]

    c = acc.classification
    fig = _page("Accuracy: contacts and classification",
                "detections paired with true contacts by time; truth 'tip' = tip or joint "
                "sphere, 'body' = side of the link")
    ax = fig.add_axes((0.11, 0.10, 0.34, 0.50))
    cm = np.asarray(c.confusion)
    ax.imshow(cm, cmap="Blues", vmin=0, vmax=max(int(cm.max()), 1))
    for (r, k), v in np.ndenumerate(cm):
        ax.text(k, r, str(v), ha="center", va="center", fontsize=13,
                color="white" if v > 0.6 * max(int(cm.max()), 1) else "black")
    ax.set_xticks(range(3), ["tip", "link", "ambiguous"])
    ax.set_yticks(range(2), ["tip / joint", "body"])
    ax.set_xlabel("predicted label")
    ax.set_ylabel("truth")
    ax.set_title("confusion matrix", fontsize=10)
    text = "\n".join([
        f"detected contacts        {c.n_detected}",
        f"true contacts            {c.n_truth}",
        f"paired                   {c.n_matched}",
        f"false detections         {c.n_false}",
        f"missed true contacts     {c.n_missed}",
        f"link identified right    {_pct(c.link_accuracy)} ({c.link_correct}/{c.n_matched})",
        f"tip/link labels right    {_pct(c.class_accuracy)} of {c.n_decided} decided",
        f"ambiguous                {_pct(c.ambiguous_fraction)}",
        f"Brier score of P_T       {_opt(c.brier, '{:.3f}')}",
        *([f"refined by the map:      {_pct(cm.class_accuracy)} right of {cm.n_decided} "
           f"decided,", f"                         {_pct(cm.ambiguous_fraction)} ambiguous, "
           f"Brier {_opt(cm.brier, '{:.3f}')}"]
          if (cm := acc.classification_map) is not None else [])])
    fig.text(0.06, 0.87, text, fontsize=8.5, family="DejaVu Sans Mono", va="top")
    ax = fig.add_axes((0.56, 0.10, 0.38, 0.72))
    ok = np.asarray(c.bin_count) > 0
    centres = 0.5 * (np.asarray(c.bins)[:-1] + np.asarray(c.bins)[1:])
    ax.plot([0, 1], [0, 1], ":", color="0.5", label="perfect calibration")
    counts = np.asarray(c.bin_count)[ok]
    ax.scatter(np.asarray(c.bin_mean_p)[ok], np.asarray(c.bin_tip_fraction)[ok],
               s=20 + 180 * counts / max(int(counts.max(initial=1)), 1), color="tab:red",
               zorder=3, label="observed (area ∝ contacts)")
    for x, y, nb in zip(np.asarray(c.bin_mean_p)[ok], np.asarray(c.bin_tip_fraction)[ok],
                        np.asarray(c.bin_count)[ok], strict=True):
        ax.annotate(f"n={nb}", (x, y), textcoords="offset points", xytext=(4, -10), fontsize=7)
    ax.set_xticks(np.asarray(c.bins))
    ax.set_xlim(0, 1)
    ax.set_ylim(-0.03, 1.03)
    ax.set_xlabel("mean P_T in bin")
    ax.set_ylabel("fraction truly tip / joint")
    ax.set_title("P_T calibration", fontsize=10)
    ax.grid(True, lw=0.3)
    ax.legend(fontsize=8, loc="upper left")
    del centres
    pages.append(fig)
    return pages


def _junction_page(j: JunctionSummary) -> Any:
    fig = _page("Well junction",
                f"main bore = primitive #{j.main_id} (holds the robot base), lateral = #"
                f"{j.lateral_id}; ± = 95 % from {j.samples} Monte Carlo draws of the fit "
                "covariances")
    rows = []
    for _, label, e in j.rows():
        scale, unit = (1e3, "mm") if e.unit == "m" else (1.0, "°")
        rows.append([label, f"{e.value * scale:.2f} {unit}",
                     _opt(e.half95, "± {:.2f} " + unit, scale),
                     _opt(e.truth, "{:.2f} " + unit, scale),
                     _opt(e.error, "{:+.2f} " + unit, scale)])
    ax = fig.add_axes((0.04, 0.45, 0.92, 0.42))
    ax.set_axis_off()
    _table(ax, ["quantity", "estimate", "95 % half-width", "truth", "error"], rows,
           [0.3, 0.15, 0.15, 0.15, 0.15], row_in=0.3)
    ref = ", ".join(f"{x:.3f}" for x in j.reference)
    notes = [
        "Window position: distance along the main axis, from the robot base's projection on it, "
        "to where the lateral's axis crosses it (closest approach of the two axes).",
        "Window azimuth: angle of the lateral's direction around the main axis (right-handed), "
        f"from the reference direction ({ref}) = base x axis projected perpendicular to the "
        "main axis.",
        "Angle: between the main axis (pointing from the base to the window) and the lateral "
        "axis (pointing into the branch).",
        "Axis offset: distance between the two axes at their closest approach (0 for "
        "intersecting bores).",
    ]
    fig.text(0.04, 0.58, "\n".join("\n".join(textwrap.wrap(n, 150)) for n in notes),
             fontsize=8.5, va="top", linespacing=1.5)
    return fig


# ----------------------------------------------------------------------------- writer


def build_pages(rec: Any, *, title: str | None = None, ptip_steps: int = 60
                ) -> tuple[list[tuple[str, Any]], AccuracyReport | None,
                           JunctionSummary | None]:
    """All report pages as ``(title, matplotlib Figure)``, with the accuracy and junction
    records they show."""
    accuracy = evaluate(rec)
    junction = junction_summary(rec)
    title = title or f"Reconstruction report — {Path(str(rec.run.source)).name}"
    views = None if rec.surface_map.planar else render_views(rec)
    pages: list[tuple[str, Any]] = [("Summary", _summary_page(rec, title, accuracy, junction,
                                                             views))]
    pages += [("Map", f) for f in _map_pages(rec, views)]
    widths = [0.06, 0.08, 0.14, 0.34, 0.24, 0.07, 0.07]
    pages += [("Primitives", f) for f in _table_pages(
        "Primitives", "parameters with 95 % half-widths (Student t on the weighted "
        "Gauss–Newton covariance); support = tip / link contacts",
        ["id", "type", "parameter", "value", "± 95 %", "tip / link", "rms [mm]"],
        _primitive_rows(rec), widths)]
    pages.append(("Tip probability", _ptip_page(rec, ptip_steps)))
    pages += [("Residuals", f) for f in _residual_pages(rec)]
    if accuracy is not None:
        acc_pages = _accuracy_pages(rec, accuracy)
        pages += [("Accuracy: primitives", acc_pages[0]),
                  ("Accuracy: contacts", acc_pages[1])]
    if junction is not None:
        pages.append(("Well junction", _junction_page(junction)))
    return pages, accuracy, junction


def write_report(path: str | os.PathLike[str], rec: Any, *, title: str | None = None,
                 ptip_steps: int = 60) -> ReportInfo:
    """Write the PDF report of a reconstruction to ``path`` atomically.

    Parameters
    ----------
    path : output PDF file (its folder must exist)
    rec : Reconstruction (``wholearm_tools.pipeline.reconstruct``)
    title : page-one title (default: from the run's source)
    ptip_steps : number of replay times of the P_T-over-time page

    Returns
    -------
    ReportInfo (path, page titles, accuracy and junction records)
    """
    from matplotlib.backends.backend_pdf import PdfPages

    if ptip_steps < 2:
        raise ValueError(f"ptip_steps must be >= 2, got {ptip_steps}")
    path = Path(path)
    meta = {"Title": title or f"wholearm report {Path(str(rec.run.source)).name}",
            "Creator": "wholearm_tools", "Producer": "wholearm_tools (matplotlib)",
            "CreationDate": None}
    with atomic_path(path, ".pdf") as tmp:   # fails fast on a missing folder
        pages, accuracy, junction = build_pages(rec, title=title, ptip_steps=ptip_steps)
        with PdfPages(tmp, metadata=meta) as pdf:
            for _, fig in pages:
                pdf.savefig(fig)
    return ReportInfo(path, tuple(name for name, _ in pages), accuracy, junction)
