; expect: 14:1: G1 comes after only 3 of the 4 knot-only blocks that close a G06.2 curve of order 4 (Fanuc alarm PS1004)
%
O2000 (BAD INPUT CASE)
G17 G21 G40 G49 G80 G90 G94
G0 X0. Y0. Z5.
G1 Z-1. F800.
G06.2 P4 K0. X0. Y0. F2000.
K0. X10. Y10.
K0. X20. Y0.
K0. X30. Y10.
K1.
K1.
K1.
G1 X40.
G0 Z5.
M30
%
