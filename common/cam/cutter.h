#pragma once
// One toroidal cutter model for ball (r = R), flat (r = 0) and bull/filleted
// (0 < r < R) end mills: the lower surface is a flat disc of radius a = R − r at
// the tip, rounded by a corner arc of radius r up to the full radius R. Lengths in
// mm; the tip (lowest point on the axis) is the cutter location (CL) point.
#include <string_view>

namespace cnc::cam {

struct Cutter {
  double diameter_mm = 0;
  double corner_radius_mm = 0;
  double flute_length_mm = 0;

  double radius() const { return 0.5 * diameter_mm; }
  // Radius of the flat part of the bottom, where the corner arcs' centres turn.
  double ring_radius() const { return radius() - corner_radius_mm; }
  bool is_ball() const { return corner_radius_mm == radius(); }
  bool is_flat() const { return corner_radius_mm == 0; }

  // Height of the lower surface above the tip at distance rho from the axis,
  // 0 <= rho <= R: 0 on the flat part, r − sqrt(r² − (rho − a)²) on the corner.
  double height_at(double rho) const;
};

// Throws std::invalid_argument unless 0 <= r <= R, R > 0, flute > 0, all finite.
Cutter make_cutter(double diameter_mm, double corner_radius_mm, double flute_length_mm);

// "ball:D", "flat:D", "bull:D:r", each optionally followed by ":L=<flute length>";
// the flute length defaults to 4·D. Throws std::invalid_argument with the spec in
// the message.
Cutter parse_cutter(std::string_view spec);

}  // namespace cnc::cam
