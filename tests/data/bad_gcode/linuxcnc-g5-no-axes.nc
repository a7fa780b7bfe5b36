; expect: 5:1: G5 without X or Y: All axes missing with motion code (LinuxCNC)
(BAD INPUT CASE)
G17 G21 G90 G94
G0 X0. Y0. F600.
G5 I3. J4. P-3. Q4.
M2
