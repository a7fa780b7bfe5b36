; expect: 8:1: a G5.2 control point needs both X and Y; Y is missing
%
O2000 (BAD INPUT CASE)
G17 G21 G40 G49 G80 G90 G94
G0 X0. Y0. Z5.
G1 Z-1. F800.
G5.2 P1
X10. P1
G5.3
G0 Z5.
M30
%
