; expect: 8:14: first control point X1. is not the current position X0. (tolerance 0.5): a G06.2 curve starts where the tool is (Fanuc alarm PS1009)
%
O2000 (BAD INPUT CASE)
G17 G21 G40 G49 G80 G90 G94
G0 X0. Y0. Z5.
G1 Z-1. F800.
G91
G06.2 P3 K0. X1. Y0. Z0. F2000.
K0. X10. Y10.
K0. X10. Y-10.
K1.
K1.
K1.
G0 Z5.
M30
%
