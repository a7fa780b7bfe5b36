(nurbsfeed: 1 curve from bad55.json)
G21 G90
G0 X19.0423 Y11.3461 Z0.
(nurbsfeed: curve 0 curve0, 2 points, period 1 ms, rk2c, length 42.181 mm, planned cycle 0.001 s)
G1 X6.3417 Y1.2585 F973156.56
M2
