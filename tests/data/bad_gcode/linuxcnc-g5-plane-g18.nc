; expect: 5:1: G5 in plane G18: Splines must be in the XY plane (LinuxCNC); select G17 first
(BAD INPUT CASE)
G18 G21 G90 G94
G0 X0. Y0. F600.
G5 X10. Y0. I3. J4. P-3. Q4.
M2
