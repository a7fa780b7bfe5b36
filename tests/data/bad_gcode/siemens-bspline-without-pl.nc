; expect: 5:5: BSPLINE without PL: the Sinumerik manual says the knot intervals are "suitably calculated internally" and does not publish the rule, so the path the controller cuts is not known; write PL= on every control point (as NX's Sinumerik post does)
; dialect: siemens
N10 G1 G64 X0 Y0 F300 G90 ; the manual's B spline example: no PL
; start point
N20 BSPLINE
N30 X10 Y20
N40 X20 Y40
N50 X30 Y30
N60 X40 Y45
N70 X50 Y0
N80 M30
