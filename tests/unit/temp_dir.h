#pragma once
// A temporary folder for a test, removed with everything in it at the end; and a
// file written whole.
#include <stdlib.h>

#include <filesystem>
#include <fstream>
#include <string>

namespace cnc::test {

class TempDir {
 public:
  TempDir() {
    std::string tmpl = (std::filesystem::temp_directory_path() / "cnc-program-test.XXXXXX").string();
    path_ = ::mkdtemp(tmpl.data());
  }
  ~TempDir() { std::filesystem::remove_all(path_); }
  TempDir(const TempDir&) = delete;
  TempDir& operator=(const TempDir&) = delete;
  std::filesystem::path operator/(const std::string& name) const { return path_ / name; }
  const std::filesystem::path& path() const { return path_; }
  // Makes the folder `name` in this folder (and its parents); its path.
  std::string dir(const std::string& name) const {
    const std::filesystem::path p = path_ / name;
    std::filesystem::create_directories(p);
    return p.string();
  }
  // Writes `text` into the file `name` in this folder; its path.
  std::string write(const std::string& name, const std::string& text) const {
    const std::filesystem::path p = path_ / name;
    std::ofstream(p, std::ios::binary | std::ios::trunc) << text;
    return p.string();
  }

 private:
  std::filesystem::path path_;
};

inline void write_file(const std::filesystem::path& p, const std::string& text) {
  std::ofstream out(p, std::ios::binary | std::ios::trunc);
  out << text;
}

}  // namespace cnc::test
