"""The commands behind gslam: compare, demo, inspect, calibrate, ablate, inject."""
