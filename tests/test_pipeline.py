"""reconstruct / fit_table on poor input (clear messages, no tracebacks) and end to end."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from click.testing import CliRunner

from cli.main import cli
from wholearm_tools.contact_table import ContactTable, write_contact_table
from wholearm_tools.errors import InputError
from wholearm_tools.pipeline import duplicate_groups, fit_table


def _table(tips: np.ndarray, links: tuple[np.ndarray, np.ndarray] | None = None,
           radius: float = 0.01) -> ContactTable:
    """A contact table of tip contacts (and optional link contacts), all confidently labelled.

    Each tip's own link reaches it from the free side: radially from the tips' centroid (the
    fit uses the link behind a tip as a local free-space hint, so a link coming through the
    surface would rightly veto it), along +x when the tips coincide."""
    tips = np.asarray(tips, dtype=float)
    d = tips.shape[1]
    a, b = links if links is not None else (np.zeros((0, d)), np.zeros((0, d)))
    nt, nl = len(tips), len(a)
    m = nt + nl
    is_tip = np.r_[np.ones(nt, bool), np.zeros(nl, bool)]
    centre = np.vstack([tips, b])
    out = tips - tips.mean(axis=0) if nt else tips
    norm = np.linalg.norm(out, axis=1, keepdims=True)
    out = np.where(norm > 1e-9, out / np.maximum(norm, 1e-12), np.eye(d)[0])
    seg_a = np.vstack([tips + 0.3 * out, a])
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
    tips = np.stack([x, np.full_like(x, 0.3)], axis=1)
    # each tip's link comes from the free side below the wall (a link lying along the wall
    # could touch it anywhere, and would leave the line's type open)
    table = dataclasses.replace(_table(tips), seg_a=tips - [0.0, 0.3])
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
    """lab_circle, 45 s of arm time (enough for the circle and one wall), written to MCAP."""
    from wholearm_tools.logs import write_run
    from wholearm_tools.sim.scenarios import load_scenario

    result = load_scenario("lab_circle").simulate(seed=0, duration=45.0)
    path = tmp_path_factory.mktemp("run") / "lab.mcap"
    write_run(path, result.run)
    return result.run, path


def _line_error(params: dict, true: dict) -> tuple[float, float]:
    """(angle in degrees, offset in metres) between a fitted and a true line."""
    d = np.asarray(params["direction"], dtype=float)
    td = np.asarray(true["direction"], dtype=float)
    td = td / np.linalg.norm(td)
    angle = np.degrees(np.arccos(min(1.0, abs(float(d @ td)))))
    normal = np.array([-td[1], td[0]])
    offset = abs(float((np.asarray(params["point"]) - np.asarray(true["point"])) @ normal))
    return float(angle), offset


def test_end_to_end_planar_run_finds_the_wall(short_lab_run):
    """Every reported primitive is one of the run's true surfaces (read from its ground
    truth, so the scenario may move its walls): the post within 3 % of its radius, walls
    within a degree and 0.2 mm; and at least one wall and the post are found."""
    from wholearm_tools.pipeline import reconstruct

    run, _ = short_lab_run
    rec = reconstruct(run, B=0.02)
    truth = {s["type"]: [] for s in run.truth.surfaces}
    for s in run.truth.surfaces:
        truth[s["type"]].append(s["params"])
    kinds = [p.kind for p in rec.surface_map.primitives]
    assert "line" in kinds, (kinds, rec.messages)
    assert "circle" in kinds, (kinds, rec.messages)
    for p in rec.surface_map.primitives:
        if p.kind == "line":
            angle, offset = min((_line_error(p.params, t) for t in truth["line"]),
                                key=lambda e: e[1])
            assert angle < 1.0, (p.params, angle)
            assert offset < 2e-4, (p.params, offset)
        else:
            err = min(np.linalg.norm(np.asarray(p.params["center"]) - t["center"])
                      + abs(float(p.params["radius"]) - t["radius"]) for t in truth["circle"])
            true_r = min(truth["circle"], key=lambda t: np.linalg.norm(
                np.asarray(p.params["center"]) - t["center"]))["radius"]
            assert err < 0.03 * true_r, (p.params, err)


def test_cli_reconstruct_on_the_run(short_lab_run, tmp_path, monkeypatch):
    _, path = short_lab_run
    monkeypatch.setenv("SOURCE_DATE_EPOCH", "1767225600")    # map.json records the date
    light = ["--no-meshes", "--no-overlay", "--no-report"]
    out = CliRunner().invoke(cli, ["reconstruct", str(path), "--B", "0.02", "-o",
                                   str(tmp_path / "out"), *light])
    assert out.exit_code == 0, out.output
    assert (tmp_path / "out" / "map.json").exists()
    # the seed fits in one process or in two give the same files, byte for byte
    one = CliRunner().invoke(cli, ["reconstruct", str(path), "--B", "0.02", "--workers", "1",
                                   "-o", str(tmp_path / "one"), *light])
    assert one.exit_code == 0, one.output
    for name in ("map.json", "contacts.csv"):
        assert (tmp_path / "one" / name).read_bytes() == (tmp_path / "out" / name).read_bytes()
    bad = CliRunner().invoke(cli, ["reconstruct", str(path), "--workers", "0", "-o",
                                   str(tmp_path / "bad")])
    assert bad.exit_code == 2
    assert "--workers" in bad.output


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


def test_reconstruct_params_reject_a_bad_number_of_workers():
    from wholearm_tools.errors import InputError
    from wholearm_tools.pipeline import ReconstructParams

    for bad in (0, -1, 1.5):
        with pytest.raises(InputError, match="workers must be a positive integer"):
            ReconstructParams(workers=bad)
    assert ReconstructParams(workers=2).workers == 2


def test_same_input_gives_the_same_map():
    rng = np.random.default_rng(7)
    tips = _circle_tips(14) + 2e-4 * rng.normal(size=(14, 2))
    table = _table(tips)
    first, _, out1, _ = fit_table(table, planar=True, B=0.02, noise_floor=1e-4)
    again, _, out2, _ = fit_table(table, planar=True, B=0.02, noise_floor=1e-4)
    assert [p.kind for p in first.primitives] == ["circle"]
    assert [p.kind for p in again.primitives] == ["circle"]
    for a, b in zip(first.primitives, again.primitives, strict=True):
        for key, value in a.params.items():
            np.testing.assert_array_equal(value, b.params[key])
    np.testing.assert_array_equal(out1.primitive, out2.primitive)


@pytest.mark.parametrize(("reach", "label"), [(1.0, "ambiguous"), (0.1, "link")])
def test_map_label_decides_only_beyond_the_kinematic_error(reach, label):
    """A contact eq. (2) leaves at even odds, where its tip sphere and the side of its link
    (of the same radius, touching 7 mm from the sphere) both lie on a well-fitted circle, the
    sphere 0.3 mm off it and the side exactly on it.  With the kinematic errors of a 1 m arm
    (0.5 mm) that difference does not tell the readings apart, and the map keeps the
    ambiguity; with those of a 0.1 m arm (0.05 mm, below the 0.1 mm noise floor) the side
    reading wins."""
    c, r, w = np.array([0.3, 0.2]), 0.08, 0.01
    tips = _circle_tips(14, centre=tuple(c), r=r, w=w)
    ang = 0.3
    radial = np.array([np.cos(ang), np.sin(ang)])
    p = c + (r + w + 3e-4) * radial                       # the sphere, 0.3 mm off the circle
    delta = np.arccos((r + w) / (r + w + 3e-4))           # a link tangent to the circle + w
    d = np.array([np.cos(ang + np.pi / 2 + delta), np.sin(ang + np.pi / 2 + delta)])
    a = p + 0.3 * d                                       # the link comes in from beyond
    base = _table(np.vstack([tips, p]))
    m = len(base.t)
    table = dataclasses.replace(
        base, p_tip=np.r_[np.ones(m - 1), 0.5], label=np.append(np.full(m - 1, "tip"), "ambiguous"),
        seg_a=np.vstack([base.seg_a[:-1], a]), seg_b=np.vstack([base.seg_b[:-1], p]))
    smap, _, out, _ = fit_table(table, planar=True, B=0.02, noise_floor=1e-4, reach=reach)
    assert [q.kind for q in smap.primitives] == ["circle"]
    assert out.primitive[-1] == 0
    assert out.label_map[-1] == label
    assert np.all(out.label_map[:-1] == "tip")


@pytest.mark.parametrize("reach", [1.0, 0.2])
def test_the_stated_radius_interval_carries_the_kinematic_error(reach):
    """Twelve tips exactly on a post: their residuals are nothing, but the arm that measured
    them is known only to its kinematic error (5e-4 of its reach).  The map states the radius
    to within the 95 % interval that error gives over twelve tips all round,
    1.96 sigma_kin / sqrt(12), not to the residuals' zero; the radius itself is exact."""
    table = _table(_circle_tips(12, r=0.08, w=0.01))
    smap, _, _, _ = fit_table(table, planar=True, B=0.02, noise_floor=1e-5, reach=reach)
    [post] = smap.primitives
    assert post.params["radius"] == pytest.approx(0.08, abs=1e-9)
    sigma_kin = 5e-4 * reach
    assert float(post.ci95["radius"]) == pytest.approx(1.96 * sigma_kin / np.sqrt(12), rel=0.05)


def test_map_refined_labels_are_right_and_leave_fewer_ambiguous(short_lab_run):
    """The fitted map resolves contacts eq. (2) left ambiguous, without mislabelling."""
    from wholearm_tools.contacts import pair_events
    from wholearm_tools.pipeline import reconstruct

    run, _ = short_lab_run
    table = reconstruct(run, B=0.02).table
    m = pair_events(table.t, table.t_end, table.link, run.truth, at=table.t_settle)
    ok = (m >= 0) & (table.link == run.truth.contact_link[np.maximum(m, 0)])
    truth_tip = run.truth.is_tip[np.maximum(m, 0)]
    decided = ok & (table.label_map != "ambiguous")
    assert np.mean((table.label_map == "tip")[decided] == truth_tip[decided]) >= 0.95
    amb_eq2 = np.mean(table.label[ok] == "ambiguous")
    amb_map = np.mean(table.label_map[ok] == "ambiguous")
    assert amb_map < 0.5 * amb_eq2, (amb_eq2, amb_map)


def test_the_table_states_how_sure_the_joint_signals_are_of_each_link(short_lab_run):
    """``p_link`` is the named link's probability among its rigid group's links: 1 where the
    joint signals name one link, the named link's share where they leave several; the fitted
    map moves a contact only to another link of such a group."""
    from wholearm_tools.classify import tip_probability
    from wholearm_tools.contacts import detect_contacts
    from wholearm_tools.pipeline import contact_table, reconstruct

    run, _ = short_lab_run
    contacts = detect_contacts(run.log, run.robot)
    n = run.robot.dof
    prior = np.eye(n)[contacts.link]
    k = int(np.flatnonzero(contacts.link > 0)[0])
    prior[k, contacts.link[k]], prior[k, contacts.link[k] - 1] = 0.7, 0.3
    split = dataclasses.replace(contacts, link_prior=prior)
    table = contact_table(run.robot, split, tip_probability(run, split, 0.02))
    expected = np.ones(len(contacts))
    expected[k] = 0.7
    np.testing.assert_allclose(table.p_link, expected)
    back = ContactTable.from_csv(table.to_csv())
    np.testing.assert_allclose(back.p_link, expected, atol=1e-6)

    fitted = reconstruct(run, B=0.02).table
    assert np.all((fitted.p_link > 0) & (fitted.p_link <= 1))
    assert np.all(fitted.p_link[fitted.link_by_map != fitted.link] < 1)
