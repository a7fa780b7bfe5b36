; expect: 7:1: 'IF' starts a macro or O-word statement; nurbsfeed reads literal G-code only (no subroutines, IF/WHILE/GOTO or expressions)
%
O2000 (BAD INPUT CASE)
G17 G21 G40 G49 G80 G90 G94
G0 X0. Y0. Z5.
G1 Z-1. F800.
IF [#1 GT 0] GOTO 10
G0 Z5.
M30
%
