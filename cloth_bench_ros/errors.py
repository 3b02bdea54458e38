"""
The root of the package's user-facing errors.

Every error that reports bad input or a failing environment to the user (a bag that cannot be
read, an unknown engine parameter, an unsafe file) derives from ClothBenchError; str() is one line
naming the input and what is wrong. The CLI and the node mains catch it once, print that line and
exit with status 2. Classes that were ValueErrors before stay ValueErrors too.
"""


class ClothBenchError(Exception):
    """A user-facing error: one line naming the input and what is wrong; exit status 2."""
