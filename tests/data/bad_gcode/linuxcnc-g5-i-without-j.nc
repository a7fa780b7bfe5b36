; expect: 5:13: I3. alone: Must specify both I and J, or neither (LinuxCNC)
(BAD INPUT CASE)
G17 G21 G90 G94
G0 X0. Y0. F600.
G5 X10. Y0. I3. P-3. Q4.
M2
