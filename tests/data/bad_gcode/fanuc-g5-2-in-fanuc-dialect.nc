; expect: 8:1: G5.2 is LinuxCNC's NURBS block; read this file with --dialect linuxcnc (or auto)
; dialect: fanuc
%
O2000 (BAD INPUT CASE)
G17 G21 G40 G49 G80 G90 G94
G0 X0. Y0. Z5.
G1 Z-1. F800.
G5.2 P1
X10. Y10. P1
X20. Y0. P1
G5.3
G0 Z5.
M30
%
