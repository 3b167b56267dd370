"""`python -m taichimyxo.sweep RUN_DIR [--threads N]`: run one point of a sweep from its folder (what each of the
local executor's workers runs; taichimyxo.sweep.runner)."""
import sys

from .runner import main

sys.exit(main())
