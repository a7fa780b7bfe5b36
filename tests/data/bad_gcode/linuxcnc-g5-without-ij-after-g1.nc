; expect: 7:1: G5 without I and J leaves in the direction the previous G5 arrived, but the move before this one is not a G5: write I and J (the first control point relative to the start)
(BAD INPUT CASE: a G1 between the two G5 breaks the series)
G17 G21 G90 G94
G0 X0. Y0. F600.
G5 X10. Y0. I3. J4. P-3. Q4.
G1 X12. Y0.
G5 X20. Y0. P-3. Q4.
M2
