"""The factor graph: keyframes and measurements, GTSAM factors, the back-end that optimises them."""
