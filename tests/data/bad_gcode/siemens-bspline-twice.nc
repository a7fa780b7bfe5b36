; expect: 8:5: BSPLINE inside the BSPLINE started on line 5: end that one with G1 (or another motion command) first
; dialect: siemens
N10 G17 G710 G90 G94
N20 G1 X0. Y0. Z0. F600.
N30 BSPLINE X10. Y5. PL=1.
N40 X20. Y0. PL=1.
N50 X30. Y5. PL=1.
N60 BSPLINE X40. Y0. PL=1.
N70 M30
