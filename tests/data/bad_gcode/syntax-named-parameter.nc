; expect: 7:1: '#' must be followed by a parameter number (#1=10.5, X#1); named (#<name>) and indirect (##1) parameters are not supported
%
O2000 (BAD INPUT CASE)
G17 G21 G40 G49 G80 G90 G94
G0 X0. Y0. Z5.
G1 Z-1. F800.
#<depth>=2
G1 Z-#<depth>
G0 Z5.
M30
%
