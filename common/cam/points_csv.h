#pragma once
// The drop command's files: XY.csv (header "x,y", one point a line) in, XYZ.csv
// ("x,y,z") out. x and y are echoed exactly as written; z is the shortest text that
// reads back as the same double, empty where the cutter touches nothing.
#include <string>
#include <vector>

#include "common/cam/drop_cutter.h"

namespace cnc::cam {

struct PointsCsv {
  std::vector<XY> points;
  std::vector<std::string> x_text, y_text;  // as written, surrounding blanks removed
};

// Throws std::runtime_error "PATH:LINE: what" for a missing header, a line without
// exactly two fields, or a field that is not a finite number. Blank lines are skipped.
PointsCsv read_points_csv(const std::string& path);
PointsCsv parse_points_csv(const std::string& text, const std::string& name);

void write_xyz_csv(const std::string& path, const PointsCsv& in, const std::vector<ClPoint>& out);

}  // namespace cnc::cam
