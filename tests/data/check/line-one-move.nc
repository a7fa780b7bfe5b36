(nurbsfeed: 1 curve from line.json)
G21 G90
G0 X0. Y0. Z0.
(nurbsfeed: curve 0 line, 365 points, period 1 ms, rk2c, length 44.721 mm, planned cycle 0.364 s)
G1 X40. Y20. F12000.
M2
