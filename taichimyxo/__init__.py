"""taichimyxo: flexible-rod myxobacteria simulator on Taichi (Janulevicius et al., PLOS Comput Biol 2015)."""
__version__ = "0.1.0"
