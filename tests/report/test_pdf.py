"""The PDF report of a short simulated planar run: the answer first, accuracy pages only with
truth, nothing outside the page, numbers to their significant digits, same input → same bytes,
no half-written file on failure."""

from __future__ import annotations

import dataclasses
import re

import numpy as np
import pytest
from report_inputs import cylinder

from wholearm_tools.mapfile import SurfaceMap
from wholearm_tools.report import pdf as report_pdf
from wholearm_tools.report import write_report
from wholearm_tools.report.data import report_data_from_reconstruction

PAGE = re.compile(rb"/Type\s*/Page\b(?!s)")


def _pdf_pages(path) -> int:
    """Page objects in the file (matplotlib writes one ``/Type /Page`` dictionary per page)."""
    return len(PAGE.findall(path.read_bytes()))


def _without_truth(rec):
    return dataclasses.replace(rec, run=dataclasses.replace(rec.run, truth=None))


@pytest.fixture(autouse=True)
def fixed_date(monkeypatch):
    monkeypatch.setenv("SOURCE_DATE_EPOCH", "1767225600")      # 2026-01-01T00:00:00Z


def test_report_with_truth_opens_with_the_answer(planar_rec, tmp_path):
    assert planar_rec.run.truth is not None
    assert len(planar_rec.table) > 0
    out = tmp_path / "report.pdf"
    info = write_report(out, planar_rec, title="paper_planar test")
    assert out.read_bytes().startswith(b"%PDF")
    assert info.pages[:3] == ("Summary", "Map", "Details")
    assert _pdf_pages(out) == info.n_pages
    assert info.accuracy is not None
    assert info.accuracy.classification.n_matched > 0
    data = report_data_from_reconstruction(planar_rec, steps=5)
    lines = report_pdf.summary_lines(data, info.accuracy, None)
    n = len(planar_rec.surface_map.primitives)
    assert lines[0] == f"{n} surface{'s' if n > 1 else ''} found (± = 95 % interval):"
    text = "\n".join(lines)
    assert "Against the simulator's ground truth" in text
    c = info.accuracy.classification
    if c.n_stopped == c.n_truth:        # a kinematic run: every contact stopped the arm
        assert f"{c.n_matched} of {c.n_truth} true contacts detected" in text
    # a physics run's touches that did not stop the arm are said apart from its stops
    slid = dataclasses.replace(info.accuracy, classification=dataclasses.replace(
        c, n_stopped=c.n_truth - 2, n_stops=c.n_truth - 3, n_stops_found=c.n_truth - 4))
    assert (f"{c.n_truth - 4} of the arm's {c.n_truth - 3} stops against contact detected "
            f"({c.n_truth - 2} true contacts held them, 2 more touches did not stop it;"
            ) in "\n".join(report_pdf.summary_lines(data, slid, None)).replace("\n  ", " ")
    assert "Torque evidence: commanded torques (command topic)" in text
    assert f"B = {planar_rec.params.B:g} m" in text
    assert "Written by wholearm_tools" in text
    assert "2026-01-01T00:00:00Z" in text
    t = planar_rec.table
    group = t.p_link < 1
    assert f"Links: {int(np.sum(~group))} named by the joint signals alone" in text
    # a field engineer sees how many links the joint signals left to the swept map and loads
    split = dataclasses.replace(t, p_link=np.where(np.arange(len(t)) == 0, 0.6, 1.0))
    data = dataclasses.replace(data, table=split)
    text = "\n".join(report_pdf.summary_lines(data, info.accuracy, None))
    assert (f"Links: {len(t) - 1} named by the joint signals alone, 1 left among the links "
            "of a rigid group (the named link's probability 0.60-0.60;") in text
    assert "Transmissions" not in text      # stiff drives without play: nothing to say
    # the field engineer reads which drive model placed the contacts, and what was learned
    drives = {**planar_rec.surface_map.meta, "joint_compliance": [0.001, 0.001],
              "joint_backlash": [0.002, 0.003], "joint_backlash_std": [1e-4, 1e-4]}
    data = dataclasses.replace(data, surface_map=dataclasses.replace(data.surface_map,
                                                                     meta=drives))
    text = "\n".join(report_pdf.summary_lines(data, info.accuracy, None))
    assert ("Transmissions: compliance 1 mrad at the effort limit, backlash 2, 3 mrad (learned "
            "from the map); contacts at the links' angles") in text


def test_report_without_truth_has_no_accuracy(planar_rec, tmp_path):
    rec = _without_truth(planar_rec)
    out = tmp_path / "report.pdf"
    info = write_report(out, rec, ptip_steps=5)
    assert info.accuracy is None
    assert _pdf_pages(out) == info.n_pages
    data = report_data_from_reconstruction(rec, steps=5)
    assert "ground truth" not in "\n".join(report_pdf.summary_lines(data, None, None))


def test_every_text_and_axes_lies_inside_its_page(planar_rec):
    """Nothing is clipped at the page edge: every drawn text and axes box of every page is
    within the page."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.text import Text

    data = report_data_from_reconstruction(planar_rec, steps=5)
    pages, _, _ = report_pdf.build_pages(data)
    for title, fig in pages:
        canvas = FigureCanvasAgg(fig)
        canvas.draw()
        renderer = canvas.get_renderer()
        w, h = fig.bbox.width, fig.bbox.height
        ticks = {id(t) for ax in fig.axes for axis in (ax.xaxis, ax.yaxis)
                 for t in axis.get_ticklabels(which="both")}   # drawn ones are in tightbbox
        boxes = [t.get_window_extent(renderer) for t in fig.findobj(Text)
                 if t.get_visible() and t.get_text().strip() and id(t) not in ticks]
        boxes += [ax.get_tightbbox(renderer) for ax in fig.axes]
        for box in boxes:
            assert box.x0 >= -0.5, (title, box)
            assert box.y0 >= -0.5, (title, box)
            assert box.x1 <= w + 0.5, (title, box)
            assert box.y1 <= h + 0.5, (title, box)


def test_junction_answer_in_plain_words_with_uncertainty():
    """A two-cylinder map opens with the junction's diameters, angle and window, each ± its
    95 % half-width to two significant digits."""
    from types import SimpleNamespace

    v45 = np.array([np.sqrt(0.5), 0.0, np.sqrt(0.5)])
    c = np.array([0.0, 0.0, 0.35])
    cov = np.diag([1e-8] * 3 + [1e-6] * 3 + [4e-8])
    up = np.array([0.0, 0.0, 0.1])
    prims = (cylinder(0, c + up, (0, 0, 1), 0.18, (-0.5, 0.1), support=(20, 4), cov=cov),
             cylinder(1, c + 0.2 * v45, v45, 0.12, (0.2, 0.7), support=(8, 1), cov=cov))
    sm = SurfaceMap(planar=False, B=0.02, primitives=prims)
    from wholearm_tools.report.junction import junction_summary

    data = SimpleNamespace(surface_map=sm, fits=(), run=SimpleNamespace(truth=None),
                           messages=())
    j = junction_summary(data)
    answer = " ".join(report_pdf._answer(data, j))
    assert answer.startswith("Well junction found. The main bore (surface #0) is 360")
    assert re.search(r"is 360\.\d+ ± 0\.\d\d mm across", answer), answer
    assert re.search(r"leaves the main bore at 45\.\d+ ± \d", answer), answer
    assert "window" in answer
    assert "along the main bore from the robot base" in answer
    assert "± 0.0 " not in answer
    assert "-0.0" not in answer


@pytest.mark.parametrize(("value", "half", "kwargs", "text"), [
    (0.3200013, 0.0000021, {"scale": 1e3, "unit": "mm"}, "320.0013 ± 0.0021 mm"),
    (-0.000004, 0.0000213, {"scale": 1e3, "unit": "mm"}, "-0.004 ± 0.021 mm"),
    (-0.00000004, 0.0000213, {"scale": 1e3, "unit": "mm"}, "0.000 ± 0.021 mm"),
    (44.9993, 0.011, {"unit": "°"}, "44.999 ± 0.011°"),
    (0.51, float("nan"), {"scale": 1e3, "unit": "mm"}, "510.0 mm"),
    (120.0, 33.0, {"unit": "mm"}, "120 ± 33 mm"),
    (1.0, 6.8e-9, {}, "1.0000 ± 6.8e-09"),
])
def test_numbers_to_their_significant_digits(value, half, kwargs, text):
    assert report_pdf.fmt_pm(value, half, **kwargs) == text


def test_same_input_same_bytes(planar_rec, tmp_path):
    rec = _without_truth(planar_rec)
    a, b = tmp_path / "a.pdf", tmp_path / "b.pdf"
    write_report(a, rec, ptip_steps=10)
    write_report(b, rec, ptip_steps=10)
    assert a.read_bytes() == b.read_bytes()
    assert b"CreationDate" not in a.read_bytes()


def test_failure_leaves_no_file_and_keeps_the_old_one(planar_rec, tmp_path, monkeypatch):
    from matplotlib.backends.backend_pdf import PdfPages

    calls = {"n": 0}
    original = PdfPages.savefig

    def failing(self, *args, **kwargs):
        calls["n"] += 1
        if calls["n"] == 3:
            raise RuntimeError("disk full")
        return original(self, *args, **kwargs)

    monkeypatch.setattr(PdfPages, "savefig", failing)
    out = tmp_path / "report.pdf"
    with pytest.raises(RuntimeError, match="disk full"):
        write_report(out, _without_truth(planar_rec), ptip_steps=5)
    assert list(tmp_path.iterdir()) == []
    out.write_bytes(b"old")
    calls["n"] = 0
    with pytest.raises(RuntimeError, match="disk full"):
        write_report(out, _without_truth(planar_rec), ptip_steps=5)
    assert out.read_bytes() == b"old"
    assert list(tmp_path.iterdir()) == [out]


def test_bad_arguments(planar_rec, tmp_path):
    with pytest.raises(ValueError, match="ptip_steps must be >= 2"):
        write_report(tmp_path / "r.pdf", planar_rec, ptip_steps=1)
    from wholearm_tools.errors import OutputError

    with pytest.raises(OutputError, match="does not exist"):
        write_report(tmp_path / "missing" / "r.pdf", _without_truth(planar_rec), ptip_steps=5)


def test_spatial_pages_stay_inside_the_page_with_long_surface_labels():
    """A 3-D map (views, legend naming five surfaces with long size texts) without a log: every
    text and axes of every page is inside the page, and there is no P_T page."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.text import Text

    from wholearm_tools.contact_table import ContactTable
    from wholearm_tools.mapfile import MappedPrimitive
    from wholearm_tools.mesh.extent import support_extent
    from wholearm_tools.report.data import ReportData, RunInfo

    v45 = np.array([np.sqrt(0.5), 0.0, np.sqrt(0.5)])
    plane = {"point": np.array([0.0, 0.0, -0.08]), "normal": np.array([0.0, 0.0, 1.0])}
    corners = np.array([[0.3, -0.2, -0.08], [0.5, 0.2, -0.08], [0.2, 0.3, -0.08]])
    prims = [cylinder(i, [0.1 * i, 0.0, 0.3], v45 if i % 2 else (0, 0, 1), 0.05 + 0.01 * i,
                      (-0.1, 0.1), cov=np.diag([1e-8] * 7)) for i in range(4)]
    prims.append(MappedPrimitive(4, "plane", plane, extent=support_extent("plane", plane,
                                                                          corners)))
    m = 6
    pts = np.c_[np.linspace(0.1, 0.4, m), np.zeros(m), np.full(m, 0.3)]
    table = ContactTable(t=np.arange(m, dtype=float), link=np.full(m, 2), p_tip=np.full(m, 0.7),
                         label=np.full(m, "tip"), variance=np.full(m, 1e-6),
                         used_as_tip=np.arange(m) % 2 == 0, tip_center=pts,
                         tip_radius=np.full(m, 0.01), seg_a=np.zeros((m, 3)), seg_b=pts,
                         link_radius=np.full(m, 0.02), primitive=np.arange(m) % 5,
                         residual=np.full(m, 1e-4))
    data = ReportData(surface_map=SurfaceMap(planar=False, B=0.02, primitives=tuple(prims)),
                      table=table, run=RunInfo(source="contacts.csv", kind="contact table"))
    pages, accuracy, _ = report_pdf.build_pages(data)
    assert accuracy is None
    assert [name for name, _ in pages][:2] == ["Summary", "Map"]
    for title, fig in pages:
        canvas = FigureCanvasAgg(fig)
        canvas.draw()
        renderer = canvas.get_renderer()
        w = fig.bbox.width
        ticks = {id(t) for ax in fig.axes for axis in (ax.xaxis, ax.yaxis)
                 for t in axis.get_ticklabels(which="both")}
        for t in fig.findobj(Text):
            if t.get_visible() and t.get_text().strip() and id(t) not in ticks:
                box = t.get_window_extent(renderer)
                assert box.x1 <= w + 0.5, (title, t.get_text())
                assert box.y0 >= -0.5, (title, t.get_text())
