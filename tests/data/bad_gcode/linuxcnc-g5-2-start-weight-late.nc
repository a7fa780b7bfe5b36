; expect: 9:1: P2 without X and Y: only the G5.2 line may set the weight of the start point
%
O2000 (BAD INPUT CASE)
G17 G21 G40 G49 G80 G90 G94
G0 X0. Y0. Z5.
G1 Z-1. F800.
G5.2
X10. Y10. P1
P2
G5.3
G0 Z5.
M30
%
