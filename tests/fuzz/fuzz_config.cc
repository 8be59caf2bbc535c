// libFuzzer target: the YAML loaders from text. The first byte picks the loader
// (even: a machine config, odd: a drive profile); the rest is the YAML. Bad files
// must end in config::ConfigError naming the file and the key path.
#include <cstddef>
#include <cstdint>
#include <string>

#include "common/config/machine_config.h"
#include "common/config/yaml_reader.h"
#include "common/drive/drive_profile.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  if (size < 1) return 0;
  const std::string text(reinterpret_cast<const char*>(data) + 1, size - 1);
  try {
    if (data[0] % 2 == 0) {
      (void)cnc::config::parse_machine_config(text, "fuzz.yaml");
    } else {
      (void)cnc::drive::parse_drive_profile(text, "fuzz_drive.yaml");
    }
  } catch (const cnc::config::ConfigError&) {
  }
  return 0;
}
