; expect: 7:1: the file ends inside the G5.2 NURBS block started here (no G5.3)
%
O2000 (BAD INPUT CASE)
G17 G21 G40 G49 G80 G90 G94
G0 X0. Y0. Z5.
G1 Z-1. F800.
G5.2
X10. Y10. P1
X20. Y0. P1
