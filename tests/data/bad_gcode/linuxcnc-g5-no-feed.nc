; expect: 5:1: no feed is in force: program an F (e.g. F600) before or in the NURBS block; without one the curve would run at the machine's maximum
(BAD INPUT CASE)
G17 G21 G90 G94
G0 X0. Y0.
G5 X10. Y0. I3. J4. P-3. Q4.
M2
