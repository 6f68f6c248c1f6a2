"""The one exception type that reaches the user as a single line and exit status 2."""


class InputError(Exception):
    """Bad input: a malformed model, an unknown name, an unreadable trial, non-convergence.

    The message names the file, the key path or the frame, and what was expected.
    """
