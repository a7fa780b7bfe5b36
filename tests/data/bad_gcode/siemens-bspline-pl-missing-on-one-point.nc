; expect: 7:1: control point without PL in a BSPLINE whose other points have one: write PL= on every control point
; dialect: siemens
N10 G17 G710 G90 G94
N20 G1 X0. Y0. Z0. F600.
N30 BSPLINE X10. Y5. PL=1.
N40 X20. Y0. PL=1.
N50 X30. Y5.
N60 X40. Y0. PL=1.
N70 G1 X50.
N80 M30
