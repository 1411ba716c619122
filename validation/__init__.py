"""Sensor validation after the Telemax paper: qualitative trends, observers,
consistency-based diagnosis (Reiter) and per-step gating of factors."""

from validation.errors import ValidationError

__all__ = ["ValidationError"]
