"""The real-time stage (design §3): from the time law's per-period targets to curve parameters
and points, stepped by one of three methods (rk2c, the paper's; rk4; taylor1).

The modules, in the order a curve runs through them:
  stepping      `Stepping.chunks` (a conversion) and `interpolate` (the analyses): one curve,
                stretch between rests by stretch, handed on in chunks of points
  landing       `Stretch`: one stretch, stepped and landed exactly on its end (sigma, the bump)
  targets       the per-period targets ds_k = s(t_k+1) - s(t_k) from the time law, at t_k = k T
  kernels       `step_spans`: the compiled rk2c / rk4 / taylor1 loop over the targets
  solved_steps  the steps the loop hands back (across a knot, beside a zero of C'), solved on
                the chord and arc equations; their arc comes from geometry.arclength
"""
