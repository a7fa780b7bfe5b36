; expect: 7:1: X is unknown here (no move has set it since the start of the program): G5.2 starts the curve at the current position; move there with G0 or G1 first
%
(BAD INPUT CASE)
G17 G21 G40 G49 G80 G90 G94
G0 Y0.
F1000
G5.2
X10. Y10. P1
X20. Y0. P1
G5.3
G0 Z5.
M30
%
