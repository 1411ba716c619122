"""Physics-based simulator of a tracked robot: a ROS 2 bag and the true fault intervals.

A tracked robot with laser, gyro, magnetometer, track odometry and GPS.

Faults are never switched on by flags: they arise from the world (open
areas without structure for the laser, steel near the compass, slippery
terrain, walls reflecting GPS signals) and are measured afterwards, see
:mod:`slam.sim.faults`.
"""

from slam.sim.scenario import Scenario, load_scenario
from slam.sim.simulator import SimulationResult, simulate, simulate_scenario

__all__ = ["Scenario", "SimulationResult", "load_scenario", "simulate", "simulate_scenario"]
