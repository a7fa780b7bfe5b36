; expect: 8:1: G06.2 needs feed per minute G94, but G95 feed per revolution is in effect since line 7 (Fanuc alarm PS1006)
%
O2000 (BAD INPUT CASE)
G17 G21 G40 G49 G80 G90 G94
G0 X0. Y0. Z5.
G1 Z-1. F800.
G95 F0.1
G06.2 P3 K0. X0. Y0.
K0. X10. Y10.
K0. X20. Y0.
K1.
K1.
K1.
G0 Z5.
M30
%
