; expect: 7:4: X has no number after it (found 'NaN'); write e.g. X10.5
%
O2000 (BAD INPUT CASE)
G17 G21 G40 G49 G80 G90 G94
G0 X0. Y0. Z5.
G1 Z-1. F800.
G1 XNaN
G0 Z5.
M30
%
