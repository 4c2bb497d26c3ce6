"""Kinematic simulator of whole-arm exploration: guarded moves under an impedance controller,
exact contacts with ground truth, exploration strategies and bundled scenarios."""

from wholearm_tools.sim.collision import Collider
from wholearm_tools.sim.scenarios import Scenario, list_scenarios, load_scenario
from wholearm_tools.sim.simulator import Controller, Move, Sensors, SimResult, simulate
from wholearm_tools.sim.strategies import STRATEGIES, Strategy, make_strategy

__all__ = ["STRATEGIES", "Collider", "Controller", "Move", "Scenario", "Sensors", "SimResult",
           "Strategy", "list_scenarios", "load_scenario", "make_strategy", "simulate"]
