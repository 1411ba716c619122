"""gated-slam: a GTSAM Pose2 back-end whose factors are gated by sensor validation."""

from slam.errors import GslamError

__all__ = ["GslamError"]
__version__ = "0.1.0"
