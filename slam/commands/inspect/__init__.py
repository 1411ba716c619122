"""gslam inspect: what a recording holds, the topics it guesses, and a starter config."""
