; expect: 5:5: G1 and BSPLINE are both motion commands; one per block
; dialect: siemens
N10 G17 G710 G90 G94
N20 G1 X0. Y0. Z0. F600.
N30 G1 BSPLINE X10. Y5. PL=1.
N40 M30
