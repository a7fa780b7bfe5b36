"""nurbsfeed: jerk-limited feedrate planning and densified G1 output for NURBS toolpaths."""

__version__ = "0.1.0"
