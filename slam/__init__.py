"""gated-slam: a GTSAM Pose2 back-end whose factors are gated by sensor validation."""

from slam.host import pin_blas_kernels

pin_blas_kernels()  # before anything imports numpy (slam/host.py)

from slam.errors import GslamError  # noqa: E402

__all__ = ["GslamError"]
__version__ = "0.1.0"
