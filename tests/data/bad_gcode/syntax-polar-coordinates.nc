; expect: 7:1: G16 (polar coordinate command) is not supported: X and Y would be radius and angle
%
O2000 (BAD INPUT CASE)
G17 G21 G40 G49 G80 G90 G94
G0 X0. Y0. Z5.
G1 Z-1. F800.
G16
G1 X10. Y45.
G0 Z5.
M30
%
