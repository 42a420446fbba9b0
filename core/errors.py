"""The one exception family of the core.

Every error the core raises on purpose is a :class:`GapFillError`, so callers (the command line,
the add-on) can catch one type and show its message to the user.
"""


class GapFillError(ValueError):
    """Something the user gave us cannot be used; the message says what and why."""


class ParseError(GapFillError):
    """A motion or knowledge-base file cannot be read.

    Parameters
    ----------
    message : str
        What is wrong.
    path : str, optional
        The file.
    line : int, optional
        1-based line number in a text file (BVH, ASF, AMC, CSV).
    frame : int, optional
        0-based frame index where the problem is (C3D, AMC).
    """

    def __init__(self, message, path=None, line=None, frame=None):
        self.path = None if path is None else str(path)
        self.line = line
        self.frame = frame
        where = []
        if self.path:
            where.append(self.path)
        if line is not None:
            where.append(f"line {line}")
        if frame is not None:
            where.append(f"frame {frame}")
        super().__init__(f"{': '.join([', '.join(where), message]) if where else message}")
        self.message = message
