"""Move planning: steps, ramps, sines, trajectories, Cartesian paths, path and pose files,
approaches and summaries. The control process never imports this package."""
