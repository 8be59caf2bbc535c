#include "common/drive/sim_profile.h"

#include <cmath>
#include <limits>

namespace cnc::drive::sim {

void put_i32_low_first(uint16_t* regs, int32_t value) {
  const auto u = static_cast<uint32_t>(value);
  regs[0] = static_cast<uint16_t>(u & 0xFFFFu);
  regs[1] = static_cast<uint16_t>(u >> 16);
}

int32_t get_i32_low_first(const uint16_t* regs) {
  return static_cast<int32_t>(static_cast<uint32_t>(regs[0]) | (static_cast<uint32_t>(regs[1]) << 16));
}

int32_t mm_to_counts(double mm) {
  const double c = std::round(mm * kCountsPerMm);
  if (!(c > std::numeric_limits<int32_t>::min())) return std::numeric_limits<int32_t>::min();
  if (c >= std::numeric_limits<int32_t>::max()) return std::numeric_limits<int32_t>::max();
  return static_cast<int32_t>(c);
}

double counts_to_mm(int32_t counts) { return static_cast<double>(counts) / kCountsPerMm; }

}  // namespace cnc::drive::sim
