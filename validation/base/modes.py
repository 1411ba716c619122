"""The gating modes, ``validation.mode``: a small module, so that the command
line offers them without loading the validator."""

from __future__ import annotations

from enum import StrEnum


class GatingMode(StrEnum):
    """``validation.mode``, typed once: how the factors are gated (see
    :mod:`validation.config`). The pipeline turns it into one policy
    (:func:`slam.gating.policy.gating_policy`); ``--gating`` offers its values."""

    OFF = "off"
    ON = "on"
    ORACLE = "oracle"
    INTERVAL_ORACLE = "interval_oracle"

    @property
    def needs_model(self) -> bool:
        """Whether the mode gates by the components of the system model."""
        return self in (GatingMode.ON, GatingMode.INTERVAL_ORACLE)
