; expect: 10:1: 3 control points are fewer than the order L4, counting the start point: LinuxCNC needs at least 4
%
O2000 (BAD INPUT CASE)
G17 G21 G40 G49 G80 G90 G94
G0 X0. Y0. Z5.
G1 Z-1. F800.
G5.2 L4
X10. Y10. P1
X20. Y0. P1
G5.3
G0 Z5.
M30
%
