"""G-code: the tokenizer, the modal state, the NURBS block readers (Fanuc G06.2, LinuxCNC G5.2 and
G6.2) and the reader that streams a program as PassThrough lines and CurveBlocks."""

from nurbsfeed.gcode.reader import DIALECTS, read_gcode

__all__ = ["DIALECTS", "read_gcode"]
