; expect: 7:13: #105 is used before it is assigned (write #105=value on an earlier line)
%
O2000 (BAD INPUT CASE)
G17 G21 G40 G49 G80 G90 G94
G0 X0. Y0. Z5.
G1 Z-1. F800.
#105=2. G1 X#105
G0 Z5.
M30
%
