; expect: 5:13: SD=4: the degree of a BSPLINE is 2 or 3 (SD=2, SD=3)
; dialect: siemens
N10 G17 G710 G90 G94
N20 G1 X0. Y0. Z0. F600.
N30 BSPLINE SD=4 X10. Y5. PL=1.
N40 M30
