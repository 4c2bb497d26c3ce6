"""reconstruct / fit_table on poor input (clear messages, no tracebacks) and end to end."""

from __future__ import annotations

import numpy as np
import pytest
from click.testing import CliRunner

from cli.main import cli
from wholearm_tools.contact_table import ContactTable, write_contact_table
from wholearm_tools.errors import InputError
from wholearm_tools.pipeline import duplicate_groups, fit_table


def _spatial_without_probes():
    """paper_spatial without tip probes of link contacts: the setting of the runs the cases
    below were found on (before the probes were the scenario's; with the option off the
    simulator draws the same random numbers as it did then)."""
    import dataclasses

    from wholearm_tools.sim.scenarios import load_scenario

    sc = load_scenario("paper_spatial")
    return dataclasses.replace(sc, strategy_params={**sc.strategy_params, "probe_links": 0.0})


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


def test_map_refined_labels_are_right_and_leave_fewer_ambiguous(short_lab_run):
    """The fitted map resolves contacts eq. (2) left ambiguous, without mislabelling."""
    from wholearm_tools.pipeline import reconstruct
    from wholearm_tools.report.metrics import match_contacts

    run, _ = short_lab_run
    table = reconstruct(run, B=0.02).table
    m = np.asarray(match_contacts(table.t, run.truth))
    ok = (m >= 0) & (table.link == run.truth.contact_link[np.maximum(m, 0)])
    truth_tip = run.truth.is_tip[np.maximum(m, 0)]
    decided = ok & (table.label_map != "ambiguous")
    assert np.mean((table.label_map == "tip")[decided] == truth_tip[decided]) >= 0.95
    amb_eq2 = np.mean(table.label[ok] == "ambiguous")
    amb_map = np.mean(table.label_map[ok] == "ambiguous")
    assert amb_map < 0.5 * amb_eq2, (amb_eq2, amb_map)


def test_a_wall_touched_only_by_the_tip_sits_at_the_tip_radius():
    """paper_planar seed 0 touches its top wall four times, with the tip (radius 0.02 m round
    the last link's 0.015 m end sphere). The second look tries those uncertain contacts as link
    contacts and finds the wall; touching with the link's outer end, they are tip contacts, so
    the wall must be fitted at the tip radius. (It was reported 5.0 mm inside the room - the
    difference of the two radii - when the outer-end check skipped second-look primitives.)"""
    from wholearm_tools.pipeline import reconstruct
    from wholearm_tools.report.metrics import evaluate
    from wholearm_tools.sim.scenarios import load_scenario

    rec = reconstruct(load_scenario("paper_planar").simulate(seed=0, duration=60.0).run,
                      B=0.03)
    acc = evaluate(rec).primitives
    assert 0 in {a.truth_id for a in acc}  # the top wall is found
    for a in acc:
        assert a.type_correct
        assert a.position_error < 1e-4, (a.truth_id, a.position_error)


def test_repeated_touches_at_one_spot_make_no_phantom_surface():
    """12 s of lab_circle (seed 1): the first link touches the post four times at one spot
    (contact points within 2 mm), P_T uncertain. Tried as tip contacts by the second look they
    fitted a line through the four tip positions, 10 cm out in free space, and the map-refined
    labels followed it (33 % right). At the scenario's B (0.02 m) a support spanning less than
    B / 2, the smallest radius a primitive may have, is no surface."""
    from wholearm_tools.pipeline import reconstruct
    from wholearm_tools.report.metrics import evaluate
    from wholearm_tools.sim.scenarios import load_scenario

    rec = reconstruct(load_scenario("lab_circle").simulate(seed=1, duration=12.0).run, B=0.02)
    ev = evaluate(rec)
    for a in ev.primitives:
        assert a.type_correct
        assert a.surface_rms < 1e-3, (a.kind, a.surface_rms)
    assert ev.classification_map.class_accuracy >= ev.classification.class_accuracy


def test_links_moving_in_one_plane_make_no_plane():
    """40 s of paper_spatial (seed 1): the base yaw is held through most contacts on the
    posts, so every link moves in one vertical plane. Offset by a link radius, that plane fits
    the link-side contacts on a post (9) and, tried as joint-sphere contacts by the second look,
    six more (RMS 0.9 um): two planes reported 82 and 103 mm RMS from the posts, and the
    map-refined labels fell from 100 % to 85 % right. A plane the contacting links lie flat in
    at most of its contacts is not reported."""
    from wholearm_tools.pipeline import reconstruct
    from wholearm_tools.report.metrics import evaluate

    rec = reconstruct(_spatial_without_probes().simulate(seed=1, duration=40.0).run, B=0.04)
    ev = evaluate(rec)
    assert any(a.kind == "plane" and a.type_correct for a in ev.primitives)  # the floor
    for a in ev.primitives:
        assert a.type_correct, a.kind
        assert a.surface_rms < 1e-3, (a.kind, a.surface_rms)
    assert ev.classification_map.class_accuracy >= ev.classification.class_accuracy
    assert any("lie flat" in m for m in rec.messages)


@pytest.mark.parametrize(("scenario", "seed", "duration", "B", "kind"), [
    # three link touches at one spot tried as tips, and one tip on the left wall 0.5 m away:
    # a line 247 mm RMS from the post it was matched to
    ("paper_planar", 8, 20.0, 0.03, "line"),
    # (30 s of well_junction, seed 4, made a horizontal plane through tips at one height in
    # both bores until its contact #7 was put on the right link; the plane rule is now
    # covered by tests/fit/test_crossing.py only: no well_junction run of seeds 0-20 at 30 s
    # makes such a plane any more)
    # four tips at one spot on the left wall and one on the top wall: a circle r 0.25 m
    # around the base, 124 mm RMS from the wall, 77 % of the motion outside it (the tip on
    # the top wall bends it: that rule now leaves it out before the crossing check is asked)
    ("lab_circle", 15, 20.0, 0.02, "circle"),
])
def test_a_surface_the_arm_passed_through_between_its_contacts_is_not_reported(
        scenario, seed, duration, B, kind):
    """Short runs where a wrong primitive was held up by contacts far apart and the arm swept
    through it in between, where a surface it touched cannot be."""
    from wholearm_tools.pipeline import reconstruct
    from wholearm_tools.report.metrics import evaluate
    from wholearm_tools.sim.scenarios import load_scenario

    run = load_scenario(scenario).simulate(seed=seed, duration=duration).run
    rec = reconstruct(run, B=B)
    ev = evaluate(rec)
    for a in ev.primitives:
        assert a.type_correct, a.kind
    assert any(f"a {kind} on" in m and ("passed through it" in m or "went through it" in m
                                        or "that bent it" in m)
               for m in rec.messages)


def test_the_second_look_switches_only_ambiguous_contacts():
    """20 s of paper_planar (seed 7): five link-body touches of a post at one spot, labelled
    link (P_T 0.15-0.18), tried as joint-sphere contacts, put those spheres 5 cm apart along a
    line 28 mm RMS from the post, and the map-refined labels followed it (54 % right against
    88 % from eq. 2)."""
    from wholearm_tools.pipeline import reconstruct
    from wholearm_tools.report.metrics import evaluate
    from wholearm_tools.sim.scenarios import load_scenario

    rec = reconstruct(load_scenario("paper_planar").simulate(seed=7, duration=20.0).run,
                      B=0.03)
    ev = evaluate(rec)
    assert ev.primitives
    for a in ev.primitives:
        assert a.type_correct, a.kind
        assert a.surface_rms < 1e-3, (a.kind, a.surface_rms)
    assert ev.classification_map.class_accuracy >= ev.classification.class_accuracy


def test_one_wall_is_one_line_once_its_outer_end_contacts_are_refitted_as_tips():
    """lab_circle (seed 0, 120 s): eleven link contacts on the left wall touch with the last
    link's outer end. Fit-and-grow fitted them at the link radius, 3 mm off the wall's other
    contacts, so the wall came out as two lines; refitted at the tip radius they coincide,
    and the map has one line per wall."""
    from wholearm_tools.pipeline import reconstruct
    from wholearm_tools.report.metrics import evaluate
    from wholearm_tools.sim.scenarios import load_scenario

    rec = reconstruct(load_scenario("lab_circle").simulate(seed=0).run, B=0.02)
    ev = evaluate(rec)
    assert sorted(a.kind for a in ev.primitives) == ["circle", "line", "line"]
    assert all(a.type_correct for a in ev.primitives)
    assert len({a.truth_id for a in ev.primitives}) == 3
    assert any("merged" in m for m in rec.messages)


def test_merge_coincident_joins_two_stretches_of_one_line_only():
    from wholearm_tools.fit import FitData, fit_primitive
    from wholearm_tools.pipeline import _merge_coincident

    rng = np.random.default_rng(3)
    x = np.r_[np.linspace(-0.3, -0.2, 6), np.linspace(0.1, 0.2, 6)]
    y = 0.5 + rng.normal(0.0, 5e-6, x.size)  # noise below the sigma the merge is given
    pts = np.c_[x, y]
    data = FitData.create(pts, dim=2)
    a, b = np.arange(6), np.arange(6, 12)
    fa = fit_primitive("line", data.take(a), free_side=-1.0)
    fb = fit_primitive("line", data.take(b), free_side=-1.0)
    out, n = _merge_coincident([(fa, a), (fb, b)], data, sigma=1e-5)
    assert n == 1
    assert len(out) == 1
    assert out[0][1].tolist() == list(range(12))
    # the second stretch 3 mm higher: a parallel wall, not the same one
    shifted = FitData.create(np.c_[x, y + np.r_[np.zeros(6), np.full(6, 0.003)]], dim=2)
    fb = fit_primitive("line", shifted.take(b), free_side=-1.0)
    fa = fit_primitive("line", shifted.take(a), free_side=-1.0)
    out, n = _merge_coincident([(fa, a), (fb, b)], shifted, sigma=1e-5)
    assert n == 0
    assert len(out) == 2


def test_a_primitive_another_explains_all_but_a_few_contacts_of_is_dissolved():
    """A line through four contacts of a circle's arc and one stray contact: the circle
    explains all but one of them, fewer than a line needs, so the line goes, the four join the
    circle and the stray one is left unexplained.  A line with five contacts off the circle
    stays."""
    from wholearm_tools.fit import FitData, fit_primitive
    from wholearm_tools.pipeline import _dissolve_redundant

    rng = np.random.default_rng(4)
    ang = np.radians(np.r_[np.linspace(0.0, 150.0, 12), np.linspace(200.0, 206.0, 4)])
    circle_pts = 0.1 * np.c_[np.cos(ang), np.sin(ang)]
    stray = np.array([[0.1 * np.cos(np.radians(203.0)) - 0.004, 0.1 * np.sin(np.radians(203.0))]])
    wall = np.c_[np.linspace(0.2, 0.3, 5), np.full(5, -0.2)]  # a wall 10 cm away
    pts = np.vstack([circle_pts, stray, wall]) + rng.normal(0.0, 2e-6, (22, 2))
    data = FitData.create(pts, dim=2)
    circle, arc, line_wall = np.arange(12), np.arange(12, 17), np.arange(17, 22)
    fc = fit_primitive("circle", data.take(circle), free_side=1.0)
    fa = fit_primitive("line", data.take(arc))
    fw = fit_primitive("line", data.take(line_wall))
    out, gone = _dissolve_redundant([(fc, circle), (fa, arc), (fw, line_wall)], data,
                                    sigma=1e-5)
    assert gone == [("line", 4, 1)]
    assert [f.kind for f, _ in out] == ["circle", "line"]
    assert out[0][1].tolist() == list(range(16))  # the arc joined, the stray one did not
    assert abs(float(out[0][0].params["radius"]) - 0.1) < 1e-5
    assert out[1][1].tolist() == line_wall.tolist()


@pytest.mark.parametrize(("scenario", "seed", "why"), [
    ("lab_circle", 20, "outer end, where eq. (2)"),
    ("lab_sharp", 20, "another primitive explains 6 of them")])
def test_a_primitive_only_the_outer_ends_of_link_labelled_contacts_touch_is_not_reported(
        scenario, seed, why):
    """20 s runs where the outer link touched a post at one spot four (six) times, P_T
    0.02-0.18: a line through (tangent at) the links' outer ends was reported 63 (76) mm RMS
    from the post, against eq. (2), which put no contact at those ends.  On lab_sharp the
    post's circle, found by the second look, explains all six, so the line is dissolved into
    it before that rule is reached."""
    from wholearm_tools.pipeline import reconstruct
    from wholearm_tools.report.metrics import evaluate
    from wholearm_tools.sim.scenarios import load_scenario

    rec = reconstruct(load_scenario(scenario).simulate(seed=seed, duration=20.0).run, B=0.02)
    ev = evaluate(rec)
    assert ev.primitives
    for a in ev.primitives:
        assert a.type_correct, a.kind
        assert a.surface_rms < 1e-3, (a.kind, a.surface_rms)
    assert any(why in m for m in rec.messages)


def test_a_post_touched_along_one_side_is_completed_by_its_other_contacts():
    """90 s of paper_spatial (seed 0): eight link bodies touch post 2 (r 0.05 m) along one
    side; they fit it 12 % too large, and growth never reaches the post's tips and joint
    contacts on its other side.  That fit is determined at the report's level, but only with
    one of its contacts: without it the others leave it free (sensitivity 316 -> 18112), so it
    is not reported as it is.  Completed by the unexplained contacts one refit also explains,
    the post is reported within 0.1 % of its radius."""
    from wholearm_tools.pipeline import reconstruct
    from wholearm_tools.report.metrics import evaluate

    sc = _spatial_without_probes()
    rec = reconstruct(sc.simulate(seed=0, duration=90.0).run, B=float(sc.hints["B"]))
    ev = evaluate(rec)
    posts = [a for a in ev.primitives if a.kind == "cylinder"]
    assert len(posts) == 1
    assert posts[0].type_correct
    assert posts[0].size_error_pct < 0.1
    assert posts[0].surface_rms < 1e-4
    for a in ev.primitives:
        assert a.type_correct, a.kind
    assert any("took" in m and "unexplained contacts" in m for m in rec.messages)


def test_the_fitted_bore_tells_which_link_of_a_rigid_group_touched_it():
    """well_junction seed 0: contact 26 is the well arm's 3 cm roll link's end sphere pressed
    into the main bore, which the joint torques cannot tell from link 1's leading edge, and
    the swept map gives link 1 two to one.  Link 1 then stands 13 mm off the fitted bore while
    the roll link's end sphere touches it: link_by_map puts it right, and every contact's
    refined link is its true one."""
    from wholearm_tools.contacts import match_truth
    from wholearm_tools.pipeline import reconstruct
    from wholearm_tools.sim.scenarios import load_scenario

    sc = load_scenario("well_junction")
    res = sc.simulate(seed=0)
    rec = reconstruct(res.run, B=float(sc.hints["B"]))
    m = match_truth(rec.contacts, res.truth)
    ok = m >= 0
    true_link = np.asarray(res.truth.contact_link)[m[ok]]
    assert np.sum(rec.table.link[ok] != true_link) == 1  # the signals' one miss
    assert np.array_equal(rec.table.link_by_map[ok], true_link)
    assert np.flatnonzero(rec.table.link_by_map != rec.table.link).tolist() == [26]


def test_a_post_the_arm_passed_through_is_not_reported():
    """180 s of paper_spatial (seed 5): six link contacts on the two posts, 45 cm apart, and
    a tip fit a tilted cylinder r 0.074 m, matched to post 2 at 268 mm RMS.  The contacts put
    the robot outside it, and the arm swept through its body 257 times between them: a post
    is solid, so it is no primitive (fit-and-grow rules it out as it selects; the report's
    crossing check would too); the floor, the sphere and post 1 (reported since the report's
    identifiability is judged at the arm's reach) stay, each on its surface."""
    from wholearm_tools.pipeline import reconstruct
    from wholearm_tools.report.metrics import evaluate

    sc = _spatial_without_probes()
    rec = reconstruct(sc.simulate(seed=5, duration=180.0).run, B=float(sc.hints["B"]))
    ev = evaluate(rec)
    assert {"plane", "sphere"} <= {a.kind for a in ev.primitives}
    assert 2 not in {a.truth_id for a in ev.primitives}  # no post 2
    for a in ev.primitives:
        assert a.type_correct
        assert a.surface_rms < 5e-4
        if a.size_error_pct is not None:
            assert abs(a.size_error_pct) < 0.5


def test_a_ball_the_arm_passed_through_does_not_take_the_contacts_of_two_surfaces():
    """240 s of paper_spatial (seed 1) with tip probes of link contacts: contacts on post 1
    and on the ball, half a metre apart, fit a sphere r 0.72 m that described them best, so
    fit-and-grow selected neither surface.  The arm swept through that sphere's body between
    its contacts thousands of times: ruled out while selecting, it leaves post 1 and the ball
    to be found."""

    from wholearm_tools.pipeline import reconstruct
    from wholearm_tools.report.metrics import evaluate
    from wholearm_tools.sim.scenarios import load_scenario

    sc = load_scenario("paper_spatial")  # 240 s with tip probes, the scenario's setting
    rec = reconstruct(sc.simulate(seed=1).run, B=float(sc.hints["B"]))
    ev = evaluate(rec)
    found = {a.truth_id: a for a in ev.primitives if a.type_correct}
    assert {1, 3} <= set(found)  # post 1 and the ball
    for i in (1, 3):
        assert abs(found[i].size_error_pct) < 0.1
        assert found[i].surface_rms < 1e-4
    assert not any(a.kind == "sphere" and a.size_fit > 0.2 for a in ev.primitives)
    # a plane through six of post 1's link contacts and a stray tip is dissolved into the post
    assert all(a.type_correct for a in ev.primitives)
    # post 2 was bent 16 % too large by a body contact taken as a tip; without that contact
    # its 16 contacts determine it at kinematic errors of 5e-4 of the reach (not of the
    # scene, 1.94 m at 240 s): reported within 0.5 %
    assert set(found) == {0, 1, 2, 3}
    assert abs(found[2].size_error_pct) < 0.5
    assert found[2].surface_rms < 1e-3
    assert any("a plane on 7 contacts not reported: another primitive explains 6" in m
               for m in rec.messages)


def test_a_second_look_primitive_whose_refit_fails_is_not_carried_with_another_fit(monkeypatch):
    """40 s of paper_spatial (seed 13): the second look finds a cylinder on nine of its fit
    contacts (versions of ambiguous contacts), eight once counted in the table; the warm refit
    on those eight fails.  It used to keep the second look's fit, whose nine residuals then
    met eight contacts: at a laxer report level (3e-4 of the scene size) the map writer raised
    ValueError.  The refit is retried cold, and a primitive that cannot be refitted on its
    own contacts is not reported."""

    from wholearm_tools import pipeline
    from wholearm_tools.report.metrics import evaluate

    monkeypatch.setattr(pipeline, "REPORT_ID_NOISE", 3e-4)
    sc = _spatial_without_probes()
    rec = pipeline.reconstruct(sc.simulate(seed=13, duration=40.0).run, B=float(sc.hints["B"]))
    assert any("found among unexplained contacts" in m for m in rec.messages)
    assert all(a.type_correct for a in evaluate(rec).primitives)


def test_the_default_paper_spatial_run_finds_every_surface():
    """The paper_spatial scenario as bundled (seed 0: 240 s, tip probes of link contacts):
    the floor, both posts and the ball, each within 0.1 % of its radius and 0.1 mm RMS of its
    surface.  Post 2 comes out of the second look (ambiguous contacts as the other class) on
    seven members that are only five contacts, both versions of two of them; completed by the
    leftovers one refit also explains, it takes twelve."""
    from wholearm_tools.pipeline import reconstruct
    from wholearm_tools.report.metrics import evaluate
    from wholearm_tools.sim.scenarios import load_scenario

    sc = load_scenario("paper_spatial")
    rec = reconstruct(sc.simulate().run, B=float(sc.hints["B"]))
    ev = evaluate(rec)
    assert sorted(a.truth_id for a in ev.primitives if a.type_correct) == [0, 1, 2, 3]
    assert len(ev.primitives) == 4
    for a in ev.primitives:
        assert a.surface_rms < 1e-4, (a.kind, a.surface_rms)
        if a.size_error_pct is not None:
            assert abs(a.size_error_pct) < 0.1, (a.kind, a.size_error_pct)


def test_a_primitive_a_wrong_contact_bends_is_not_reported_bent():
    """The bundled paper_spatial run, seed 12: seven contacts fit post 1 12 % too large; one of
    them is a tip taken as a link contact, 2.8 mm off the post, and the six others pin the
    post without it (the fit without it leaves it far off and explains the others far
    better).  Left out, too few contacts remain for a cylinder: it is not reported, rather
    than reported 12 % off."""
    from wholearm_tools.pipeline import reconstruct
    from wholearm_tools.report.metrics import evaluate
    from wholearm_tools.sim.scenarios import load_scenario

    sc = load_scenario("paper_spatial")
    rec = reconstruct(sc.simulate(seed=12).run, B=float(sc.hints["B"]))
    ev = evaluate(rec)
    assert all(a.type_correct for a in ev.primitives)
    assert all(abs(a.size_error_pct) < 1.0 for a in ev.primitives if a.size_error_pct is not None)
    assert any("cylinder on 7 contacts not reported: without the 1 that bent it" in m
               for m in rec.messages)
