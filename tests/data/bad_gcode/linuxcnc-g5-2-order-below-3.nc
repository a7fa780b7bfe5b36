; expect: 7:6: L2: the order L of a G5.2 block is a whole number 3 or more (LinuxCNC ignores smaller L and uses 3)
%
O2000 (BAD INPUT CASE)
G17 G21 G40 G49 G80 G90 G94
G0 X0. Y0. Z5.
G1 Z-1. F800.
G5.2 L2
X10. Y10. P1
G5.3
G0 Z5.
M30
%
