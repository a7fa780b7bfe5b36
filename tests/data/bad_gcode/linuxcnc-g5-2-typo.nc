; expect: 7:1: G2.2 is a G code nurbsfeed does not know, and the G5.3 on line 11 closes a NURBS block nothing opened: write G5.2 to open it
%
(BAD INPUT CASE)
G17 G20
G0 X0 Y0
F100
G2.2 X0 Y1 P1 L3
     X2 Y2 P1
     X2 Y0 P1
     X0 Y0 P2
G5.3
M2
%
