"""What a result shows: metrics, trajectories, occupancy grid, figures, run.mcap, PLY and the HTML report."""
