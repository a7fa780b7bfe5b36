; expect: 6:13: X is unknown here (after G500 on line 5): BSPLINE starts at the current position; move there with G0 or G1 first
; dialect: siemens
N10 G17 G710 G90 G94
N20 G1 X0. Y0. Z0. F600.
N25 G500
N30 BSPLINE X5. Y10. PL=1.
N40 X15. Y12. PL=1.
N50 X20. Y0. PL=1.
N60 G1 X1.
