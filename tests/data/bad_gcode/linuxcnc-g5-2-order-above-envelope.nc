; expect: 7:6: L11: the order L is at most 10 (degree 9, the highest nurbsfeed evaluates accurately)
%
O2000 (BAD INPUT CASE)
G17 G21 G40 G49 G80 G90 G94
G0 X0. Y0. Z5.
G1 Z-1. F800.
G5.2 L11
X10. Y10. P1
G5.3
G0 Z5.
M30
%
