// The register encoding of the simulated servo drive.
#include <gtest/gtest.h>

#include <cstdint>
#include <limits>

#include "common/drive/sim_profile.h"

namespace cnc::drive::sim {
namespace {

TEST(SimProfile, Int32LowWordFirst) {
  uint16_t regs[2] = {};
  put_i32_low_first(regs, 0x12345678);
  EXPECT_EQ(regs[0], 0x5678);
  EXPECT_EQ(regs[1], 0x1234);
  EXPECT_EQ(get_i32_low_first(regs), 0x12345678);
  for (int32_t v : {0, 1, -1, -123456789, std::numeric_limits<int32_t>::min(), std::numeric_limits<int32_t>::max()}) {
    put_i32_low_first(regs, v);
    EXPECT_EQ(get_i32_low_first(regs), v);
  }
  put_i32_low_first(regs, -2);
  EXPECT_EQ(regs[0], 0xFFFE);
  EXPECT_EQ(regs[1], 0xFFFF);
}

TEST(SimProfile, MillimetresToCountsRoundsAndSaturates) {
  EXPECT_EQ(mm_to_counts(0.0), 0);
  EXPECT_EQ(mm_to_counts(1.0), 10000);
  EXPECT_EQ(mm_to_counts(-12.34567), -123457);
  EXPECT_EQ(mm_to_counts(0.00004), 0);
  EXPECT_EQ(mm_to_counts(0.00006), 1);
  EXPECT_EQ(mm_to_counts(1e9), std::numeric_limits<int32_t>::max());
  EXPECT_EQ(mm_to_counts(-1e9), std::numeric_limits<int32_t>::min());
  EXPECT_DOUBLE_EQ(counts_to_mm(-123457), -12.3457);
  for (double mm : {-150.0, -0.0001, 0.0001, 123.4567, 400.0}) EXPECT_NEAR(counts_to_mm(mm_to_counts(mm)), mm, 0.5e-4);
}

}  // namespace
}  // namespace cnc::drive::sim
