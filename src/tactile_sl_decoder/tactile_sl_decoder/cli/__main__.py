"""`python -m tactile_sl_decoder.cli` is `tactile-sl`."""
import sys

from tactile_sl_decoder.cli import main

sys.exit(main())
