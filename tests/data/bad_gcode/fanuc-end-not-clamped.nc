; expect: 12:1: K2.: the last 3 knots must be equal (clamped end, order 3); K1. on line 10 is the first of them (Fanuc alarm PS1007)
%
O2000 (BAD INPUT CASE)
G17 G21 G40 G49 G80 G90 G94
G0 X0. Y0. Z5.
G1 Z-1. F800.
G06.2 P3 K0. X0. Y0. F2000.
K0. X10. Y10.
K0. X20. Y0.
K1.
K1.
K2.
G0 Z5.
M30
%
