; expect: 5:5: CSPLINE (cubic spline) is not supported: nurbsfeed reads BSPLINE, whose control points and knots make a NURBS
; dialect: siemens
N10 G17 G710 G90 G94
N20 G1 X0. Y0. Z0. F600.
N30 CSPLINE X10. Y5.
N40 M30
