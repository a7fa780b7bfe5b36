; expect: 11:1: control point 4 [-1500000.0, 0.0, -1.0] has a coordinate beyond +-1000000, the range nurbsfeed converts
%
O2000 (BAD INPUT CASE)
G17 G21 G40 G49 G80 G90 G94
G0 X0. Y0. Z5.
G1 Z-1. F800.
G06.2 P3 K0. X0. Y0. Z-1. F2000.
K0. X10. Y10. Z-1.
K0. X20. Y0. Z-1.
K0.5 X30. Y10. Z-1.
K0.6 X-1500000. Y0. Z-1.
K1.
K1.
K1.
G0 Z5.
M30
%
