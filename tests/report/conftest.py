"""Report tests: the helpers in report_inputs.py and one short simulated run shared by all."""

import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).parent))


@pytest.fixture(scope="session")
def planar_rec():
    """A short simulated planar run (paper_planar, 20 s of arm time), reconstructed."""
    from wholearm_tools.pipeline import reconstruct
    from wholearm_tools.sim import load_scenario

    sc = load_scenario("paper_planar")
    sim = sc.simulate(seed=0, duration=20.0)
    return reconstruct(sim.run, B=sc.hints.get("B", 0.03))
