#pragma once
// STL meshes in and out, ASCII and binary (little-endian floats, as every exporter
// writes them). Reading takes the whole file in one block and converts it in place;
// errors are StlError with the file name and where it went wrong: the triangle
// (counted from 1) for binary files, the line for ASCII ones.
//
// A file is binary when its size is exactly 84 + 50·N for the count N in bytes
// 80..83; otherwise it is ASCII if it starts with "solid", and otherwise a binary
// file whose count disagrees with its size (cut off, or bytes after the last
// triangle) — an error either way. Zero-area triangles (mesh.h) are skipped and
// counted; non-finite vertex coordinates are errors (normals are not read: the
// drop-cutter computes its own from the vertices).
#include <cstddef>
#include <cstdint>
#include <stdexcept>
#include <string>
#include <string_view>

#include "common/cam/mesh.h"

namespace cnc::cam {

class StlError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

struct StlInfo {
  bool binary = false;
  std::uint64_t bytes = 0;
  std::size_t triangles_in_file = 0;   // as read, zero-area ones included
  std::size_t zero_area_skipped = 0;
};

// Reads PATH; `info`, when given, receives what was found.
Mesh read_stl(const std::string& path, StlInfo* info = nullptr);

// The same from bytes already in memory; `name` is what the errors call the file.
Mesh parse_stl(std::string_view data, const std::string& name, StlInfo* info = nullptr);

// Binary STL (coordinates rounded to float, as the format holds them) and ASCII STL
// (17 significant digits, exact for doubles).
void write_stl_binary(const std::string& path, const Mesh& mesh);
void write_stl_ascii(const std::string& path, const Mesh& mesh);

}  // namespace cnc::cam
