; expect: 11:1: '%' (start or end of the program) inside a NURBS block: the block has not ended here
%
O2000 (BAD INPUT CASE)
G17 G21 G40 G49 G80 G90 G94
G0 X0. Y0. Z0.
G06.2 P3 K0. X0. Y0. F2000.
K0. X10. Y10.
K0. X20. Y0.
K1.
K1.
%
