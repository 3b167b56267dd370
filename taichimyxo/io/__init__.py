"""Inputs and outputs: scenes and their schema, the catalogue of scene and sweep files, frames, the GSD trajectory,
writers, event tables, output folders, the videos and interop with other tools."""
