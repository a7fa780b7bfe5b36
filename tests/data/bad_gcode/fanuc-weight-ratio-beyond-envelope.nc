; expect: 7:1: weight 2 (1001) is more than 1000 times weight 0 (1); nurbsfeed plans curves up to that ratio
%
O2000 (BAD INPUT CASE)
G17 G21 G40 G49 G80 G90 G94
G0 X0. Y0. Z5.
G1 Z-1. F800.
G06.2 P3 K0. X0. Y0. F2000.
K0. X10. Y10.
K0. X20. Y0. R1001.
K1.
K1.
K1.
G0 Z5.
M30
%
