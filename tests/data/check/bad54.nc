(nurbsfeed: 1 curve from bad54.json)
G21 G90
G0 X-16.4653 Y-7.7964 Z0.
(nurbsfeed: curve 0 curve0, 2 points, period 1 ms, rk2c, length 29.212 mm, planned cycle 0.001 s)
G1 X8.2328 Y7.8037 F1752738.814
M2
