; expect: 5:1: G5 without Q: Must specify both P and Q with G5 (LinuxCNC): P Q is the second control point relative to the end
(BAD INPUT CASE)
G17 G21 G90 G94
G0 X0. Y0. F600.
G5 X10. Y0. I3. J4. P-3.
M2
