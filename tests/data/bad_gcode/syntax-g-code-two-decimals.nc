; expect: 7:1: G06.25 is not a valid G code: a whole number or one decimal from 0 to 10000 (e.g. G6.2)
%
O2000 (BAD INPUT CASE)
G17 G21 G40 G49 G80 G90 G94
G0 X0. Y0. Z5.
G1 Z-1. F800.
G06.25 P3 K0. X0. Y0.
G0 Z5.
M30
%
