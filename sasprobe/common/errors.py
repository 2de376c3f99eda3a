"""Errors a user can cause. The CLI prints each as one line and exits with status 2."""


class UserError(Exception):
    """A problem with the user's input or environment, reported as one line (exit 2)."""
