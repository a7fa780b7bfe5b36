; expect: 8:1: G6.2 under G91 is not supported (LinuxCNC does not document incremental G6.2 control points): program the curve in G90
%
O2000 (BAD INPUT CASE)
G17 G21 G40 G49 G80 G90 G94
G0 X0. Y0. Z5.
G1 Z-1. F800.
G91
G6.2 P3 Q1 K0 X0 Y0 Z0 F2000
K0 X10 Y10
K0 X10 Y-10
G6.2 K1
G6.2 K1
G6.2 K1
G0 Z5.
M30
%
