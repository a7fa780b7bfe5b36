; expect: 6:20: F900. inside a BSPLINE: write it on the BSPLINE block or before it (nurbsfeed plans one feed per spline)
; dialect: siemens
N10 G17 G710 G90 G94
N20 G1 X0. Y0. Z0. F600.
N30 BSPLINE X10. Y5. PL=1.
N40 X20. Y0. PL=1. F900.
N50 M30
