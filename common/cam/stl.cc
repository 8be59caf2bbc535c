#include "common/cam/stl.h"

#include <bit>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <memory>
#include <string>

namespace cnc::cam {
namespace {

constexpr std::size_t kHeaderBytes = 84;
constexpr std::size_t kTriangleBytes = 50;

[[noreturn]] void fail(const std::string& name, const std::string& what) {
  throw StlError(name + ": " + what);
}

bool starts_with_solid(std::string_view data) {
  std::size_t i = 0;
  while (i < data.size() && (data[i] == ' ' || data[i] == '\t' || data[i] == '\r' || data[i] == '\n')) ++i;
  return data.substr(i, 5) == "solid";
}

std::uint32_t read_u32_le(const char* p) {
  const auto* b = reinterpret_cast<const unsigned char*>(p);
  return static_cast<std::uint32_t>(b[0]) | static_cast<std::uint32_t>(b[1]) << 8 |
         static_cast<std::uint32_t>(b[2]) << 16 | static_cast<std::uint32_t>(b[3]) << 24;
}

static_assert(std::endian::native == std::endian::little, "binary STL is little-endian; so must the host be");

Mesh parse_binary(std::string_view data, const std::string& name, std::size_t count, StlInfo& info) {
  info.binary = true;
  Mesh mesh;
  mesh.triangles.reserve(count);
  const char* p = data.data() + kHeaderBytes;
  for (std::size_t i = 0; i < count; ++i, p += kTriangleBytes) {
    float f[9];
    std::memcpy(f, p + 12, sizeof f);  // past the normal; little-endian host, as the format
    Triangle t;
    for (std::size_t k = 0; k < 3; ++k) {
      if (!std::isfinite(f[3 * k]) || !std::isfinite(f[3 * k + 1]) || !std::isfinite(f[3 * k + 2])) {
        char buf[160];
        std::snprintf(buf, sizeof buf, "triangle %zu of %zu (byte %zu): vertex %zu is (%g, %g, %g), not finite",
                      i + 1, count, kHeaderBytes + i * kTriangleBytes, k + 1, static_cast<double>(f[3 * k]),
                      static_cast<double>(f[3 * k + 1]), static_cast<double>(f[3 * k + 2]));
        fail(name, buf);
      }
      t.v[k] = {f[3 * k], f[3 * k + 1], f[3 * k + 2]};
    }
    if (is_zero_area(t)) {
      ++info.zero_area_skipped;
      continue;
    }
    mesh.triangles.push_back(t);
  }
  info.triangles_in_file = count;
  return mesh;
}

// ASCII: a hand-written tokenizer (whitespace-separated words, lines counted) and
// std::from_chars for the numbers; about 5x faster than iostreams on large files.
class AsciiReader {
 public:
  AsciiReader(std::string_view data, const std::string& name) : p_(data.data()), end_(p_ + data.size()), name_(name) {}

  Mesh read(StlInfo& info) {
    info.binary = false;
    Mesh mesh;
    std::size_t facets = 0;
    expect("solid", "at the start of an ASCII STL");
    skip_line();  // the solid's name, if any
    for (;;) {
      std::string_view w = word();
      if (w.empty()) fail_here("end of file before 'endsolid'");
      if (w == "endsolid") {
        skip_line();
        w = word();
        if (w.empty()) break;
        if (w != "solid") fail_here("expected 'solid' or the end of the file after 'endsolid', found '" + std::string(w) + "'");
        skip_line();
        continue;
      }
      if (w != "facet") fail_here("expected 'facet' or 'endsolid', found '" + std::string(w) + "'");
      ++facets;
      facet_ = facets;
      expect("normal", "after 'facet'");
      for (int k = 0; k < 3; ++k) number(nullptr);  // normals are recomputed, not checked
      expect("outer", "");
      expect("loop", "");
      Triangle t;
      for (int k = 0; k < 3; ++k) {
        expect("vertex", "");
        Vec3& v = t.v[static_cast<std::size_t>(k)];
        number(&v.x);
        number(&v.y);
        number(&v.z);
      }
      expect("endloop", "");
      expect("endfacet", "");
      if (is_zero_area(t)) {
        ++info.zero_area_skipped;
        continue;
      }
      mesh.triangles.push_back(t);
    }
    info.triangles_in_file = facets;
    return mesh;
  }

 private:
  static bool space(char c) { return c == ' ' || c == '\t' || c == '\r' || c == '\n' || c == '\f' || c == '\v'; }

  std::string_view word() {
    while (p_ < end_ && space(*p_)) {
      if (*p_ == '\n') ++line_;
      ++p_;
    }
    const char* b = p_;
    while (p_ < end_ && !space(*p_)) ++p_;
    return {b, static_cast<std::size_t>(p_ - b)};
  }

  void skip_line() {
    while (p_ < end_ && *p_ != '\n') ++p_;
  }

  [[noreturn]] void fail_here(const std::string& what) const {
    std::string where = ":" + std::to_string(line_);
    if (facet_ > 0) where += " (facet " + std::to_string(facet_) + ")";
    throw StlError(name_ + where + ": " + what);
  }

  void expect(std::string_view keyword, const char* context) {
    const std::string_view w = word();
    if (w == keyword) return;
    std::string msg = w.empty() ? "end of file, expected '" + std::string(keyword) + "'"
                                : "expected '" + std::string(keyword) + "', found '" + std::string(w) + "'";
    if (*context) msg += std::string(" ") + context;
    fail_here(msg);
  }

  void number(double* out) {
    const std::string_view w = word();
    if (w.empty()) fail_here("end of file, expected a number");
    const char* b = w.data();
    const char* e = b + w.size();
    if (b < e && *b == '+') ++b;
    double v = 0;
    const auto r = std::from_chars(b, e, v);
    if (r.ec != std::errc() || r.ptr != e) fail_here("expected a number, found '" + std::string(w) + "'");
    if (out == nullptr) return;
    if (!std::isfinite(v)) fail_here("vertex coordinate '" + std::string(w) + "' is not finite");
    *out = v;
  }

  const char* p_;
  const char* end_;
  const std::string& name_;
  std::size_t line_ = 1;
  std::size_t facet_ = 0;
};

}  // namespace

Mesh parse_stl(std::string_view data, const std::string& name, StlInfo* info_out) {
  StlInfo info;
  info.bytes = data.size();
  Mesh mesh;
  if (data.size() >= kHeaderBytes) {
    const std::size_t count = read_u32_le(data.data() + 80);
    const std::size_t expected = kHeaderBytes + kTriangleBytes * count;
    if (data.size() == expected) {
      mesh = parse_binary(data, name, count, info);
    } else if (starts_with_solid(data)) {
      mesh = AsciiReader(data, name).read(info);
    } else if (data.size() < expected) {
      const std::size_t whole = (data.size() - kHeaderBytes) / kTriangleBytes;
      fail(name, "truncated binary STL: the header announces " + std::to_string(count) + " triangles (" +
                     std::to_string(expected) + " bytes) but the file has " + std::to_string(data.size()) +
                     " bytes; triangle " + std::to_string(whole + 1) + " is cut off");
    } else {
      fail(name, "binary STL whose triangle count disagrees with its size: the header announces " +
                     std::to_string(count) + " triangles (" + std::to_string(expected) + " bytes) but the file has " +
                     std::to_string(data.size()) + " bytes (" + std::to_string(data.size() - expected) +
                     " more, room for " + std::to_string((data.size() - kHeaderBytes) / kTriangleBytes) +
                     " triangles)");
    }
  } else if (starts_with_solid(data)) {
    mesh = AsciiReader(data, name).read(info);
  } else {
    fail(name, std::to_string(data.size()) + " bytes: too short for a binary STL (84-byte header) and not ASCII");
  }
  if (info_out) *info_out = info;
  return mesh;
}

Mesh read_stl(const std::string& path, StlInfo* info) {
  std::unique_ptr<std::FILE, int (*)(std::FILE*)> f(std::fopen(path.c_str(), "rb"), &std::fclose);
  if (!f) fail(path, std::string("cannot open: ") + std::strerror(errno));
  if (std::fseek(f.get(), 0, SEEK_END) != 0) fail(path, "cannot seek");
  const long size = std::ftell(f.get());
  if (size < 0) fail(path, "cannot tell its size");
  std::rewind(f.get());
  std::string data(static_cast<std::size_t>(size), '\0');
  if (size > 0 && std::fread(data.data(), 1, data.size(), f.get()) != data.size())
    fail(path, std::string("read error: ") + std::strerror(errno));
  return parse_stl(data, path, info);
}

void write_stl_binary(const std::string& path, const Mesh& mesh) {
  std::unique_ptr<std::FILE, int (*)(std::FILE*)> f(std::fopen(path.c_str(), "wb"), &std::fclose);
  if (!f) fail(path, std::string("cannot create: ") + std::strerror(errno));
  std::string out(kHeaderBytes + kTriangleBytes * mesh.triangles.size(), '\0');
  std::memcpy(out.data(), "binary STL written by cnc-cam", 29);
  const auto count = static_cast<std::uint32_t>(mesh.triangles.size());
  for (int i = 0; i < 4; ++i) out[static_cast<std::size_t>(80 + i)] = static_cast<char>((count >> (8 * i)) & 0xff);
  char* p = out.data() + kHeaderBytes;
  for (const Triangle& t : mesh.triangles) {
    float vals[12] = {0, 0, 0};
    for (std::size_t k = 0; k < 3; ++k) {
      vals[3 + 3 * k] = static_cast<float>(t.v[k].x);
      vals[4 + 3 * k] = static_cast<float>(t.v[k].y);
      vals[5 + 3 * k] = static_cast<float>(t.v[k].z);
    }
    std::memcpy(p, vals, sizeof vals);  // little-endian host, as the format
    p += kTriangleBytes;
  }
  if (std::fwrite(out.data(), 1, out.size(), f.get()) != out.size()) fail(path, "write error");
}

void write_stl_ascii(const std::string& path, const Mesh& mesh) {
  std::unique_ptr<std::FILE, int (*)(std::FILE*)> f(std::fopen(path.c_str(), "w"), &std::fclose);
  if (!f) fail(path, std::string("cannot create: ") + std::strerror(errno));
  std::fprintf(f.get(), "solid cnc-cam\n");
  for (const Triangle& t : mesh.triangles) {
    std::fprintf(f.get(), "  facet normal 0 0 0\n    outer loop\n");
    for (const Vec3& v : t.v) std::fprintf(f.get(), "      vertex %.17g %.17g %.17g\n", v.x, v.y, v.z);
    std::fprintf(f.get(), "    endloop\n  endfacet\n");
  }
  std::fprintf(f.get(), "endsolid cnc-cam\n");
  if (std::ferror(f.get())) fail(path, "write error");
}

}  // namespace cnc::cam
