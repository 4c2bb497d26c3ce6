"""Bundled scenarios load; malformed ones fail with the file name."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest

from wholearm_tools.errors import RobotModelError, ScenarioError
from wholearm_tools.sim import list_scenarios, load_scenario
from wholearm_tools.sim.scenarios import datasets_dir

EXPECTED = {"paper_planar", "paper_spatial", "lab_circle", "lab_sharp", "well_junction"}


def test_all_bundled_scenarios_are_listed() -> None:
    assert set(list_scenarios()) >= EXPECTED


@pytest.mark.parametrize("name", sorted(EXPECTED))
def test_every_scenario_loads(name: str) -> None:
    sc = load_scenario(name)
    assert sc.name == name
    assert sc.robot.planar == (name in {"paper_planar", "lab_circle", "lab_sharp"})
    assert len(sc.surfaces) >= 2
    assert sc.duration > 0
    assert sc.rate > 0
    assert np.all(np.diff(sc.robot.link_radii) < 0)


def test_scenario_short_run_is_reproducible() -> None:
    sc = load_scenario("lab_circle")
    a = sc.simulate(duration=2.0)
    b = sc.simulate(duration=2.0)
    np.testing.assert_array_equal(a.run.log.q, b.run.log.q)
    assert a.truth.meta["scenario"] == "lab_circle"


def test_unknown_name_lists_known_ones() -> None:
    with pytest.raises(ScenarioError, match=r"known: .*lab_circle"):
        load_scenario("no_such_scenario")


def _copy(tmp_path: Path, name: str) -> Path:
    for ext in ("yaml", "urdf"):
        shutil.copy(datasets_dir() / f"{name}.{ext}", tmp_path / f"{name}.{ext}")
    return tmp_path / f"{name}.yaml"


def test_malformed_yaml_names_the_file(tmp_path: Path) -> None:
    path = _copy(tmp_path, "lab_circle")
    path.write_text("name: [unclosed\n", encoding="utf-8")
    with pytest.raises(ScenarioError, match=r"lab_circle\.yaml: malformed YAML"):
        load_scenario(path)


def test_bad_content_names_the_file(tmp_path: Path) -> None:
    path = _copy(tmp_path, "lab_circle")
    text = path.read_text(encoding="utf-8").replace("type: arc", "type: blob")
    path.write_text(text, encoding="utf-8")
    with pytest.raises(ScenarioError, match=r"lab_circle\.yaml: unknown obstacle type 'blob'"):
        load_scenario(path)


def test_malformed_urdf_names_the_file(tmp_path: Path) -> None:
    path = _copy(tmp_path, "lab_sharp")
    (tmp_path / "lab_sharp.urdf").write_text("<robot><link", encoding="utf-8")
    with pytest.raises(RobotModelError, match=r"lab_sharp\.urdf"):
        load_scenario(path)


def test_home_in_collision_is_refused(tmp_path: Path) -> None:
    path = _copy(tmp_path, "lab_circle")
    text = path.read_text(encoding="utf-8")
    text = "\n".join("home: [0.56, 0.0]" if line.startswith("home:") else line
                     for line in text.splitlines())
    path.write_text(text, encoding="utf-8")
    with pytest.raises(ScenarioError, match="in collision"):
        load_scenario(path)
