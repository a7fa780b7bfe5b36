; expect: 9:1: Z is unknown here (after M6 on line 8): program Z in the curve's first block (omitted axes keep the current position)
%
O2000 (BAD INPUT CASE)
G17 G21 G40 G49 G80 G90 G94
G0 X0. Y0. Z5.
G1 Z-1. F800.
G0 Z50.
T2 M6
G06.2 P3 K0. X0. Y0. F2000.
K0. X10. Y10.
K0. X20. Y0. Z-1.
K1.
K1.
K1.
G0 Z5.
M30
%
