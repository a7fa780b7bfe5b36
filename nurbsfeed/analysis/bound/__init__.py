"""A jerk-limited time-optimal schedule along one curve: the reference `plan --reference`
compares with (`solve.jerk_limited_schedule`).

Independent of the planner by construction: nothing of `nurbsfeed.planning` runs here (only its
`Limits` record is read); the geometry comes from the curve's span polynomials
(`NurbsCurve.span_polynomials`), the optimisation from scipy's HiGHS.

Motion along C(s) at speed v, tangential acceleration a and tangential jerk j, with the
curvature vector K = kappa N and its arc-length derivative K_s = -kappa^2 T + kappa' N +
kappa tau B (both computed as vectors from C', C'', C''', so an inflection, kappa = 0, needs no
Frenet frame):

    velocity = v T,   acceleration = a T + v^2 K,   jerk = j T + 3 v a K + v^3 K_s.

In b = v^2 over arc length, a = b'/2 and j = sqrt(b) b''/2, so every jerk component is sqrt(b)
times an expression linear in (b, b', b''):  jerk = sqrt(b) (b''/2 T + 3/2 b' K + b K_s).

Constraint models (`Limits.jerk_model`):
- "paper", what the planner enforces: v <= min(feed, chord limit (2/T) sqrt(2 rho delta -
  delta^2), saturating at 2 rho / T once delta >= rho, sqrt(A_n / kappa), cbrt(J_n / kappa^2)),
  |a| <= A_t, |j| <= J_t (j the time law's jerk).
- "path", what the machine feels: the same speed caps without the cbrt(J_n / kappa^2) proxy,
  |a| <= A_t, kappa v^2 <= A_n, |jerk . T| <= J_t, |jerk across T| <= J_n, and per axis
  |velocity_x| <= V_x, |acceleration_x| <= A_x, |jerk_x| <= J_x where given. At a knot where
  kappa N jumps by D the acceleration jumps by v^2 D, which positions one period apart read
  as a jerk v^2 |D| / T: it adds to the normal jerk and to each axis's (|D_x|) there.

The schedule is a C1 piecewise quadratic b(s) on a grid of nodes (variables: b and its slope
b' at each node; on each cell b'' is constant), so a = b'/2 is continuous and j is bounded: the
motion it describes is jerk-limited between the nodes too, however long a cell lasts. A cell
beside a rest (the ends, a corner or a cusp, where the motion must stop) is
b = b_far (x)^(4/3), x the distance to the rest over the cell's length: constant jerk from rest,
a = 0 at the rest, the shape of the time-optimal start (a quadratic with a = 0 there would never
leave the rest). The constraints are imposed at each cell's ends and middle.

Method: sequential linear programming. The jerk constraints are sqrt(b) L(b, b', b'') <= J with
L linear; with sqrt(b) frozen at the previous iterate they are linear, and the LP (HiGHS, sparse)
maximises the integral of b inside a trust region around that iterate. Each iterate is made
exactly feasible at the constraint points by the uniform time scaling lambda >= 1 (v / lambda,
a / lambda^2, jerk / lambda^3 keep every limit) and judged by its scaled cycle time; a worse one
shrinks the trust region. The best scaled iterate is the result: a schedule that keeps every
constraint at every constraint point, so its cycle time is one that a jerk-limited motion
reaches (on a finer grid it can only get shorter).

Grid: the knot spans, each cut so that a cell turns the tangent by at most MAX_TURN_RAD, changes
kappa by at most MAX_KAPPA_CHANGE_REL and is at most MAX_CELL_PERIODS periods of travel at the
feed cap long; cells beside a rest are cut down to REST_CELL_SHARE of the distance a jerk-limited
start takes to reach A_t.

The modules, in the order the method runs: frames (C and its derivatives, T, K, K_s at any u),
grid (the rests and the cells), constraints (the constraint points and the rows of each limit),
solve (the sequential linear programs, scipy's HiGHS: the only module that imports scipy),
schedule (the result, `BoundSchedule`, sampled at any time).
"""
