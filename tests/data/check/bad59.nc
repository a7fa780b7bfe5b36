(nurbsfeed: 1 curve from bad59.json)
G21 G90
G0 X0.6745 Y-5.0809 Z0.
(nurbsfeed: curve 0 curve0, 2 points, period 1 ms, rk2c, length 9.743 mm, planned cycle 0.001 s)
G1 X6.5068 Y2.7231 F584555.644
M2
