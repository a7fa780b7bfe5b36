; expect: 5:8: X has no number after it (found '=IC(5) Y'); expressions, AC(), IC() and R parameters are not supported: write e.g. X=10.5
; dialect: siemens
N10 G17 G710 G90 G94
N20 G1 X0. Y0. Z0. F600.
N30 G1 X=IC(5) Y0.
N40 M30
