; expect: 5:1: G5.1 without I and J: Must specify both I and J with G5.1 (LinuxCNC): I J is the control point relative to the start
(BAD INPUT CASE)
G17 G21 G90 G94
G0 X0. Y0. F600.
G5.1 X10. Y10.
M2
