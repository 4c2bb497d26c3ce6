"""reconstruct / fit_table on poor input (clear messages, no tracebacks) and end to end."""

from __future__ import annotations

import numpy as np
import pytest
from click.testing import CliRunner

from cli.main import cli
from wholearm_tools.contact_table import ContactTable, write_contact_table
from wholearm_tools.errors import InputError
from wholearm_tools.pipeline import duplicate_groups, fit_table


def _table(tips: np.ndarray, links: tuple[np.ndarray, np.ndarray] | None = None,
           radius: float = 0.01) -> ContactTable:
    """A contact table of tip contacts (and optional link contacts), all confidently labelled."""
    tips = np.asarray(tips, dtype=float)
    d = tips.shape[1]
    a, b = links if links is not None else (np.zeros((0, d)), np.zeros((0, d)))
    nt, nl = len(tips), len(a)
    m = nt + nl
    is_tip = np.r_[np.ones(nt, bool), np.zeros(nl, bool)]
    centre = np.vstack([tips, b])
    seg_a = np.vstack([tips - [0.3] + [0.0] * (d - 1), a])
    seg_b = np.vstack([tips, b])
    return ContactTable(
        t=np.arange(m, dtype=float), link=np.ones(m, dtype=np.int64),
        p_tip=is_tip.astype(float), label=np.where(is_tip, "tip", "link"),
        variance=np.full(m, 1e-6), used_as_tip=is_tip, tip_center=centre,
        tip_radius=np.full(m, radius), seg_a=seg_a, seg_b=seg_b,
        link_radius=np.full(m, radius), primitive=np.full(m, -1, dtype=np.int64),
        residual=np.full(m, np.nan))


def _circle_tips(n: int, centre=(0.3, 0.2), r: float = 0.08, w: float = 0.01,
                 span: float = 2 * np.pi) -> np.ndarray:
    a = np.linspace(0.0, span, n, endpoint=False)
    return np.asarray(centre) + (r + w) * np.stack([np.cos(a), np.sin(a)], axis=1)


def test_too_few_contacts_is_a_message_not_an_error():
    table = _table(_circle_tips(3))
    smap, fits, _, messages = fit_table(table, planar=True, B=0.02)
    assert smap.primitives == ()
    assert fits == ()
    assert any("too few distinct contacts" in m for m in messages)


def test_collinear_contacts_give_a_line_and_never_a_circle():
    x = np.linspace(0.0, 0.4, 12)
    table = _table(np.stack([x, np.full_like(x, 0.3)], axis=1))
    smap, _, _, _ = fit_table(table, planar=True, B=0.02)
    assert [p.kind for p in smap.primitives] == ["line"]
    smap, _, _, messages = fit_table(table, planar=True, B=0.02, kinds=("circle",))
    assert smap.primitives == ()
    assert messages


def test_coincident_contacts_say_so():
    table = _table(np.tile([[0.2, 0.1]], (8, 1)))
    smap, _, _, messages = fit_table(table, planar=True, B=0.02)
    assert smap.primitives == ()
    assert any("counted once" in m for m in messages)
    assert any("too few distinct" in m for m in messages)


def test_wrong_kind_for_the_dimension_is_an_input_error():
    with pytest.raises(InputError, match="cannot be fitted to 2-D"):
        fit_table(_table(_circle_tips(10)), planar=True, B=0.02, kinds=("plane",))


def test_repeated_configuration_is_counted_once():
    tips = np.vstack([_circle_tips(10), np.tile([[0.6, 0.6]], (5, 1))])
    table = _table(tips)
    group = duplicate_groups(table, 1e-6)
    assert len(np.unique(group)) == 11
    smap, _, out, messages = fit_table(table, planar=True, B=0.02)
    assert [p.kind for p in smap.primitives] == ["circle"]
    assert abs(float(smap.primitives[0].params["radius"]) - 0.08) < 1e-6
    assert any("4 repeated contacts" in m for m in messages)
    # the repeats share the (unexplained) fate of their representative
    assert len(set(out.primitive[10:].tolist())) == 1


def test_link_contacts_through_one_point_do_not_make_a_circle():
    """Links of the first joint all start at the base: a vanishing circle at the base would
    touch them all; it must not be reported (radius floor B/2 and identifiability)."""
    ang = np.linspace(0.2, 1.2, 12)
    length = np.random.default_rng(0).uniform(0.3, 0.5, 12)
    b = length[:, None] * np.stack([np.cos(ang), np.sin(ang)], axis=1)
    table = _table(np.zeros((0, 2)), links=(np.zeros((12, 2)), b))
    smap, _, _, _ = fit_table(table, planar=True, B=0.02, kinds=("circle",))
    assert smap.primitives == ()


def test_solver_not_converging_is_reported_in_the_result():
    from wholearm_tools.fit import FitData, fit_primitive

    data = FitData.create(_circle_tips(12, span=np.pi) + 1e-3 * np.arange(12)[:, None], 0.01)
    res = fit_primitive("circle", data, max_iter=1)
    assert not res
    assert "iterations" in res.message


def test_cli_fit_exits_nonzero_with_one_line(tmp_path):
    path = tmp_path / "contacts.csv"
    write_contact_table(path, _table(_circle_tips(3)))
    out = CliRunner().invoke(cli, ["fit", str(path), "-o", str(tmp_path / "map.json")])
    assert out.exit_code != 0
    assert "nothing could be fitted" in out.output
    assert "Traceback" not in out.output
    assert len(out.output.strip().splitlines()) == 1
    assert not (tmp_path / "map.json").exists()


def test_cli_fit_writes_a_map(tmp_path):
    path = tmp_path / "contacts.csv"
    write_contact_table(path, _table(_circle_tips(12)))
    out = CliRunner().invoke(cli, ["fit", str(path), "-o", str(tmp_path / "map.json")])
    assert out.exit_code == 0, out.output
    assert "circle" in out.output


@pytest.fixture(scope="module")
def short_lab_run(tmp_path_factory):
    """lab_circle, 20 s of arm time, written to MCAP."""
    from wholearm_tools.logs import write_run
    from wholearm_tools.sim.scenarios import load_scenario

    result = load_scenario("lab_circle").simulate(seed=0, duration=20.0)
    path = tmp_path_factory.mktemp("run") / "lab.mcap"
    write_run(path, result.run)
    return result.run, path


def test_end_to_end_planar_run_finds_the_wall(short_lab_run):
    from wholearm_tools.pipeline import reconstruct

    run, _ = short_lab_run
    rec = reconstruct(run, B=0.02)
    lines = [p for p in rec.surface_map.primitives if p.kind == "line"]
    assert lines, rec.messages
    # the wall y = 0.52 with free space below: normal (0, -1) within a degree, offset 0.1 mm
    d = np.asarray(lines[0].params["direction"], dtype=float)
    normal = np.array([-d[1], d[0]])
    assert np.degrees(np.arccos(min(1.0, abs(normal @ [0.0, 1.0])))) < 1.0
    assert abs(float(np.asarray(lines[0].params["point"])[1]) - 0.52) < 1e-4
    for p in rec.surface_map.primitives:  # no degenerate primitive
        if p.kind == "circle":
            assert abs(float(p.params["radius"]) - 0.05) / 0.05 < 0.03


def test_cli_reconstruct_on_the_run(short_lab_run, tmp_path):
    _, path = short_lab_run
    out = CliRunner().invoke(cli, ["reconstruct", str(path), "--B", "0.02", "-o",
                                   str(tmp_path / "out")])
    assert out.exit_code == 0, out.output
    assert (tmp_path / "out" / "map.json").exists()


def test_cli_reconstruct_without_contacts_exits_nonzero(tmp_path):
    from wholearm_tools.logs import write_run
    from wholearm_tools.sim.scenarios import load_scenario

    run = load_scenario("lab_circle").simulate(seed=0, duration=0.5).run
    path = tmp_path / "short.mcap"
    write_run(path, run)
    out = CliRunner().invoke(cli, ["reconstruct", str(path), "-o", str(tmp_path / "out")])
    assert out.exit_code != 0
    assert "nothing could be fitted" in out.output
    assert "Traceback" not in out.output
