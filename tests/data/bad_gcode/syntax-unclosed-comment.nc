; expect: 7:9: comment '(' is not closed by ')' on this line
%
O2000 (BAD INPUT CASE)
G17 G21 G40 G49 G80 G90 G94
G0 X0. Y0. Z5.
G1 Z-1. F800.
G1 X10. (FINISH PASS
G0 Z5.
M30
%
