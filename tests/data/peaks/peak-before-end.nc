(fuzz find gcode-2500083-481, curve 1 alone: a curvature peak inside the last sample interval)
G17 G21 G40 G49 G80 G90 G94
G0 X1. Y2. Z0.
G1 F1620.
G06.2 P4 K0. X1. Y2. Z0.
K0 X3.946 Y0. R+1.1
K0 X0.341 Y0.341000 Z+0.
K0. X0 Y.01 R1.193
K6. X1.29 Y4.869000 Z+0.
K9 X4.032 Y3.386
K9. X4.01 Y3.679
K10.
K10.
K10.
K10.
G1 X2. Y0. Z0.
M30
