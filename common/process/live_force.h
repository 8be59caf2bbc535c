#pragma once
// VMCS 1999's cutting force and tool deflection along a running
// tool path, for the monitor (per setpoint) and the interpolator's planner (the
// force feed limit). The engagement comes from a Z-map stock (engagement.h) that the
// flat end mill's envelope is removed from as the tool moves, as `cnc-predict
// program` does offline; the stock is the machine config's box (cutting.stock).
//
// At a tool position the engagement profile (180 bins over the front half) is read
// from the stock, then the force (force_from_profile, discs of at most
// disc_height_mm) is evaluated at angles_per_tooth rotation angles over one tooth
// period. An estimate holds the mean force over that period, the peak |F| in XY and
// the peak tool-tip deflection |δ(0)| (the cantilever of deflection.h). The feed per
// tooth is the feed in XY (a plunge feeds no chip into the periphery): c = v_xy/(N·n).
//
// Everything is sized at construction: estimate(), limit_feed_per_tooth() and
// remove() allocate nothing (the monitor runs them per setpoint). The cost of one
// estimate is bins + angles × discs × flutes element forces (16 × 30 × 4 for a 3 mm
// deep cut), remove() the cells under the swept disc.
#include <Eigen/Core>
#include <string>
#include <vector>

#include "common/config/machine_config.h"
#include "common/process/cutting_force.h"
#include "common/process/deflection.h"
#include "common/process/engagement.h"
#include "common/process/zmap.h"

namespace cnc::process {

// The tool, material and force law of a machine config's cutting section, loaded.
// Errors name the config key (cutting.tool, cutting.material, cutting.model) and the
// file's own key path.
struct CuttingSetup {
  EndMill tool;
  Material material;
  ForceModel model = ForceModel::kLinearEdge;
};
CuttingSetup load_cutting_setup(const config::MachineConfig& cfg);

struct ForceEstimate {
  bool engaged = false;
  Eigen::Vector3d mean_force = Eigen::Vector3d::Zero();  // N, world axes, mean over a tooth period
  double peak_force_n = 0;       // max |F_xy| over the tooth period
  double peak_deflection_mm = 0;  // max |δ| at the tool tip over the tooth period
  double radial_depth_mm = 0;     // ae from the engaged arc (for reports)
  double axial_depth_mm = 0;      // the profile's largest depth
};

class LiveForce {
 public:
  LiveForce(const CuttingSetup& setup, const config::CuttingConfig& cfg);

  // The stock back to the uncut box.
  void reset();
  // Reads the engagement at `tip` for feed direction `feed_dir` (XY, need not be unit)
  // from the current stock into the estimator (call before remove() reaches tip).
  void engage(const Eigen::Vector3d& tip, const Eigen::Vector2d& feed_dir);
  // Force and deflection at the last engagement for feed per tooth c (XY), mm.
  ForceEstimate estimate(double feed_per_tooth);
  // The largest feed per tooth in (0, c_max] whose estimate keeps the peak deflection
  // within the tolerance (and the peak force within max_force_n when set): c_max when
  // that already holds, else by bisection on log c (the estimate grows with c), never
  // below c_max·1e-3. *binding: whether the limit is below c_max.
  double limit_feed_per_tooth(double c_max, bool* binding);
  // Removes the tool's envelope from tip0 to tip1 (straight, tip heights interpolated).
  void remove(const Eigen::Vector3d& tip0, const Eigen::Vector3d& tip1);

  const EndMill& tool() const { return model_.tool(); }
  double tolerance_mm() const { return cfg_.deflection_tolerance_mm; }
  double max_force_n() const { return cfg_.max_force_n; }
  const ZMap& stock() const { return stock_; }
  const EngagementProfile& profile() const { return profile_; }

 private:
  bool within(const ForceEstimate& e) const;

  config::CuttingConfig cfg_;
  CuttingForceModel model_;
  CantileverTool beam_;
  ZMap stock_;
  EngagementProfile profile_;
  std::vector<Eigen::Vector3d> discs_;
  std::vector<double> heights_;
};

}  // namespace cnc::process
