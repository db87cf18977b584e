"""Make this folder's message builders (viewer_messages) importable."""
import pathlib
import sys

sys.path.insert(0, str(pathlib.Path(__file__).parent))
