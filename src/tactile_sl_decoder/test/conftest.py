"""Make this folder's shared test helpers (small_patterns) importable."""
import pathlib
import sys

sys.path.insert(0, str(pathlib.Path(__file__).parent))
