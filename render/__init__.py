"""taichimyxo.render: off-screen movies from Frames (no display, no GPU)."""
