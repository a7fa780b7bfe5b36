; expect: 7:5: M8 does not belong in a BSPLINE control point (N X Y Z PL PW)
; dialect: siemens
N10 G17 G710 G90 G94
N20 G1 X0. Y0. Z0. F600.
N30 BSPLINE X10. Y5. PL=1.
N40 X20. Y0. PL=1.
N50 M8
N60 M30
