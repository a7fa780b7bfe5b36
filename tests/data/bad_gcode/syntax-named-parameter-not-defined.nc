; expect: 7:5: Named parameter #<dept> not defined (LinuxCNC): assign it (#<dept> = value) on an earlier line
%
O2000 (BAD INPUT CASE: a typo in a parameter name)
#<depth> = 2.
G17 G21 G40 G49 G80 G90 G94
G0 X0. Y0. Z5.
G1 Z-#<Dept> F800.
G0 Z5.
M30
%
