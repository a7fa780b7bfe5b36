; expect: 7:6: 'sin[...]' is an expression; expressions are not supported, write the value as a number
%
O2000 (BAD INPUT CASE)
G17 G21 G40 G49 G80 G90 G94
G0 X0. Y0. Z5.
G1 Z-1. F800.
G1 X sin[30]
G0 Z5.
M30
%
