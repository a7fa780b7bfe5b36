; expect: 6:1: X20. without a G code after the G5.1 on line 5: LinuxCNC moves it in G0, the mode before the spline, but the G1 moves written in place of the spline leave G1 in force: write G0 on this line
(BAD INPUT CASE)
G17 G21 G90 G94
G0 X0. Y0. F600.
G5.1 X10. Y10. I10. J0.
X20. Y0.
M2
