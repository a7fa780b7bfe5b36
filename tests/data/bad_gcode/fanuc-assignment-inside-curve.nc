; expect: 8:1: #100= inside a NURBS block: the block is replaced by G1 moves, so assign parameters before it
%
O2000 (BAD INPUT CASE)
G17 G21 G40 G49 G80 G90 G94
G0 X0. Y0. Z5.
G1 Z-1. F800.
G06.2 P3 K0. X0. Y0. F2000.
#100=10.
K0. X10. Y10.
G0 Z5.
M30
%
