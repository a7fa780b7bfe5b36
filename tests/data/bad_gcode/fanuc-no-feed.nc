; expect: 6:1: no feed is in force: program an F (e.g. F600) before or in the NURBS block; without one the curve would run at the machine's maximum
%
O2000 (BAD INPUT CASE)
G17 G21 G40 G49 G80 G90 G94
G0 X0. Y0. Z0.
G06.2 P3 K0. X0. Y0.
K0. X10. Y10.
K0. X20. Y0.
K0.5 X30. Y5. F600.
K1.
K1.
K1.
M30
%
