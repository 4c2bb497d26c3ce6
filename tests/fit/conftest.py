import sys
from pathlib import Path

# the synthetic-data helpers (fit_synth.py) live next to the tests
sys.path.insert(0, str(Path(__file__).parent))
