#include "common/drive/drive_profile.h"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <limits>
#include <set>

#include "common/config/yaml_reader.h"
#include "common/drive/profile_logic.h"
#include "common/util/install.h"

namespace cnc::drive {
namespace {

constexpr std::array<const char*, kRoleCount> kRoleNames = {
    "controlword", "statusword", "mode", "mode_display", "target_position",
    "actual_position", "actual_velocity", "error_code", "fault_reset", "following_error",
    "home_latch_position", "home_latch_count", "speed_setpoint", "actual_speed", "output_current",
    "probe_rise_position", "probe_rise_count", "probe_fall_position", "probe_fall_count", "probe_function",
    "encoder_position"};

// The keys a profile file may hold: its top level, `registers:` (one per role) and each field.
constexpr std::string_view kProfileKeys[] = {"name",         "description",       "state_machine", "write_and_read",
                                             "read_gap_max", "mode_of_operation", "registers",     "huanyang"};
constexpr auto kRegisterKeys = [] {
  std::array<std::string_view, kRoleCount> k{};
  for (int i = 0; i < kRoleCount; ++i) k[i] = kRoleNames[i];
  return k;
}();
constexpr std::string_view kFieldKeys[] = {"address", "words", "signed", "word_order", "scale"};
constexpr std::string_view kHuanyangKeys[] = {"output_frequency_index", "output_current_index", "frequency_scale",
                                              "current_scale",          "run_source_pd",        "frequency_source_pd",
                                              "source_link",            "max_frequency_pd",     "rated_rpm_pd",
                                              "rated_rpm_hz"};

HuanyangMap read_huanyang(config::MapReader r) {
  HuanyangMap h;
  h.present = true;
  const auto byte = [&](const char* key) { return static_cast<int>(r.require_int(key, 0, 255)); };
  h.output_frequency_index = byte("output_frequency_index");
  h.output_current_index = byte("output_current_index");
  h.frequency_scale = r.require_double("frequency_scale", 1e-3, 1e4);
  h.current_scale = r.require_double("current_scale", 1e-3, 1e4);
  h.run_source_pd = byte("run_source_pd");
  h.frequency_source_pd = byte("frequency_source_pd");
  h.source_link = static_cast<int>(r.require_int("source_link", 0, 65535));
  h.max_frequency_pd = byte("max_frequency_pd");
  h.rated_rpm_pd = byte("rated_rpm_pd");
  h.rated_rpm_hz = r.require_double("rated_rpm_hz", 1, 1000);
  if (h.output_frequency_index == h.output_current_index)
    r.fail("output_current_index", "is the output frequency's index too");
  r.finish();
  return h;
}

uint32_t join(const uint16_t* regs, WordOrder order) {
  const uint32_t lo = order == WordOrder::kLowFirst ? regs[0] : regs[1];
  const uint32_t hi = order == WordOrder::kLowFirst ? regs[1] : regs[0];
  return lo | (hi << 16);
}

Field read_field(config::MapReader r) {
  Field f;
  f.address = static_cast<int>(r.require_int("address", 0, 65535));
  f.words = static_cast<int>(r.get_int("words", 1, 1, 2));
  f.is_signed = r.get_bool("signed", false);
  const std::string order = r.get_choice("word_order", "low_first", {"low_first", "high_first"});
  f.order = order == "low_first" ? WordOrder::kLowFirst : WordOrder::kHighFirst;
  f.scale = r.get_double("scale", 1.0, 1e-9, 1e9);
  if (f.end() > 65536) r.fail("address", "the field runs past register 65535");
  r.finish();
  return f;
}

DriveProfile read_profile(config::MapReader top, const std::string& file) {
  DriveProfile p;
  p.file = file;
  p.name = top.require_string("name");
  if (p.name.empty()) top.fail("name", "must not be empty");
  p.description = top.get_string("description", "");
  std::set<std::string> machines;
  for (const auto& n : profile_logic_names()) machines.insert(n);
  p.state_machine = top.get_choice("state_machine", "", machines);
  p.write_and_read = top.get_bool("write_and_read", false);
  p.read_gap_max = static_cast<int>(top.get_int("read_gap_max", 0, 0, 32));
  p.mode_of_operation = static_cast<int>(top.get_int("mode_of_operation", 8, -128, 127));
  config::MapReader regs = top.map("registers", kRegisterKeys);
  for (int i = 0; i < kRoleCount; ++i) {
    if (regs.has(kRoleNames[i])) p.fields[i] = read_field(regs.map(kRoleNames[i], kFieldKeys));
  }
  regs.finish();
  const bool huanyang = p.state_machine == "huanyang";
  if (huanyang != top.has("huanyang"))
    top.fail("huanyang", huanyang ? "is required by state_machine huanyang" : "belongs to state_machine huanyang only");
  if (huanyang) p.huanyang = read_huanyang(top.map("huanyang", kHuanyangKeys));
  const ProfileLogic& logic = profile_logic(p);
  for (Role r : logic.required_roles()) {
    if (!p.has(r)) regs.fail(role_name(r), std::string("is required by state_machine ") + logic.name());
  }
  // Positions are 32-bit in every drive worth the name; a 16-bit position would wrap within millimetres.
  for (Role r : {Role::kTargetPosition, Role::kActualPosition}) {
    if (p.has(r) && p.field(r).words != 2) regs.fail(std::string(role_name(r)) + ".words", "must be 2 for a position");
  }
  // The encoder's counter is raw counts: the machine's spindle.encoder_counts_per_rev makes revolutions of it.
  if (p.has(Role::kEncoderPosition) &&
      (p.field(Role::kEncoderPosition).words != 2 || p.field(Role::kEncoderPosition).scale != 1.0))
    regs.fail("encoder_position", "must be two registers (a 32-bit counter) with scale 1");
  for (Role r : {Role::kControlword, Role::kStatusword, Role::kFaultReset}) {
    if (p.has(r) && (p.field(r).words != 1 || p.field(r).scale != 1.0))
      regs.fail(role_name(r), "must be one register with scale 1");
  }
  // No two fields share a register.
  for (int a = 0; a < kRoleCount; ++a) {
    for (int b = a + 1; b < kRoleCount; ++b) {
      const Field& fa = p.fields[a];
      const Field& fb = p.fields[b];
      if (fa.present() && fb.present() && fa.address < fb.end() && fb.address < fa.end())
        regs.fail(kRoleNames[b], std::string("overlaps ") + kRoleNames[a]);
    }
  }
  top.finish();
  return p;
}

}  // namespace

const char* role_name(Role r) { return kRoleNames[static_cast<size_t>(r)]; }

std::span<const std::string_view> drive_profile_keys() { return kProfileKeys; }
std::span<const std::string_view> drive_profile_register_keys() { return kRegisterKeys; }
std::span<const std::string_view> drive_profile_field_keys() { return kFieldKeys; }
std::span<const std::string_view> drive_profile_huanyang_keys() { return kHuanyangKeys; }

int64_t Field::min_raw() const {
  if (!is_signed) return 0;
  return words == 2 ? std::numeric_limits<int32_t>::min() : std::numeric_limits<int16_t>::min();
}

int64_t Field::max_raw() const {
  if (is_signed) return words == 2 ? std::numeric_limits<int32_t>::max() : std::numeric_limits<int16_t>::max();
  return words == 2 ? std::numeric_limits<uint32_t>::max() : std::numeric_limits<uint16_t>::max();
}

void Field::encode_raw(int64_t raw, uint16_t* regs) const {
  raw = std::clamp(raw, min_raw(), max_raw());
  if (words == 1) {
    regs[0] = static_cast<uint16_t>(static_cast<uint64_t>(raw) & 0xFFFFu);
    return;
  }
  const auto u = static_cast<uint32_t>(static_cast<uint64_t>(raw) & 0xFFFFFFFFu);
  const auto lo = static_cast<uint16_t>(u & 0xFFFFu);
  const auto hi = static_cast<uint16_t>(u >> 16);
  regs[0] = order == WordOrder::kLowFirst ? lo : hi;
  regs[1] = order == WordOrder::kLowFirst ? hi : lo;
}

int64_t Field::decode_raw(const uint16_t* regs) const {
  if (words == 1) return is_signed ? int64_t{static_cast<int16_t>(regs[0])} : int64_t{regs[0]};
  const uint32_t u = join(regs, order);
  return is_signed ? int64_t{static_cast<int32_t>(u)} : int64_t{u};
}

void Field::encode(double value, uint16_t* regs) const {
  const double r = std::round(value * scale);
  int64_t raw = 0;
  if (!(r > static_cast<double>(min_raw()))) {
    raw = min_raw();  // NaN and -inf end here too
  } else if (r >= static_cast<double>(max_raw())) {
    raw = max_raw();
  } else {
    raw = static_cast<int64_t>(r);
  }
  encode_raw(raw, regs);
}

double Field::decode(const uint16_t* regs) const { return static_cast<double>(decode_raw(regs)) / scale; }

int DriveProfile::first_address() const {
  int lo = 65536;
  for (const auto& f : fields)
    if (f.present()) lo = std::min(lo, f.address);
  return lo == 65536 ? 0 : lo;
}

int DriveProfile::end_address() const {
  int hi = 0;
  for (const auto& f : fields)
    if (f.present()) hi = std::max(hi, f.end());
  return hi;
}

DriveProfile load_drive_profile(const std::string& file) {
  return read_profile(config::MapReader(config::load_yaml_file(file), "", file, kProfileKeys), file);
}

DriveProfile parse_drive_profile(const std::string& yaml_text, const std::string& file_label) {
  YAML::Node root;
  try {
    root = YAML::Load(yaml_text);
  } catch (const YAML::ParserException& e) {
    throw config::ConfigError(file_label, "", "YAML syntax error at line " + std::to_string(e.mark.line + 1) + ": " +
                                                  e.msg);
  }
  return read_profile(config::MapReader(root, "", file_label, kProfileKeys), file_label);
}

std::string find_drive_profile(const std::string& name, const std::string& machine_file,
                               const std::string& profile_dir) {
  namespace fs = std::filesystem;
  const fs::path machine_dir = machine_file.empty() ? fs::current_path() : fs::path(machine_file).parent_path();
  auto rel = [&](const fs::path& p) { return p.is_absolute() ? p : machine_dir / p; };
  if (name.find('/') != std::string::npos || (name.size() > 5 && name.ends_with(".yaml"))) return rel(name).string();
  const std::string file = name + ".yaml";
  if (!profile_dir.empty()) return (rel(profile_dir) / file).string();
  const fs::path beside = machine_dir / ".." / "drives" / file;
  if (fs::exists(beside)) return beside.lexically_normal().string();
  // The shipped profiles: PREFIX/share/cnc/config/drives when installed, else the source tree's.
  const fs::path built_in = fs::path(util::resource_path("config/drives")) / file;
  if (fs::exists(built_in)) return built_in.string();
  return beside.lexically_normal().string();  // does not exist: the loader says so with this path
}

}  // namespace cnc::drive
