; expect: 5:1: K1.: a NURBS knot with no G06.2 curve open (under G0/G1 K means nothing): write G06.2 on the curve's first block
(BAD INPUT CASE: knot-only blocks with no curve open)
G21 G90 G1 X0. Y0. F600.
X10. Y10.
K1.
K1.
M30
