"""Running a simulation: the Simulation, the run loop and its triggers, a scene's run with its outputs, the Taichi
backend and kernel launching, resources and the progress line."""
