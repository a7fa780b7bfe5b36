; expect: 8:11: Z2. does not belong in a G5.2 block in the XY plane: the curve moves X and Y, Z holds
%
O2000 (BAD INPUT CASE)
G17 G21 G40 G49 G80 G90 G94
G0 X0. Y0. Z5.
G1 Z-1. F800.
G5.2
X10. Y10. Z2. P1
G5.3
G0 Z5.
M30
%
