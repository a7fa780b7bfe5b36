; expect: 5:24: P2. does not belong in a G5.1 block (X Y I J F)
(BAD INPUT CASE)
G17 G21 G90 G94
G0 X0. Y0. F600.
G5.1 X10. Y10. I5. J0. P2.
M2
