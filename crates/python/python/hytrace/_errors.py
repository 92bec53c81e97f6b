"""Exceptions raised by hytrace, carrying the messages the command line prints."""


class HytraceError(Exception):
    """Base of every error hytrace raises: a scene, volume or run it cannot handle."""


class HytraceValueError(HytraceError, ValueError):
    """A bad argument value: rays or points that are not finite, a wrong array shape, an
    unknown option value, a photon source or count out of range."""


class HytraceTypeError(HytraceError, TypeError):
    """An argument of the wrong type, such as an array of integers where floats are
    needed."""


class HytraceFileNotFoundError(HytraceError, FileNotFoundError):
    """A scene, volume or other input file that does not exist."""
