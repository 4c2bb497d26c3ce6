"""The PDF report of a short simulated planar run: pages, accuracy pages only with truth,
same input → same bytes, and no half-written file on failure."""

from __future__ import annotations

import dataclasses
import math
import re

import pytest

from wholearm_tools.report import pdf as report_pdf
from wholearm_tools.report import write_report

PAGE = re.compile(rb"/Type\s*/Page\b(?!s)")


def _pdf_pages(path) -> int:
    """Page objects in the file (matplotlib writes one ``/Type /Page`` dictionary per page)."""
    return len(PAGE.findall(path.read_bytes()))


def _expected_base_pages(rec) -> int:
    prims = rec.surface_map.primitives
    rows = sum(len(p.params) for p in prims)
    return (1 + 1 + max(1, math.ceil(rows / report_pdf.ROWS_PER_TABLE_PAGE)) + 1
            + max(1, math.ceil(len(prims) / report_pdf.HISTS_PER_PAGE)))


def _without_truth(rec):
    return dataclasses.replace(rec, run=dataclasses.replace(rec.run, truth=None))


def test_report_with_truth_has_accuracy_pages(planar_rec, tmp_path):
    assert planar_rec.run.truth is not None
    assert len(planar_rec.table) > 0
    out = tmp_path / "report.pdf"
    info = write_report(out, planar_rec, title="paper_planar test")
    assert out.read_bytes().startswith(b"%PDF")
    assert info.pages[0] == "Summary"
    assert info.pages[1] == "Map"
    assert info.pages[-2:] == ("Accuracy: primitives", "Accuracy: contacts")
    assert "Well junction" not in info.pages                    # planar: no junction page
    assert info.n_pages == _expected_base_pages(planar_rec) + 2
    assert _pdf_pages(out) == info.n_pages
    assert info.accuracy is not None
    assert info.accuracy.classification.n_matched > 0
    text = "\n".join(report_pdf.summary_lines(planar_rec, info.accuracy, None))
    assert "Accuracy against ground truth" in text
    assert "Primitives found" in text


def test_report_without_truth_omits_accuracy_pages(planar_rec, tmp_path):
    rec = _without_truth(planar_rec)
    out = tmp_path / "report.pdf"
    info = write_report(out, rec)
    assert info.accuracy is None
    assert not any(p.startswith("Accuracy") for p in info.pages)
    assert info.n_pages == _expected_base_pages(rec)
    assert _pdf_pages(out) == info.n_pages
    assert "Accuracy" not in "\n".join(report_pdf.summary_lines(rec, None, None))


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
