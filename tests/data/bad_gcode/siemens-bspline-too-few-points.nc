; expect: 5:5: 3 control points are too few for SD=3, counting the start point: a B spline of degree 3 needs at least 4
; dialect: siemens
N10 G17 G710 G90 G94
N20 G1 X0. Y0. Z0. F600.
N30 BSPLINE X10. Y5. PL=1.
N40 X20. Y0. PL=1.
N50 G1 X30.
N60 M30
