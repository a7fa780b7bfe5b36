"""What the command line offers to choose from, named once and importable without numpy or numba
(so that `nurbsfeed --help` and `--version` do not load the pipeline): the interpolation methods,
whose positions are their codes in the stepping kernel (`interpolate.kernels.METHODS`), and the
G-code dialects (`readers.gcode`)."""

METHOD_NAMES = ("taylor1", "rk4", "rk2c")
DIALECTS = ("auto", "fanuc", "linuxcnc", "siemens")
