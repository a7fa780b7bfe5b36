; expect: 5:13: Z1.: Splines may not have motion in Z, A, B, or C (LinuxCNC): G5 moves X and Y only
(BAD INPUT CASE)
G17 G21 G90 G94
G0 X0. Y0. Z0. F600.
G5 X10. Y0. Z1. I3. J4. P-3. Q4.
M2
