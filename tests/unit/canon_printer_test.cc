// The canon printer formats rs274's text itself (printf's formatting was half of
// cnc-rs274's time): every number must read as printf's "%.4f" of the same double,
// ties and their neighbours, signs of values that round to zero, the largest
// magnitudes and what printf alone prints (NaN, infinities) included.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <limits>
#include <random>
#include <string>
#include <vector>

#include "common/rs274/canon_printer.h"

namespace cnc::rs274 {
namespace {

std::string printed(const std::vector<Pose>& poses, const std::string& n_text) {
  char* data = nullptr;
  size_t size = 0;
  std::FILE* f = open_memstream(&data, &size);
  {
    CanonPrinter printer(f, [&n_text]() -> const std::string& { return n_text; });
    for (const Pose& p : poses) printer.straight_feed(SourceRef{}, p);
    printer.set_feed_rate(SourceRef{}, poses.front()[0]);
  }
  std::fclose(f);
  std::string out(data, size);
  std::free(data);
  return out;
}

std::string expected(const std::vector<Pose>& poses, const std::string& n_field) {
  std::string out;
  char b[2048];
  int k = 0;
  for (const Pose& p : poses) {
    std::snprintf(b, sizeof b, "%5d %sSTRAIGHT_FEED(%.4f, %.4f, %.4f, %.4f, %.4f, %.4f)\n", ++k, n_field.c_str(), p[0], p[1],
                  p[2], p[3], p[4], p[5]);
    out += b;
  }
  std::snprintf(b, sizeof b, "%5d %sSET_FEED_RATE(%.4f)\n", ++k, n_field.c_str(), poses.front()[0]);
  return out + b;
}

TEST(CanonPrinter, NumbersReadAsPrintfsWhateverTheirValue) {
  const double inf = std::numeric_limits<double>::infinity();
  std::vector<Pose> poses = {
      {1.03125, 0.00005, -0.00005, 0.00015, -0.0, 0.0},          // exact ties round to even; near-ties as printf
      {-0.00001, -0.00004999, 9999999.99995, 1e7, -1e7, 1e300},  // -0.0000; the largest fast one; printf's
      {inf, -inf, std::nan(""), 0.12345, 2.5e-5, 7.5e-5},
      {123.45675, -123.45665, 0.1 + 0.2, 1.0 / 3.0, 2.0 / 3.0, 4095.99995},
  };
  std::mt19937_64 g(3);
  std::uniform_real_distribution<double> u(-5000.0, 5000.0);
  for (int i = 0; i < 20000; ++i) {
    Pose p{};
    for (int k = 0; k < 6; ++k) p[static_cast<size_t>(k)] = i % 2 ? u(g) : std::round(u(g) * 1e5) / 1e5;
    poses.push_back(p);
  }
  EXPECT_EQ(printed(poses, ""), expected(poses, "N..... "));
  EXPECT_EQ(printed(poses, "  N120 G1 X1"), expected(poses, "N120   "));
}

}  // namespace
}  // namespace cnc::rs274
