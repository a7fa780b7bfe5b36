; expect: 5:1: G1 and G5 are both motion codes; one per block
(BAD INPUT CASE)
G17 G21 G90 G94
G0 X0. Y0. F600.
G1 G5 X10. Y0. I3. J4. P-3. Q4.
M2
