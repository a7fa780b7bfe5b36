; expect: 7:22: F-2000.: a feed must not be negative
%
O2000 (BAD INPUT CASE)
G17 G21 G40 G49 G80 G90 G94
G0 X0. Y0. Z5.
G1 Z-1. F800.
G06.2 P3 K0. X0. Y0. F-2000.
G0 Z5.
M30
%
