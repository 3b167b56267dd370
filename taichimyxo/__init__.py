"""taichimyxo: flexible-rod myxobacteria simulator on Taichi (Janulevicius et al., PLOS Comput Biol 2015)."""
__version__ = "0.1.0"

import os as _os

_os.environ.setdefault("ENABLE_TAICHI_HEADER_PRINT", "false")   # keep stdout for our own output
