; expect: 5:18: Y is unknown here (no move has set it since the start of the program): BSPLINE starts at the current position; move there with G0 or G1 first
; dialect: siemens
N10 G17 G710 G90 G94
N20 G1 X0. Z0. F600.
N30 BSPLINE X10. Y5. PL=1.
N40 X20. Y0. PL=1.
N50 X30. Y5. PL=1.
N60 X40. Y0. PL=1.
N70 M30
