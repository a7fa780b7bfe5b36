; expect: 7:1: control point 0 [0.0, 2000000.0, -1.0] has a coordinate beyond +-1000000, the range nurbsfeed converts
%
O2000 (BAD INPUT CASE)
G17 G21 G40 G49 G80 G90 G94
G0 X0. Y2000000. Z5.
G1 Z-1. F800.
G5.2
X10. Y10. P1
X20. Y0. P1
G5.3
G0 Z5.
M30
%
