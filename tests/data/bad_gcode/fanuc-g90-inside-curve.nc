; expect: 7:1: G90 does not belong in the first block of a G06.2 curve (P K X Y Z R F)
%
O2000 (BAD INPUT CASE)
G17 G21 G40 G49 G80 G90 G94
G0 X0. Y0. Z5.
G1 Z-1. F800.
G90 G06.2 P3 K0. X0. Y0. F2000.
G0 Z5.
M30
%
