; expect: 7:1: G5.3 without G5.2 first (LinuxCNC: Cannot use G5.3 without G5.2 first)
%
O2000 (BAD INPUT CASE)
G17 G21 G40 G49 G80 G90 G94
G0 X0. Y0. Z5.
G1 Z-1. F800.
G5.3
G0 Z5.
M30
%
