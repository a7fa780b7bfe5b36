; expect: 7:1: G062 is a G code nurbsfeed does not know, and K0. on line 8 is a knot of a curve nothing opened: write G06.2 to open it
%
(BAD INPUT CASE: G062 for G06.2, Fanuc G62 corner override; the points would run as G0 moves)
G17 G21 G90
G0 X0. Y0. Z0.
F600.
G062 P3 K0. X0. Y0. Z0.
K0. X10. Y10.
K0. X20. Y0.
K1.
K1.
K1.
M30
%
