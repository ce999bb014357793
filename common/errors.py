"""The one error type for input that cannot be served, wherever it is found.

A command-line tool exits 2 for bad input and 1 for a failure. Most bad input is refused
before any work; some can only be found on the way (a demanded object no camera sees, a
receiver holding another codec than the transmitter). Such errors subclass
:class:`InputError`, so the boundary that reports them says "bad input", not "failed".
"""


class InputError(ValueError):
    """The input cannot be served: the user's to fix (a command exits 2), not a failure."""
