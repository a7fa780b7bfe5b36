; expect: 13:1: X30. in NURBS mode without a knot: a G06.2 control point carries K (Fanuc alarm PS1002); write G1 for a straight move
%
O2000 (BAD INPUT CASE)
G17 G21 G40 G49 G80 G90 G94
G0 X0. Y0. Z5.
G1 Z-1. F800.
G06.2 P3 K0. X0. Y0. F2000.
K0. X10. Y10.
K0. X20. Y0.
K1.
K1.
K1.
X30. Y0.
G0 Z5.
M30
%
