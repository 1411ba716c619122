"""A loop constraint: a relative pose between two non-consecutive keyframes
(defined with the loop observer, :mod:`validation.loops.constraint`)."""

from validation.loops.constraint import LoopConstraint

__all__ = ["LoopConstraint"]
