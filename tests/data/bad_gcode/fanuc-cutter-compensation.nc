; expect: 8:1: G06.2 cannot run under cutter compensation G41 (since line 7): cancel it with G40 first (Fanuc alarm PS1006)
%
O2000 (BAD INPUT CASE)
G17 G21 G40 G49 G80 G90 G94
G0 X0. Y0. Z5.
G1 Z-1. F800.
G41 D1 G1 X1.
G06.2 P3 K0. X1. Y0. F2000.
K0. X10. Y10.
K0. X20. Y0.
K1.
K1.
K1.
G0 Z5.
M30
%
