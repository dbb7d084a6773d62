"""Errors of the model layer. ``mjcf`` imports nothing from ``sim``; the CLI reports these
as one line with exit code 2, as it does ``sim``'s own user errors."""


class MjcfError(ValueError):
    """Anything wrong with what ``mjcf`` was asked to build (a user can fix it)."""


class DescriptionError(MjcfError):
    """A table or payload description that is incomplete or inconsistent."""
