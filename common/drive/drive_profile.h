#pragma once
// A drive profile: the register map of one kind of servo drive, as data
// (`config/drives/NAME.yaml`), loaded strictly like the machine config: unknown
// keys and bad values are errors naming the file and the key path.
//
//   name: cia402_modbus
//   state_machine: cia402          # sim, cia402, leadshine; delta_vfd, huanyang, cia402_velocity: the logic in code
//   write_and_read: true           # the drive answers function 23 (write and read in one transaction)
//   read_gap_max: 0                # unused registers a cyclic read may span to merge two fields
//   mode_of_operation: 8           # cia402: the mode written before enabling
//   registers:
//     controlword:     {address: 0x6040}
//     target_position: {address: 0x607A, words: 2, signed: true, word_order: low_first, scale: 26214.4}
//
// A field is 1 or 2 holding registers; `scale` converts the engineering value
// (mm, mm/s, or a plain number) to the drive's integer: raw = round(value * scale).
#include <array>
#include <cstdint>
#include <span>
#include <string>
#include <string_view>

namespace cnc::drive {

enum class Role : int8_t {
  kControlword,     // control (CiA-402 controlword, sim enable bits, Leadshine-style servo on)
  kStatusword,      // drive state bits
  kMode,            // mode of operation (written)
  kModeDisplay,     // mode of operation display (read)
  kTargetPosition,  // mm
  kActualPosition,  // mm
  kActualVelocity,  // mm/s
  kErrorCode,       // drive's fault / alarm code (read)
  kFaultReset,      // a separate alarm-clear register (Leadshine-style)
  kFollowingError,  // mm, the drive's own position demand minus actual (CiA-402 0x60F4; read)
  kHomeLatchPosition,  // mm, the position latched at the home switch's last closing edge (CiA-402 touch probe 0x60BA; read)
  kHomeLatchCount,     // closing edges latched so far, wrapping (read)
  // A spindle drive (a VFD, state_machine delta_vfd; a servo drive in velocity mode,
  // cia402_velocity): speeds in Hz (a servo's: motor revolutions per second), current in A.
  kSpeedSetpoint,   // frequency command (written); cia402_velocity: target velocity 0x60FF, signed
  kActualSpeed,     // output frequency (read); cia402_velocity: velocity actual value 0x606C, signed
  kOutputCurrent,   // output current, the drive's load figure (read)
  // The touch probe (CiA-402 0x60BA/0x60BB positions, 0x60D5/0x60D6 edge counters; read):
  // the position at the probe input's last rising / falling edge, and the edges so far (wrapping).
  kProbeRisePosition,
  kProbeRiseCount,
  kProbeFallPosition,
  kProbeFallCount,
  // The touch probe's function (CiA-402 0x60B8; written once before enabling, where mapped):
  // TP1 on, continuous, on the TP1 input, latching at both edges (0x0033).
  kProbeFunction,
  // A spindle drive's encoder: its position counter, raw counts (two registers, scale 1;
  // CiA-402 0x6064, a VFD's encoder input), read each cycle. The bridge unwraps the 32-bit
  // counter and divides by spindle.encoder_counts_per_rev.
  kEncoderPosition,
};
inline constexpr int kRoleCount = 21;
const char* role_name(Role r);

enum class WordOrder : int8_t { kLowFirst, kHighFirst };

struct Field {
  int address = -1;  // -1: the profile does not have this field
  int words = 1;     // 1 or 2 registers
  bool is_signed = false;
  WordOrder order = WordOrder::kLowFirst;
  double scale = 1.0;  // drive units per engineering unit

  bool present() const { return address >= 0; }
  int end() const { return address + words; }
  // Engineering value -> registers (rounded, saturated to the field's range).
  void encode(double value, uint16_t* regs) const;
  double decode(const uint16_t* regs) const;
  // Integer level, for control words and tests.
  void encode_raw(int64_t raw, uint16_t* regs) const;
  int64_t decode_raw(const uint16_t* regs) const;
  int64_t min_raw() const;
  int64_t max_raw() const;
};

// A Huanyang VFD's data (state_machine huanyang; its frames in huanyang_frame.h, its
// command and status bits in huanyang_profile.h): where its values are and how they
// scale, and the PD parameters that must be set for the link to drive it.
struct HuanyangMap {
  bool present = false;
  int output_frequency_index = 1;  // function 0x04's index of the output frequency
  int output_current_index = 2;    // and of the output current
  double frequency_scale = 100;    // counts per Hz: function 0x05, the output frequency, PD005
  double current_scale = 10;       // counts per A
  int run_source_pd = 1;           // PD001: where run commands come from
  int frequency_source_pd = 2;     // PD002: where the frequency comes from
  int source_link = 2;             // the value of both that means the communication port
  int max_frequency_pd = 5;        // PD005: the highest frequency the drive puts out
  int rated_rpm_pd = 144;          // PD144: the motor's rpm at rated_rpm_hz
  double rated_rpm_hz = 50;
};

struct DriveProfile {
  std::string name;
  std::string file;
  std::string description;
  std::string state_machine;  // sim | cia402 | leadshine | delta_vfd, huanyang, cia402_velocity (spindle drives)
  bool write_and_read = false;
  int read_gap_max = 0;
  int mode_of_operation = 8;
  std::array<Field, kRoleCount> fields{};
  HuanyangMap huanyang;

  const Field& field(Role r) const { return fields[static_cast<size_t>(r)]; }
  bool has(Role r) const { return field(r).present(); }
  // Lowest register address and one past the highest of all fields.
  int first_address() const;
  int end_address() const;
};

// The keys a profile file may hold (docs/config.md documents each; a test keeps both equal):
// the top level, the roles under `registers:`, and the keys of each field.
std::span<const std::string_view> drive_profile_keys();
std::span<const std::string_view> drive_profile_register_keys();
std::span<const std::string_view> drive_profile_field_keys();
std::span<const std::string_view> drive_profile_huanyang_keys();

// Loads and validates; throws config::ConfigError naming the file and key path.
DriveProfile load_drive_profile(const std::string& file);
DriveProfile parse_drive_profile(const std::string& yaml_text, const std::string& file_label);

// Where the profile `name` of a machine is: `profile_dir` when set (relative to the
// machine file's folder), else `config/drives` next to the machine file's folder,
// else the source tree's config/drives. A name with '/' or ending in .yaml is a path.
std::string find_drive_profile(const std::string& name, const std::string& machine_file,
                               const std::string& profile_dir);

}  // namespace cnc::drive
