; expect: 6:1: no feed is in force: program an F (e.g. F600) before or in the NURBS block; without one the curve would run at the machine's maximum
%
(BAD INPUT CASE)
G17 G20
G0 X0 Y0
G5.2 X0 Y1 P1 L3
     X2 Y2 P1
     X2 Y0 P1
     X0 Y0 P2
G5.3
M2
%
