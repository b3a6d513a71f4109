"""Errors a user can cause and fix: the CLI prints them as one line and exits 2."""


class UserError(Exception):
    """Bad input (a scenario, a file, an argument): the message names the problem."""
