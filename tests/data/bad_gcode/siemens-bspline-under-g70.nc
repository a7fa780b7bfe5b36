; expect: 5:5: BSPLINE under G70 (line 3): F stays in the machine's basic unit, which the program does not say; write G700 (inch, F in inch/min) or G710
; dialect: siemens
N10 G17 G70 G90 G94
N20 G1 X0. Y0. Z0. F20.
N30 BSPLINE X1. Y0.5 PL=1.
N40 X2. Y0. PL=1.
N50 X3. Y0. PL=1.
N60 X4. Y1. PL=1.
N70 M30
