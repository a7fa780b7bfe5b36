"""Reading a program: an input file -> a stream of PassThrough lines and CurveBlocks (program.py).

`read_program` is the one entry point: it picks the reader, `json_curves` for JSON curves
(design §4) or `gcode` for a G-code program in one of its DIALECTS, and both stream: memory holds
the item being read, never the file.
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

from nurbsfeed.files import InputFile
from nurbsfeed.program import ProgramItem
from nurbsfeed.readers.gcode import DIALECTS, read_gcode
from nurbsfeed.readers.json_curves import json_program

__all__ = ["DIALECTS", "read_program"]


def read_program(path: Path | InputFile, dialect: str = "auto") -> Iterator[ProgramItem]:
    """JSON curves (a .json file, or any file whose first character is "{") or a G-code program
    in `dialect`, as a stream of items. A file that cannot be opened, or an unknown dialect, is
    refused at once; anything wrong inside the file when the stream reaches it. An InputFile
    already opened is read as it is (a pipe can be read only once)."""
    source = path if isinstance(path, InputFile) else InputFile(path)
    path = source.path
    if path.suffix.lower() == ".json" or source.head.lstrip().startswith(b"{"):
        return json_program(source)
    return read_gcode(source.path, source.lines(), dialect)
