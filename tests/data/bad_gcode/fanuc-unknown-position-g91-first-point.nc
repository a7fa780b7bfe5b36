; expect: 10:14: X is unknown here (after M6 on line 8): a G91 first control point is relative to it
%
O2000 (BAD INPUT CASE)
G17 G21 G40 G49 G80 G90 G94
G0 X0. Y0. Z5.
G1 Z-1. F800.
G0 Z50.
T2 M6
G91
G06.2 P3 K0. X0. Y0. Z0. F2000.
K0. X10. Y10.
K0. X10. Y-10.
K1.
K1.
K1.
G0 Z5.
M30
%
