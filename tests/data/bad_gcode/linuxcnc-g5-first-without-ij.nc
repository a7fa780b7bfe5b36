; expect: 5:1: G5 without I and J leaves in the direction the previous G5 arrived, but the move before this one is not a G5: write I and J (the first control point relative to the start)
(BAD INPUT CASE)
G17 G21 G90 G94
G0 X0. Y0. F600.
G5 X10. Y0. P-3. Q4.
M2
