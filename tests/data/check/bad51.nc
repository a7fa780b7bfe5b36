(nurbsfeed: 1 curve from bad51.json)
G21 G90
G0 X-19.4658 Y4.1487 Z0.
(nurbsfeed: curve 0 curve0, 2 points, period 1 ms, rk2c, length 70.173 mm, planned cycle 0.001 s)
G1 X1.5697 Y-19.6053 F1903754.5
M2
