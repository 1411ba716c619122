"""Gating: the policy of each validation mode, the oracles, the recheck, the odometry scale."""
