; expect: 8:3: '%' (start or end of the program) inside a NURBS block: the block has not ended here
%
(BAD INPUT CASE)
G17 G21 G40 G49 G80 G90 G94
G0 X0. Y0. Z0.
F1000
G5.2 X0. Y1. P1
  %
X20. Y0. P1
G5.3
M30
%
