; expect: 8:1: control point without a weight: LinuxCNC needs a positive P on every G5.2 control point
%
O2000 (BAD INPUT CASE)
G17 G21 G40 G49 G80 G90 G94
G0 X0. Y0. Z5.
G1 Z-1. F800.
G5.2
X10. Y10.
G5.3
G0 Z5.
M30
%
