; expect: 7:1: control point 0 [2000000.0, 0.0, -1.0] has a coordinate beyond +-1000000, the range nurbsfeed converts
%
O2000 (BAD INPUT CASE)
G17 G21 G40 G49 G80 G90 G94
G0 X2000000. Y0. Z5.
G1 Z-1. F800.
G06.2 P3 K0. Y0. F2000.
K0. X10. Y10.
K0. X20. Y0.
K1.
K1.
K1.
G0 Z5.
M30
%
