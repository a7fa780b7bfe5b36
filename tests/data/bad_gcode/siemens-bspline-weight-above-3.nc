; expect: 6:14: PW=3.5: a point weight is above 0 and at most 3
; dialect: siemens
N10 G17 G710 G90 G94
N20 G1 X0. Y0. Z0. F600.
N30 BSPLINE X10. Y5. PL=1.
N40 X20. Y0. PW=3.5 PL=1.
N50 M30
