#pragma once
// A flat end mill's engagement from the stock, for VMCS
// 1999's force model along a tool path. The stock is a Z-map (dexel columns); the
// tool removes its envelope as it moves (a flat end mill's edges leave the envelope
// on walls and floor up to feed marks far below the map's resolution).
//
// At a tool position (tip T, feed direction f in XY) the engagement is sampled on
// the tool's periphery in the front half, in the frame of cutting_force.h (feed along
// local +X, φ clockwise from local +Y, the periphery point at T + R·(sin φ·f + cos φ·n),
// n = f turned 90° to the left): at each of `bins` angles φ in (0, π) the axial depth
// a(φ) = clamp(stock height one cell outside the periphery − T_z, 0, flute length).
// Call it before removing the step that reaches T. Radial depth and the engaged arc follow from where a(φ) > 0, so corners
// and arcs get their changing engagement.
#include <Eigen/Core>
#include <vector>

#include "common/process/cutting_force.h"
#include "common/process/zmap.h"

namespace cnc::process {

struct EngagementProfile {
  std::vector<double> phi;    // bin centres in (0, π), rad
  std::vector<double> depth;  // axial depth a(φ), mm
  double feed_per_tooth_mm = 0;
  Eigen::Vector2d feed_dir{1.0, 0.0};  // unit, world XY
  double max_depth() const;
  double arc_start() const;  // first engaged bin's φ (lower edge), or 0 when none
  double arc_exit() const;   // last engaged bin's φ (upper edge)
  bool engaged() const { return max_depth() > 0.0; }
};

EngagementProfile engagement_from_stock(const ZMap& stock, const Eigen::Vector3d& tip, const Eigen::Vector2d& feed_dir,
                                        double radius, double flute_length, int bins, double feed_per_tooth);

// The same into *out, its vectors reused (no allocation once they hold `bins`).
void engagement_from_stock(const ZMap& stock, const Eigen::Vector3d& tip, const Eigen::Vector2d& feed_dir,
                           double radius, double flute_length, int bins, double feed_per_tooth, EngagementProfile* out);

// Lowers the stock to the envelope of a flat end mill (radius, tip heights
// interpolated) moving from tip0 to tip1.
void remove_flat_envelope(ZMap& stock, const Eigen::Vector3d& tip0, const Eigen::Vector3d& tip1, double radius);

// The force on the tool (world X, Y, Z) at rotation angle theta for an engagement
// profile: equal discs of at most dz_max up to the profile's largest depth, every
// element engaged where its (helix-lagged) φ lies in the front half and its height
// is below a(φ). disc_forces (optional) receives the per-disc world forces, disc i's
// centre at (i + 1/2)·dz above the tip, dz (the height used) in *dz_used.
Eigen::Vector3d force_from_profile(const CuttingForceModel& model, const EngagementProfile& p, double dz_max, double theta,
                                   std::vector<Eigen::Vector3d>* disc_forces = nullptr, double* dz_used = nullptr);

}  // namespace cnc::process
