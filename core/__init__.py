"""The numeric core: motion model, file formats, gap filling. Never imports bpy."""

from .errors import GapFillError, ParseError
from .motion import Motion

__all__ = ["GapFillError", "ParseError", "Motion"]
