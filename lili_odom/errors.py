"""Exceptions with a message meant for the user (printed as one line by the CLI)."""


class UserError(Exception):
    """Bad input a user can fix: unreadable file, missing topic, corrupt bag, invalid parameter."""
