//! Why [`Lambert`]'s node bounds hold: the derivations of the multipole
//! series and the second-order Taylor bounds ([`BoundKind`]), every
//! inequality with its domain, and the rounding each bound is widened by.
//! [`Lambert`]'s docs state the model, the domain, the paper's bound and
//! the box refinements, and what the series and Taylor bounds certify.
//! This module is documentation only; the code is in `node` (the geometry
//! every kind shares, the paper's and the box's intervals, their
//! intersection), `series` (the expansion through degree 2 and the
//! remainder's width) and `taylor`; `group` evaluates the series in `f32`
//! lanes with its own rounding analysis, and `shared` takes it over a
//! group of shading points.
//!
//! From [`Lambert`]'s docs: a node of intensity `I`, centroid `c`, radius
//! `R`, seen from the point `p` with unit normal `n` at distance
//! `D = |c - p| > R`; `g(x) = n.(x - p) / |x - p|^3` is the smooth term and
//! `f = max(0, g)` the model's, which exceeds `g` only below the tangent
//! plane, by at most the clamp term `I_k depth / (D - R)^3` per channel
//! (or, in `f64`, `I_k min(depth, chord_k) / (D - R)^3`: see the chord in
//! [`Lambert`]'s docs).
//! The slab bound for nodes the tangent plane cuts (convexity of `h^+` on
//! each cut slice, and a second-order expansion of `|x - p|^-3` under the
//! non-negative weights `I_ik h_i` of the slices wholly above) is derived in
//! full in [`Lambert`]'s docs, "Nodes the tangent plane cuts", and coded in
//! `slab`.
//!
//! Every bound below holds per channel `k` whenever the node's cone exists
//! (`D - R > D * MIN_CLEARANCE`, see [`Cone::new`]), for any unit normal,
//! including nodes that straddle the tangent plane.
//!
//! # Multipole series
//! [`BoundKind::Series`], the default. Notation:
//! `y = x - c`, `u = c - p`, `uh = u / D`, `sigma = R / D < 1`,
//! `s = |y| / D <= sigma`, `t = -uh . y^` (the cosine between `y` and `-uh`),
//! `c0 = n . uh`, `nperp = n - c0 uh`, `nu = |nperp|`, `P_m` the Legendre
//! polynomials, and per channel `k` the node's intensity `I_k`, first moment
//! `o_k` ([`Node::channel_offsets`]) and second moment matrix `S_k`
//! ([`Node::channel_covariances`]).
//!
//! *Expansion.* `g(u + y) = -n . grad_y (1 / |u + y|)` (a dipole), and
//! `1 / |u + y| = sum_l |y|^l P_l(t) / D^(l+1)` for `|y| < D` (the generating
//! function of the Legendre polynomials). Differentiating term by term with
//! `grad_y (r^l P_l(t)) = -r^(l-1) [P_(l-1)'(t) y^ + P_l'(t) uh]` (from
//! `l P_l - t P_l' = -P_(l-1)'`) and then `P_(m+1)' - t P_m' = (m+1) P_m`:
//!
//! ```text
//! g(u + y) = D^-2 sum_(m>=0) a_m(y),
//! a_m(y) = s^m [c0 (m+1) P_m(t) + (nperp . y^) P_m'(t)],
//! ```
//!
//! absolutely convergent for `s < 1`; `D^-2 a_m` is the degree-`m` Taylor
//! term of `g` about `c`, a homogeneous harmonic polynomial of degree `m` in
//! `y`. Degrees 0 to 2 written out (`sum_i I_ik y_i = I_k o_k`,
//! `sum_i I_ik y_i y_i^T = I_k S_k`):
//!
//! ```text
//! E_k = I_k / D^2 [c0 + (n.o_k - 3 c0 uh.o_k) / D
//!                  + (15 c0 uh.S_k.uh - 3 c0 tr S_k - 6 uh.S_k.n) / (2 D^2)]
//! ```
//!
//! is the exact sum of the first three terms over the members.
//!
//! *Degrees 3 to 5: harmonic norms.* Write
//! `nperp . y^ = nu sqrt(1 - t^2) cos phi` (`phi` the azimuth of `y^` about
//! `uh`, from `nperp`). On the unit sphere `a_m` is a spherical harmonic `Y`
//! of degree `m`; expand it in the `2m + 1` Schmidt
//! semi-normalised real harmonics, `Y = sum_j beta_j R_mj`. Their mean
//! squares over the sphere are `1 / (2m + 1)`, so
//! `|beta|^2 = (2m + 1) mean(Y^2)`, and from `mean(P_m^2) = 1 / (2m + 1)`,
//! `mean((1 - t^2) P_m'^2 cos^2 phi) = m (m+1) / (2 (2m + 1))` and a cross
//! term odd in `cos phi`:
//! `|beta|^2 = c0^2 (m+1)^2 + nu^2 m (m+1) / 2 =: A_m^2`. With the node's
//! moments `C_j = sum_i I_ik |y_i|^m R_mj(y^_i)`, whose norm is
//! `|C| = q_mk I_k R^m` ([`Node::harmonic_norms`]), Cauchy-Schwarz gives
//!
//! ```text
//! |sum_i I_ik a_m(y_i)| = D^-m |beta . C| <= I_k A_m sigma^m q_mk.
//! ```
//!
//! This captures the cancellation between members that pointwise bounds
//! miss. The zonal part alone (`Y = P_m(t)`, `|beta| = 1` by the addition
//! theorem) gives `|c0| (m+1) sigma^m q_mk` for the `c0` term, and the
//! `nperp` term is bounded pointwise with `|P_m'| <= m (m+1) / 2` and
//! `|nperp . y| <= hperp`, the largest `|nperp . (x - c)|` over the node's box:
//!
//! ```text
//! |sum_i I_ik a_m(y_i)| <= I_k [|c0| (m+1) sigma^m q_mk + (hperp / D) m (m+1) / 2 mu_(m-1)],
//! ```
//!
//! with `mu_j = sum_i I_ik s_i^j / I_k <= sigma^(j-2) mu_2`,
//! `mu_2 = tr(S_k) / D^2`. At grazing angles (`c0` small) over flat clusters
//! (`hperp` small) this second form is far smaller. Each degree takes the
//! smaller. (The classical pointwise bound, `|a_m| <= s^m (m+1)` from
//! Sonin's inequality, is never smaller than the first form, since
//! `A_m <= m + 1` and `sigma^m q_mk <= mu_m`.)
//!
//! *Tail from degree 6.* Sonin's inequality
//! `m (m+1) P_m^2 + (1 - t^2) P_m'^2 <= m (m+1)` (by Legendre's equation
//! `F = P_m^2 + (1 - t^2) P_m'^2 / (m (m+1))` has `F' = 2 t P_m'^2 / (m (m+1))`,
//! so `F` is largest at `t = +-1`, where it is 1) and Cauchy-Schwarz on
//! `a_m / s^m = c0 (m+1) P_m + nu sqrt(1 - t^2) P_m' cos phi`, pairing
//! `(c0 sqrt((m+1)/m), nu cos phi)` with `(sqrt(m (m+1)) P_m, sqrt(1 - t^2) P_m')`,
//! give `|a_m| <= (m+1) s^m`.
//! With `mu_m <= sigma^(m-6) mu_6` the tail closes:
//! `sum_(m>=6) (m+1) mu_m <= mu_6 G1`, `G1 = 7 / (1 - sigma) + sigma / (1 - sigma)^2`.
//! The `hperp` form gives `|c0| mu_6 G1 + (hperp / D) mu_5 G2` with
//! `G2 = sum_(j>=0) (6+j)(7+j)/2 sigma^j
//!     = [42 / (1 - sigma) + 13 sigma / (1 - sigma)^2 + sigma (1 + sigma) / (1 - sigma)^3] / 2`;
//! the smaller is used.
//!
//! *Interval.* With `rho_k` the sum of the degree 3 to 5 bounds and the tail
//! (times `I_k / D^2`), `sum_i I_ik g(x_i)` lies in `[E_k - rho_k, E_k + rho_k]`,
//! which the clamp term (see the top) widens upward; intersected with the paper's
//! interval and the box's, times `kd_k`. The estimate is the final
//! interval's midpoint, which minimises the certified error
//! `max(estimate - lower, upper - estimate)`.
//!
//! # Second-order Taylor bound
//! [`BoundKind::Taylor`]. Taylor's theorem
//! for `g` about `c` gives, per channel `k`,
//!
//! ```text
//! sum_i I_ik g(x_i) = I_k g(c) + grad g(c) . (I_k o_k) + sum_i I_ik rem_i,
//! |rem_i| <= 1/2 sum_jl sup|H_jl| |x_ij - c_j| |x_il - c_l|
//! ```
//!
//! with `H` the Hessian of `g` over the ball. The estimate includes the
//! first-order term, so the error is second order. By Cauchy-Schwarz,
//! `sum_i I_ik |x_ij - c_j||x_il - c_l| <= I_k sqrt(S_k,jj S_k,ll)` with
//! `S_k` expressed in a frame `e1` (horizontal, towards `c`), `e2`
//! (horizontal), `e3 = n`. In units of `D` (`rho = 1 - R/D`,
//! `z+ = |cos theta_c| + R/D`, `a+ = sin theta_c + R/D`, `b+ = R/D`,
//! `t_a = min(1, (a+/rho)^2)`, likewise `t_b`, `t_z`, `q = z+/rho^5`) the
//! Hessian entries are bounded over the ball by
//!
//! ```text
//! |H11| <= q max(3, 15 t_a - 3)     |H12| <= 15 q min(sqrt(t_a t_b), 1/2)
//! |H22| <= q max(3, 15 t_b - 3)     |H13| <= sqrt(t_a) max(3, 15 t_z - 3) / rho^4
//! |H33| <= 9 q                      |H23| <= sqrt(t_b) max(3, 15 t_z - 3) / rho^4
//! ```
//!
//! and, isotropically, `||H|| <= 6 / rho^4` (the spectral norm of the Hessian
//! of `z/r^3` at unit distance is at most 6, reached along the normal). The
//! remainder uses the smaller of the per-axis and the isotropic sums. The
//! estimate, the Taylor sum plus half the clamp term, is clamped into the
//! final interval.
//!
//! # Rounding
//! Cosine bounds are widened by [`COS_SLACK`]. The series
//! bound widens its estimate by [`SERIES_SLACK`] of its terms' magnitudes,
//! by [`POINT_SLACK`](crate::numeric::POINT_SLACK) for the offset `c - p`, by
//! `f32::EPSILON (|o_k|_1 / D + 33 tr(S_k) / D^2)` for the `f32` storage of
//! the moments (offsets rounded to nearest move the degree-1 term by at most
//! `|grad| |o|_1 f32::EPSILON / 2 / D`, `|grad| <= 2`; the stored entries of
//! `S_k` are within `f32::EPSILON tr(S_k)` of the `f64` ones, moving each
//! quadratic form by at most `3 f32::EPSILON tr(S_k)`, and the degree-2 term
//! by `(15 * 3 + 3 + 6 * 3) / 2 = 33` of those), and by
//! `2 delta (sigma + 18 sigma^2)` for the build's `f64` sums of the
//! members' moments (each entry within `delta I_k R^j` of exact,
//! `delta` the node's [`Node::moment_error`]);
//! its remainder by [`SERIES_SLACK`] as documented there. Stored diagonals
//! of `S_k` and harmonic norms are rounded upward at build time, after an
//! allowance for their `f64` sums. The Taylor bound widens its estimate by
//! [`SECOND_ORDER_SLACK`] of its terms' magnitudes, by [`COS_SLACK`] times
//! `I_k / D^2` for the cosine, and by `f32::EPSILON` of the first-order
//! term, and by the same `2 delta (sigma + 18 sigma^2)` as the series for
//! the build's moment sums; the quadratic forms of `S_k` by
//! `f32::EPSILON * tr(S_k)`.
//!
//! [`Lambert`]: super::Lambert
//! [`BoundKind`]: super::BoundKind
//! [`BoundKind::Series`]: super::BoundKind::Series
//! [`BoundKind::Taylor`]: super::BoundKind::Taylor
//! [`Cone::new`]: crate::shader::Cone::new
//! [`Node::channel_offsets`]: crate::shader::Node::channel_offsets
//! [`Node::channel_covariances`]: crate::shader::Node::channel_covariances
//! [`Node::harmonic_norms`]: crate::shader::Node::harmonic_norms
//! [`Node::moment_error`]: crate::shader::Node::moment_error
//! [`COS_SLACK`]: crate::numeric::COS_SLACK
//! [`SERIES_SLACK`]: crate::numeric::SERIES_SLACK
//! [`SECOND_ORDER_SLACK`]: crate::numeric::SECOND_ORDER_SLACK
