; expect: 7:6: P30: the order P is a whole number from 2 to 10 (degree + 1)
%
O2000 (BAD INPUT CASE)
G17 G21 G40 G49 G80 G90 G94
G0 X0. Y0. Z5.
G1 Z-1. F800.
G6.2 P30 Q1 K0 X0 Y0 F2000
G0 Z5.
M30
%
