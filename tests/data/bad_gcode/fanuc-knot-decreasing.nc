; expect: 11:1: K0.4: knots must not decrease (K0.5 on line 10 before it) (Mitsubishi error P551)
%
O2000 (BAD INPUT CASE)
G17 G21 G40 G49 G80 G90 G94
G0 X0. Y0. Z5.
G1 Z-1. F800.
G06.2 P3 K0. X0. Y0. F2000.
K0. X10. Y10.
K0. X20. Y0.
K0.5 X30. Y10.
K0.4 X40. Y0.
K1.
K1.
K1.
G0 Z5.
M30
%
