#pragma once
// Choi et al. 2005 (Choi, Lee, Jung, Yang 2005): the surface roughness R_max left by a ball
// end mill, extended to the region where the tool tip cuts, and its inverse, the
// feed law that holds a target R_max. The forms are those of the seed digest
// (docs/seed-digest.md, section 000), which were checked against the paper's numbers.
//
// Symbols as in the paper; lengths in mm, angles in rad:
//   r ball radius, f_p pick feed (path interval), f_t feed per tooth, n flutes,
//   S spindle speed [rpm], α feed inclination angle (between the path tangent and
//   the plane normal to the tool axis), α_c the critical inclination angle.
//
// Preconditions for the model functions: r > 0, f_p > 0, 0 <= f_t <= r. The model
// is meaningful for f_t between about 0.53·f_p and f_p (paper, Fig. 7: below that
// α_c = 0 and the tool tip never dominates).
//
// Region I (|α| < α_c, eq. 3) is exactly where the tool tip's protrusion is higher
// than the region II surface (eq. 2 with p = f_p/(2π)), so
// rmax_extended = max(rmax_region1, rmax_region2 with the feed-law phase), and the
// feed law is the smaller of eq. 5 and eq. 6; roughness_test checks both identities.
#include <Eigen/Core>
#include <string>

namespace cnc::process {

// α = asin(|t_z| / |t|) for a vertical tool (axis Z), in [0, π/2]; 0 for a zero or
// non-finite tangent.
double feed_inclination_angle(const Eigen::Vector3d& tangent);

// Eq. 1, the classic model: cutter mark plus cusp, on a surface with radii of
// curvature rho_f (feed direction) and rho_p (pick direction); +inf for a flat one.
double rmax_classic(double r, double f_t, double f_p, double rho_f, double rho_p);

// The phase shift p of eq. 2 that the feed law uses (digest: it reproduces the
// paper's numbers): f_p / (2π).
double phase_feed_law(double f_p);

// The paper's general phase shift: (f_t/π)·f_p/(r·sin|α|), clamped to [0, f_t/2]
// (f_t/2 at α = 0).
double phase_general(double r, double f_t, double f_p, double alpha);

// Eq. 2, region II (|α| > α_c: the tool tip does not cut):
// f_p²/(8r)·[1 + ((f_t − p)/f_p)²].
double rmax_region2(double r, double f_t, double f_p, double phase);

// Eq. 3 as the digest corrects it, region I (|α| <= α_c: the tool tip leaves cutting
// remains): r·[1 − sqrt(1 − (f_t/r)² + sin²α)], evaluated without cancellation.
// Negative where sin|α| > f_t/r, far outside region I.
double rmax_region1(double r, double f_t, double alpha);

// Eq. 4: α_c = asin((1/r)·sqrt((A/(8r))² − A/4 + f_t²)), A = f_p² + (f_t − f_p/(2π))²,
// the angle where eq. 3 equals A/(8r). 0 where the root's argument is negative (the
// tool tip never dominates), π/2 where the asin's argument exceeds 1.
double critical_angle(double r, double f_t, double f_p);

// Region I when |α| < α_c(f_t), else region II with p = f_p/(2π). At |α| = α_c the
// two agree, so which side the boundary belongs to does not matter.
double rmax_extended(double r, double f_t, double f_p, double alpha);

// The feed per tooth that gives R_max = rmax at inclination α (eqs. 5, 6).
// The region: f_t^II from eq. 5; region II iff |α| >= α_c(f_t^II), else eq. 6. This
// is consistent with rmax_extended, continuous at α_c (eq. 6 at α_c(f_t^II) gives
// f_t^II) and non-decreasing in |α|. rmax is clamped to [f_p²/(8r), r]: below the
// cusp height f_p²/(8r) no feed meets the target, and the clamp gives the feed of
// least roughness, f_p/(2π).
double feed_per_tooth_for_rmax(double r, double f_p, double rmax, double alpha);

// The recommended target: the isotropic surface, cutter-mark height equal to the
// cusp height: f_p²/(4r).
double isotropic_target_rmax(double r, double f_p);

// The feed law for one tool and path: F = n·S·f_t.
struct RoughnessLaw {
  double ball_radius_mm = 0;
  int flutes = 0;
  double pick_feed_mm = 0;
  double target_rmax_mm = 0;

  // "" when usable, else what is wrong (the target must lie in [f_p²/(8r), r)).
  std::string validate() const;
  double feed_mm_per_min(double spindle_rpm, double alpha) const;
};

}  // namespace cnc::process
