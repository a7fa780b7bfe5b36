; expect: 5:1: Y is unknown here (no move has set it since the start of the program): G5 starts at the current position; move there with G0 or G1 first
(BAD INPUT CASE)
G17 G21 G90 G94
G0 X0. F600.
G5 X10. Y0. I3. J4. P-3. Q4.
M2
