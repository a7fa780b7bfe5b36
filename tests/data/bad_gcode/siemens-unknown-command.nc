; expect: 4:5: 'TRANS' is not a Sinumerik command nurbsfeed reads: it reads words (X10.5, G1, F300), BSPLINE with SD, PL, PW, and BRISK, CFC, CFIN, CFTCP, COMPCAD, COMPCURV, COMPOF, COMPON, DRIVE, FFWOF, FFWON, FNORM, SOFT, SPATH, SUPA, UPATH
; dialect: siemens
N10 G17 G710 G90 G94
N20 TRANS X10. Y5.
N30 M30
