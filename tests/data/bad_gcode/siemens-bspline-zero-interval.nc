; expect: 7:14: PL=0: the parameter interval of a span must be above 0
; dialect: siemens
N10 G17 G710 G90 G94
N20 G1 X0. Y0. Z0. F600.
N30 BSPLINE X10. Y5. PL=1.
N40 X20. Y0. PL=1.
N50 X30. Y5. PL=0
N60 X40. Y0. PL=1.
N70 X50. Y5. PL=1.
N80 M30
