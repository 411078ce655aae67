"""Errors that the CLI reports as one line (file and what is wrong) with a non-zero exit."""


class HspError(Exception):
    """A user-facing error: bad input, a missing file, an unavailable capability."""
