"""Bundled simulation scenarios: a YAML file plus the robot's URDF next to it.

Scenario file (``datasets/<name>.yaml``)::

    name: lab_circle                # defaults to the file stem
    description: one line for `wholearm scenarios`
    robot: lab_circle.urdf          # path relative to the YAML file
    home: [0.0, 0.6]                # start configuration (must be free)
    environment:                    # obstacles in geometry.obstacle_from_dict form
      - {type: surface, surface_id: 1, free_side: -1,
         primitive: {type: line, params: {point: [0, 0.5], direction: [1, 0]}}}
    strategy: {name: random, lower: [...], upper: [...]}   # name + strategy parameters
    controller: {speed: 0.8, dwell: 0.1}                   # sim.Controller fields
    sensors: {counts_per_rev: 131072}                      # sim.Sensors fields
    physics: {friction: 0.4, gravity: false}               # sim.physics.Physics fields
                                                           #   (the physics engine only)
    defaults: {duration: 60, rate: 500, seed: 0}
    hints: {B: 0.02}                                       # stored in the ground-truth meta

Planar robots use 2-D obstacles in the arm's xy plane.
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from wholearm_tools.errors import RobotModelError, ScenarioError, WholearmError
from wholearm_tools.robot.model import RobotModel
from wholearm_tools.sim.physics import ENGINES, Physics, simulate_physics
from wholearm_tools.sim.simulator import Controller, ProgressCallback, Sensors, SimResult, simulate
from wholearm_tools.sim.strategies import STRATEGIES

FloatArray = NDArray[np.float64]

#: where bundled scenarios live (override with the WHOLEARM_DATASETS environment variable)
DATASETS = Path(__file__).resolve().parents[2] / "datasets"

_KEYS = {"name", "description", "robot", "home", "environment", "strategy", "controller",
         "sensors", "physics", "defaults", "hints"}


def datasets_dir() -> Path:
    return Path(os.environ.get("WHOLEARM_DATASETS", DATASETS))


@dataclass(frozen=True, eq=False)
class Scenario:
    """A loaded scenario: robot, environment, strategy and default run settings."""

    name: str
    description: str
    robot: RobotModel
    obstacles: tuple[Any, ...]
    home: FloatArray
    strategy: str
    strategy_params: dict[str, Any]
    controller: Controller
    sensors: Sensors
    duration: float
    rate: float
    seed: int
    hints: dict[str, Any] = field(default_factory=dict)
    path: Path | None = None
    physics: Physics = field(default_factory=Physics)

    @property
    def dof(self) -> int:
        return self.robot.dof

    @property
    def planar(self) -> bool:
        return self.robot.planar

    @property
    def surfaces(self) -> list[str]:
        """Primitive type of every surface, in surface-id order."""
        out = []
        for obs in self.obstacles:
            prims = getattr(obs, "primitives", None) or (getattr(obs, "primitive", None),)
            out.extend(getattr(p, "kind", "?") for p in prims)
        return out

    def simulate(self, *, seed: int | None = None, duration: float | None = None,
                 rate: float | None = None, strategy: str | None = None,
                 progress: ProgressCallback | None = None, engine: str = "kinematic",
                 physics: Physics | None = None) -> SimResult:
        """Run the scenario; ``None`` arguments take the scenario's defaults.

        ``engine`` is ``"kinematic"`` (default) or ``"physics"`` (MuJoCo); ``physics``
        replaces the scenario's physical parameters (the physics engine only).
        """
        if engine not in ENGINES:
            raise ScenarioError(f"unknown engine {engine!r} (known: {', '.join(ENGINES)})")
        seed = self.seed if seed is None else seed
        name = self.strategy if strategy is None else strategy
        params = self.strategy_params if name == self.strategy else _box_only(
            self.strategy_params)
        meta = {"scenario": self.name, **dict(self.hints.items())}
        common: dict[str, Any] = {
            "strategy": name, "strategy_params": params,
            "duration": self.duration if duration is None else duration,
            "rate": self.rate if rate is None else rate, "seed": seed, "home": self.home,
            "controller": self.controller, "sensors": self.sensors, "progress": progress,
            "meta": meta}
        if engine == "physics":
            return simulate_physics(self.robot, self.obstacles,
                                    physics=self.physics if physics is None else physics,
                                    **common)
        return simulate(self.robot, self.obstacles, **common)

    def summary(self) -> dict[str, Any]:
        """JSON-ready description for ``wholearm scenarios --json``."""
        return {"name": self.name, "dof": self.dof, "planar": self.planar,
                "surfaces": self.surfaces, "strategy": self.strategy,
                "duration": self.duration, "rate": self.rate, "seed": self.seed,
                "description": self.description}


def _box_only(params: Mapping[str, Any]) -> dict[str, Any]:
    """Parameters every strategy accepts (used when another strategy is asked for)."""
    return {k: v for k, v in params.items() if k in ("lower", "upper", "margin", "min_step")}


def list_scenarios(root: str | os.PathLike[str] | None = None) -> list[str]:
    """Names of the bundled scenarios (YAML files in the datasets folder), sorted."""
    folder = Path(root) if root is not None else datasets_dir()
    return sorted(p.stem for p in folder.glob("*.yaml")) if folder.is_dir() else []


def load_scenario(name_or_path: str | os.PathLike[str],
                  root: str | os.PathLike[str] | None = None) -> Scenario:
    """Load a bundled scenario by name, or any scenario YAML by path.

    Raises
    ------
    ScenarioError
        Unknown name (the message lists the known ones) or malformed YAML/content (the message
        names the file).
    RobotModelError
        The URDF cannot be read (the message names the file).
    """
    text = str(name_or_path)
    path = Path(text)
    if not (text.endswith((".yaml", ".yml")) or path.is_file()):
        folder = Path(root) if root is not None else datasets_dir()
        path = folder / f"{text}.yaml"
        if not path.is_file():
            known = ", ".join(list_scenarios(folder)) or "none"
            raise ScenarioError(f"unknown scenario {text!r} (known: {known})")
    elif not path.is_file():
        raise ScenarioError(f"{path}: scenario file not found")
    return _parse(path)


def _parse(path: Path) -> Scenario:
    import yaml

    try:
        data = yaml.safe_load(path.read_text(encoding="utf-8"))
    except OSError as exc:
        raise ScenarioError(f"{path}: cannot read scenario ({exc.strerror})") from None
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f" at line {mark.line + 1}" if mark is not None else ""
        raise ScenarioError(f"{path}: malformed YAML{where}") from None
    if not isinstance(data, dict):
        raise ScenarioError(f"{path}: expected a mapping at the top level, got "
                            f"{type(data).__name__}")
    unknown = set(data) - _KEYS
    if unknown:
        raise ScenarioError(f"{path}: unknown keys {sorted(unknown)}")
    try:
        return _build(path, data)
    except RobotModelError:
        raise
    except WholearmError as exc:
        raise ScenarioError(f"{path}: {exc}") from None
    except (KeyError, TypeError, ValueError) as exc:
        raise ScenarioError(f"{path}: invalid scenario ({exc!r})") from None


def _build(path: Path, data: dict[str, Any]) -> Scenario:
    from wholearm_tools.geometry import obstacle_from_dict
    from wholearm_tools.robot.urdf import load_urdf
    from wholearm_tools.sim.collision import Collider

    if "robot" not in data:
        raise ScenarioError("missing 'robot' (a URDF file next to the scenario)")
    robot = load_urdf(path.parent / str(data["robot"]))
    env = data.get("environment")
    if not isinstance(env, list) or not env:
        raise ScenarioError("'environment' must be a non-empty list of obstacles")
    obstacles = tuple(obstacle_from_dict(item) for item in env)
    home = np.asarray(data.get("home", 0.5 * (robot.lower + robot.upper)), dtype=float)
    if home.shape != (robot.dof,):
        raise ScenarioError(f"home must have {robot.dof} values, got {home.tolist()}")
    strat = dict(data.get("strategy") or {"name": "random"})
    sname = str(strat.pop("name", "random"))
    if sname not in STRATEGIES:
        raise ScenarioError(f"unknown strategy {sname!r} (known: {', '.join(sorted(STRATEGIES))})")
    ctrl = dict(data.get("controller") or {})
    if "stiffness" in ctrl and ctrl["stiffness"] is not None:
        ctrl["stiffness"] = tuple(np.broadcast_to(ctrl["stiffness"], (robot.dof,)).tolist())
    defaults = dict(data.get("defaults") or {})
    collider = Collider(robot, obstacles)  # validates radii and dimensions
    if collider.min_clearance(home[None])[0] <= 0:
        raise ScenarioError(f"home {home.tolist()} is in collision")
    return Scenario(
        name=str(data.get("name", path.stem)),
        description=str(data.get("description", "")).strip(),
        robot=robot, obstacles=obstacles, home=home, strategy=sname, strategy_params=strat,
        controller=Controller(**ctrl), sensors=Sensors(**dict(data.get("sensors") or {})),
        duration=float(defaults.get("duration", 60.0)), rate=float(defaults.get("rate", 500.0)),
        seed=int(defaults.get("seed", 0)), hints=dict(data.get("hints") or {}), path=path,
        physics=Physics(**dict(data.get("physics") or {})),
    )
