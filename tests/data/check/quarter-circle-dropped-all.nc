(nurbsfeed: 1 curve from quarter-circle.json)
G21 G90
G0 X10. Y0. Z0.
(nurbsfeed: curve 0 quarter-circle-r10, 379 points, period 1 ms, rk2c, length 15.708 mm, planned cycle 0.378 s)
G1 X0. Y10. F3.
M2
