(fuzz seed 57, case 870: a stretch of one node between two rests)
G17 G21 G40 G49 G80 G90 G94
G0 X0. Y1. Z0.
G1 F829.
G06.2 P3 K0. X0. Y1. Z0. R0.5
K0. X0. Y0. R0.5
K0. X0. Y0. R.5 F300.
K1. X0. Y0.
K8 X0.277 Y+3.823
K8 X0 Y1.171
K9.
K9.
K9.
G1 X2. Y2. Z0.
G0 Z5.
M30
