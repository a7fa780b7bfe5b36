"""G-code: the tokenizer, the modal state, the NURBS block readers (Fanuc G06.2, LinuxCNC G5.2 and
G6.2) and the writer. The reader that streams a whole program as PassThrough lines and
CurveBlocks, choosing among them, is readers/gcode.py."""
