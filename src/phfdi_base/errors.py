"""Errors a user can cause and fix: the CLI prints them as one line and exits 2."""


class UserError(Exception):
    """Bad input (a scenario, a file, an argument): the message names the problem.

    The command line prints it as one line and exits with status 2, without a traceback. Library code
    raises it (or ``ValueError``) where the user can fix the cause.

    Examples
    --------
    >>> from phfdi_base import UserError
    >>> try:
    ...     raise UserError("scenario.yaml: duration_s: must be greater than 0")
    ... except UserError as exc:
    ...     print(exc)
    scenario.yaml: duration_s: must be greater than 0
    """
