#pragma once
// G-code out for every CAM command: a header (units mm G21, XY plane G17, absolute
// G90, work offset G54, the tool and its spindle start), G0/G1 moves with modal words
// left out where they repeat, and a footer (retract, spindle stop, end). Coordinates
// are written with 4 decimals, so a written point lies within 5e-5 mm of the given
// one on each axis.
#include <cstddef>
#include <string>
#include <vector>

#include "common/cam/cutter.h"
#include "common/cam/mesh.h"

namespace cnc::cam {

struct GcodeSetup {
  std::string title;              // a comment line; parentheses are replaced
  int tool_number = 1;
  Cutter cutter;
  double spindle_rpm = 10000;
  double feed_mm_per_min = 1000;  // cutting moves
  double plunge_mm_per_min = 300; // down to the first point of a cut
  double safe_z_mm = 2;           // rapids between cuts happen at this height
};

class GcodeWriter {
 public:
  explicit GcodeWriter(const GcodeSetup& setup);

  // A cut along CL points: rapid above the first at safe Z, plunge to it, feed
  // through the rest, retract to safe Z.
  void cut(const Vec3* points, std::size_t n);
  // The same cut with the feed part as cubic NURBS (G6.2 P4, weights 1): the CL points
  // fitted by geometry::fit_cubic within `tol_mm` of every point and of every segment's
  // midpoint, cut into curves of at most 100 knot spans. Control points are written to
  // 4 decimals like every coordinate, which moves the curve by at most 8.7e-5 mm (a
  // B-spline stays within the largest move of its control points): the written curve is
  // within tol_mm + 8.7e-5 mm of the CL points. Each curve starts on the point the tool
  // is at, as written. A cut the fit cannot take (fewer than 3 points, or no fit) is
  // written as lines. Returns the fit's largest error, 0 for lines. `samples`, if given,
  // receives points of the written curves (control points as written, 16 a knot span).
  double cut_nurbs(const Vec3* points, std::size_t n, double tol_mm, std::vector<Vec3>* samples = nullptr);
  void rapid(const Vec3& p);
  void feed(const Vec3& p, double feed_mm_per_min);

  // The program so far with its footer; the writer is done after this.
  std::string finish();

  std::size_t feed_moves() const { return feed_moves_; }
  std::size_t nurbs_blocks() const { return nurbs_blocks_; }
  std::size_t nurbs_control_points() const { return nurbs_ctrl_; }
  double feed_length_mm() const { return feed_length_; }

 private:
  void move(int g, const Vec3& p, double feed_mm_per_min);

  GcodeSetup setup_;
  std::string out_;
  Vec3 at_;
  bool known_ = false;  // at_ holds the position
  int modal_g_ = -1;
  double modal_f_ = -1;
  std::size_t feed_moves_ = 0;
  std::size_t nurbs_blocks_ = 0, nurbs_ctrl_ = 0;
  double feed_length_ = 0;
};

}  // namespace cnc::cam
