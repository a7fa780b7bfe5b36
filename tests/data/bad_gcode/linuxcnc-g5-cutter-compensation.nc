; expect: 6:1: G5 cannot run under cutter compensation G41 (since line 5): cancel it with G40 first (Fanuc alarm PS1006)
(BAD INPUT CASE)
G17 G21 G90 G94
G0 X0. Y0. F600.
G41 D1 G1 X1. Y0.
G5 X10. Y0. I3. J4. P-3. Q4.
M2
