#pragma once
// Choi et al. 2005's check: a Z-map of the surface a ball end mill leaves, from its rotating
// cutting edges rather than its envelope, so that feed marks, cusps and the tool
// tip's "cutting remains" appear.
//
// The grid holds one z column per cell centre (x0 + (i + 1/2)·pitch, y0 + (j + 1/2)·pitch).
// The tool is a ball of radius r whose n cutting edges are quarter arcs in planes
// through the tool axis (together a semicircle for n = 2, the paper's model): edge k
// at azimuth θ_k = θ(t) + 2πk/n reaches down to the tip, and at distance ρ ≤ r from
// the axis it is at z = C_z − sqrt(r² − ρ²), C the ball centre. The spindle turns
// clockwise seen from above (M3): θ(t) = θ0 − 2π·S·t/60. The centre follows the
// setpoint stream linearly between samples.
//
// The sweep is stepped by at most max_step_rad of rotation. During a step the edge
// sweeps a thin sliver; a cell is cut when the edge's plane passes over it within the
// step (the signed distances to the edge's line at the step's ends change sign); the
// crossing's fraction of the step is interpolated linearly, and the edge's height at
// that moment (centre and azimuth interpolated) lowers the column. Only the part of
// each edge that can reach below the current surface is rasterised: a tile pyramid of
// the grid's maxima bounds the radii worth visiting. Threads take bands of rows.
#include <Eigen/Core>
#include <functional>
#include <vector>

namespace cnc::process {

struct BallCutter {
  double radius_mm = 5.0;
  int flutes = 2;
};

struct ToolSample {
  double t_s = 0;
  Eigen::Vector3d center;  // ball centre, mm
};

struct ZMapCutOptions {
  double spindle_rpm = 10000;
  double theta0_rad = 0;
  double max_step_rad = 0.5 * 3.14159265358979323846 / 180.0;
  int threads = 1;
};

struct ZMapStats {
  long long steps = 0;
  long long cells_visited = 0;  // edge–column tests
  long long cells_cut = 0;      // columns lowered
};

class ZMap {
 public:
  ZMap(double x0, double y0, double pitch, int nx, int ny, double z_init);
  // Initial stock z(x, y) per cell centre.
  void fill(const std::function<double(double, double)>& z_of_xy);
  // Every column back to z (no allocation).
  void reset(double z);

  ZMapStats cut(const BallCutter& tool, const std::vector<ToolSample>& path, const ZMapCutOptions& opt);

  int nx() const { return nx_; }
  int ny() const { return ny_; }
  double pitch() const { return pitch_; }
  double x(int i) const { return x0_ + (i + 0.5) * pitch_; }
  double y(int j) const { return y0_ + (j + 0.5) * pitch_; }
  float z(int i, int j) const { return z_[static_cast<size_t>(j) * static_cast<size_t>(nx_) + static_cast<size_t>(i)]; }
  const std::vector<float>& data() const { return z_; }
  // The column holding (x, y), or NaN outside the grid.
  double sample(double px, double py) const;
  float& cell(int i, int j) {
    tiles_valid_ = false;
    return z_[static_cast<size_t>(j) * static_cast<size_t>(nx_) + static_cast<size_t>(i)];
  }
  double x0() const { return x0_; }
  double y0() const { return y0_; }

 private:
  friend struct ZMapBand;
  double x0_, y0_, pitch_;
  int nx_, ny_;
  std::vector<float> z_;
  std::vector<float> tile_max_;  // kept between cuts, see ZMapBand
  bool tiles_valid_ = false;
};

// Peak-to-valley of the deviation dev(x, y, z) (e.g. the distance from the nominal
// surface) over the cells [i0, i1) × [j0, j1).
double zmap_rmax(const ZMap& m, const std::function<double(double, double, double)>& dev, int i0, int i1, int j0,
                 int j1);

// R_max per block of bx × by cells (a map: blocks along x fastest).
struct RmaxMap {
  int bx = 0, by = 0, nbx = 0, nby = 0;
  std::vector<double> rmax;
};
RmaxMap zmap_rmax_map(const ZMap& m, const std::function<double(double, double, double)>& dev, int bx, int by);

// Choi et al. 2005's Z-map case: a plane inclined at α along X (feed direction), machined by
// parallel passes along +X, f_p apart in Y, each starting at the same X with the same
// spindle phase, at feed per tooth f_t. The window [0, wx] × [0, wy] is the middle of
// a cut that runs r beyond it on every side. Returns R_max (peak-to-valley of the
// distance from the nominal plane, along its normal) over the window.
struct InclinedPlaneCase {
  double radius_mm = 5.0;
  int flutes = 2;
  double pick_feed_mm = 0.5;
  double feed_per_tooth_mm = 0.5;
  double alpha_rad = 0.0;
  double window_x_mm = 1.0;
  double window_y_mm = 1.0;
  double pitch_mm = 0.0025;
  double allowance_mm = 0.05;  // stock above the nominal plane
  double max_step_rad = 0.5 * 3.14159265358979323846 / 180.0;
  double pass_phase_rad = 0.0;  // spindle phase added from one pass to the next
  int threads = 1;
};
struct InclinedPlaneResult {
  double rmax_mm = 0;
  ZMapStats stats;
  double seconds = 0;
  long long cells = 0;
};
InclinedPlaneResult simulate_inclined_plane(const InclinedPlaneCase& c, ZMap* keep = nullptr);

}  // namespace cnc::process
