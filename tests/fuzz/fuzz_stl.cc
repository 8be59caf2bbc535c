// libFuzzer target: the STL reader (binary and ASCII) on bytes in memory. Bad files
// must end in cam::StlError naming the file and the triangle or line.
#include <cstddef>
#include <cstdint>
#include <string_view>

#include "common/cam/stl.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  try {
    cnc::cam::StlInfo info;
    const cnc::cam::Mesh mesh =
        cnc::cam::parse_stl(std::string_view(reinterpret_cast<const char*>(data), size), "fuzz.stl", &info);
    (void)mesh;
  } catch (const cnc::cam::StlError&) {
  }
  return 0;
}
