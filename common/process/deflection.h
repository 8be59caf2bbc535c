#pragma once
// VMCS 1999, section 2.2–2.3: the tool as a cantilever under the distributed disc
// loads, and the error of the wall it machines.
//
// Eq. 13 (u measured from the holder, a load dF at l from it):
//   δ(u) = Σ dF/(6EI)·[⟨u − l⟩³ − u³ + 3u²·l],   ⟨x⟩ = x for x > 0, else 0,
// i.e. u²(3l − u)/(6EI)·dF below the load and l²(3u − l)/(6EI)·dF beyond it;
// I = π·D_e⁴/64 with D_e = 0.8·D (eq. 14, Kops). The holder is overhang_mm above
// the tip; the loads are the disc forces at the disc centres.
//
// Surface error (Fig. 7, eqs. 15–16): a wall point at height SG above the tip is
// generated when the flute element at SG passes the wall's angle φ_w (φ_w = 0 for up
// milling, π for down milling, see cutting_force.h). That element lags the bottom
// one by SG·tan(h)/R, so the tool's rotation angle then is θ = φ_w + SG·tan(h)/R
// (eq. 15 with θ measured from the bottom element's generating position). The force
// model is evaluated at that angle directly (the paper rounds it to the nearest
// angular index, eq. 16), and the surface error is the deflection at SG along the
// wall's normal: positive when the tool is pushed away from the wall and leaves
// material (undercut), negative when it cuts into it.
#include <Eigen/Core>
#include <vector>

#include "common/process/cutting_force.h"

namespace cnc::process {

class CantileverTool {
 public:
  explicit CantileverTool(const EndMill& tool);
  double inertia_mm4() const { return inertia_; }  // π·D_e⁴/64
  double ei() const { return ei_; }                // E·I, N·mm²
  double length() const { return length_; }
  // Deflection at height z above the tip under loads (x, y used) at load_heights.
  Eigen::Vector2d deflection(double z, const std::vector<double>& load_heights,
                             const std::vector<Eigen::Vector3d>& loads) const;
  // δ at u from the holder under a unit load at l from it (eq. 13 for one load).
  double influence(double u, double l) const;

 private:
  double length_;
  double inertia_;
  double ei_;
};

struct WallErrorPoint {
  double height_mm = 0;             // SG
  double theta = 0;                 // rotation angle at generation, rad
  Eigen::Vector3d force;            // total force then, N
  Eigen::Vector2d deflection;       // at SG, mm
  double surface_error_mm = 0;      // along the wall normal, + = material left
};

// The wall's angle for an engagement: φ_start when the cut starts at 0 (up milling),
// else φ_exit (down milling; a slot: the up-milling wall, pass the other explicitly).
double wall_angle(const Engagement& e);

// Surface error at `points` heights SG_p = (p + 1/2)·a/points over the axial depth.
std::vector<WallErrorPoint> wall_surface_error(const CuttingForceModel& model, const Engagement& e, int points,
                                               double wall_phi);

// A wall along the feed with changing engagement: one profile per position.
struct WallSection {
  double x_mm = 0;
  Engagement engagement;
};
struct WallErrorMap {
  std::vector<double> x_mm;
  std::vector<double> height_mm;
  std::vector<std::vector<double>> error_mm;  // [x][height]
  double max_abs_mm = 0;
};
WallErrorMap wall_error_map(const CuttingForceModel& model, const std::vector<WallSection>& sections, int points);

}  // namespace cnc::process
