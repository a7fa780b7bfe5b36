; expect: 5:5: '２' is not one of the digits 0-9 (full-width and other scripts' digits are not G-code numbers)
%
G17 G21 G90 G94
G0 X0. Y0. Z0.
G1 X２５. F100.
M30
%
