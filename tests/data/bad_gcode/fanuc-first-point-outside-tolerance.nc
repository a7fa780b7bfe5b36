; expect: 7:14: first control point X10.1236 is not the current position X10.123 (tolerance 0.0005): a G06.2 curve starts where the tool is (Fanuc alarm PS1009)
%
O2000 (BAD INPUT CASE)
G17 G21 G40 G49 G80 G90 G94
G0 X10.123 Y0. Z5.
G1 Z-1. F800.
G06.2 P3 K0. X10.1236 Y0. F2000.
K0. X20. Y10.
K0. X30. Y0.
K1.
K1.
K1.
G0 Z5.
M30
%
