; expect: 6:1: the feed in force is F0: a NURBS curve needs a feed above zero
%
O2000 (BAD INPUT CASE)
G17 G21 G40 G49 G80 G90 G94
G0 X0. Y0. Z5. F0
G06.2 P3 K0. X0. Y0. Z5.
K0. X10. Y10.
K0. X20. Y0.
K1.
K1.
K1.
G0 Z5.
M30
%
