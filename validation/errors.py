"""The one exception type of the ``validation`` package."""


class ValidationError(Exception):
    """A user-facing error in a validation model or its configuration."""
