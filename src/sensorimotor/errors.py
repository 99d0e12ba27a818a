"""The one exception the user can cause; the command line turns it into one line and exit 2."""


class InputError(ValueError):
    """Bad input from the user: a malformed file, a wrong option, a missing path.

    The message is one line that names the file (where there is one) and the problem.
    """
