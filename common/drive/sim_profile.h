#pragma once
// Register map of the simulated servo drive (cnc-servo-sim), one Modbus unit per
// axis. Holding registers:
//   0  controlword  bit 0 enable operation, bit 7 fault reset (rising edge)
//   1  statusword   bit 0 operation enabled, bit 3 fault (written by the drive)
//   2,3 target position, int32 counts, low word first
//   4,5 actual position, int32 counts, low word first (written by the drive)
//   6,7 actual velocity, int32 counts/s, low word first (written by the drive)
// One read-write transaction (function 23) per axis and servo cycle writes the
// target and reads statusword..velocity.
#include <cstdint>

namespace cnc::drive::sim {

inline constexpr int kControlword = 0;
inline constexpr int kStatusword = 1;
inline constexpr int kTargetPosition = 2;
inline constexpr int kActualPosition = 4;
inline constexpr int kActualVelocity = 6;
inline constexpr int kNumRegisters = 8;

inline constexpr uint16_t kCwEnable = 1u << 0;
inline constexpr uint16_t kCwFaultReset = 1u << 7;
inline constexpr uint16_t kSwEnabled = 1u << 0;
inline constexpr uint16_t kSwFault = 1u << 3;

inline constexpr double kCountsPerMm = 10000.0;  // 0.1 µm resolution

// 32-bit value split into two registers, low word first.
void put_i32_low_first(uint16_t* regs, int32_t value);
int32_t get_i32_low_first(const uint16_t* regs);

// mm -> counts, rounded to nearest and saturated to the int32 range.
int32_t mm_to_counts(double mm);
double counts_to_mm(int32_t counts);

}  // namespace cnc::drive::sim
