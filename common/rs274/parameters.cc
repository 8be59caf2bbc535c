#include "common/rs274/parameters.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <stdexcept>
#include <string>
#include <utility>

#include "common/rs274/lexer.h"

namespace cnc::rs274 {

namespace {

constexpr int kCallArgs = 30;  // #1..#30, LinuxCNC's INTERP_SUB_PARAMS

// LinuxCNC's required_parameters (interp_array.cc): what every var file it writes
// holds: G28 and G30 homes, the G52/G92 flag and offsets, the selected coordinate
// system and the nine systems' X Y Z A B C U V W and rotation R.
bool required(int i) {
  if (i >= 5161 && i <= 5169) return true;
  if (i >= 5181 && i <= 5189) return true;
  if (i >= 5210 && i <= 5230) return true;
  if (i >= 5241 && i <= 5390) return (i - 5241) % 20 < 10;
  return false;
}

std::string errno_text(const std::string& what, const std::string& path) {
  return what + " '" + path + "': " + std::strerror(errno);
}

bool space(char c) { return c == ' ' || c == '\t' || c == '\r' || c == '\n' || c == '\f' || c == '\v'; }

// A value as LinuxCNC writes it ("%f") when that loses nothing, else the shortest
// text that reads back exactly; LinuxCNC reads either with "%lf".
std::string value_text(double v) {
  char buf[400];
  std::snprintf(buf, sizeof buf, "%f", v);
  double back = 0;
  const auto r = std::from_chars(buf, buf + std::strlen(buf), back);
  if (r.ec == std::errc() && back == v) return buf;
  const auto s = std::to_chars(buf, buf + sizeof buf, v);
  return std::string(buf, s.ptr);
}

class Fd {
 public:
  explicit Fd(int fd) : fd_(fd) {}
  Fd(const Fd&) = delete;
  Fd& operator=(const Fd&) = delete;
  ~Fd() {
    if (fd_ >= 0) ::close(fd_);
  }
  int get() const { return fd_; }
  int release() { return std::exchange(fd_, -1); }

 private:
  int fd_;
};

void write_all(int fd, const std::string& data, const std::string& path) {
  size_t done = 0;
  while (done < data.size()) {
    const ssize_t n = ::write(fd, data.data() + done, data.size() - done);
    if (n < 0) {
      if (errno == EINTR) continue;
      throw std::runtime_error(errno_text("cannot write", path));
    }
    done += static_cast<size_t>(n);
  }
}

}  // namespace

Parameters::Parameters() : numbered_(kMaxParameter + 1, 0.0), persistent_(kMaxParameter + 1, false) {
  for (int i = 1; i <= kMaxParameter; ++i) persistent_[static_cast<size_t>(i)] = required(i);
}

int Parameters::index_of(double index, int column) {
  if (!(std::fabs(index) < 1e9)) throw Error(column, "parameter number out of range (1.." + std::to_string(kMaxParameter) + ")");
  double f = std::floor(index);
  if (index - f > 0.9999) f = std::ceil(index);
  else if (index - f > 0.0001) throw Error(column, "parameter number " + std::to_string(index) + " is not an integer");
  return static_cast<int>(f);
}

double Parameters::get(int index, int column) const {
  if (index < 1 || index > kMaxParameter)
    throw Error(column, "parameter number #" + std::to_string(index) + " out of range (1.." + std::to_string(kMaxParameter) + ")");
  return numbered_[static_cast<size_t>(index)];
}

void Parameters::set(int index, double value, int column) {
  if (index < 1 || index > kMaxParameter)
    throw Error(column, "parameter number #" + std::to_string(index) + " out of range (1.." + std::to_string(kMaxParameter) + ")");
  numbered_[static_cast<size_t>(index)] = value;
}

double Parameters::get_named(const std::string& name, int column) const {
  double v = 0;
  if (!find_named(name, &v)) throw Error(column, "named parameter #<" + name + "> not defined");
  return v;
}

bool Parameters::find_named(const std::string& name, double* value) const {
  const auto& scope = (!name.empty() && name[0] == '_') ? globals_ : locals_;
  const auto it = scope.find(name);
  if (it == scope.end()) return false;
  if (value) *value = it->second;
  return true;
}

void Parameters::set_named(const std::string& name, double value) {
  auto& scope = (!name.empty() && name[0] == '_') ? globals_ : locals_;
  scope[name] = value;
}

// LinuxCNC's O-word call: the caller's #1..#30 are saved and the callee's start at
// zero (arguments not given stay zero); named locals are lexically scoped, so the
// callee sees none of the caller's.
void Parameters::push_call(bool scoped_args) {
  Frame f;
  f.scoped_args = scoped_args;
  if (scoped_args) {
    for (int i = 0; i < kCallArgs; ++i) {
      f.args[static_cast<size_t>(i)] = numbered_[static_cast<size_t>(i + 1)];
      numbered_[static_cast<size_t>(i + 1)] = 0.0;
    }
  }
  f.locals = std::move(locals_);
  locals_.clear();
  frames_.push_back(std::move(f));
}

void Parameters::pop_call() {
  if (frames_.empty()) throw std::logic_error("Parameters::pop_call without a matching push_call");
  Frame& f = frames_.back();
  if (f.scoped_args)
    for (int i = 0; i < kCallArgs; ++i) numbered_[static_cast<size_t>(i + 1)] = f.args[static_cast<size_t>(i)];
  locals_ = std::move(f.locals);
  frames_.pop_back();
}

bool Parameters::persistent(int index) const {
  return index >= 1 && index <= kMaxParameter && persistent_[static_cast<size_t>(index)];
}

// LinuxCNC's restore_parameters: a missing file is fine (it is written on the next
// save), lines that do not start with a number are comments, numbers ascend
// strictly, and the persistent parameters the file does not give become zero.
// The whole file is checked before anything is applied.
void Parameters::read_var_file(const std::string& path) {
  std::ifstream in(path);
  if (!in) {
    if (::access(path.c_str(), F_OK) != 0 && errno == ENOENT) return;
    throw std::runtime_error(errno_text("cannot open parameter file", path));
  }
  std::vector<std::pair<int, double>> read;
  std::string text;
  int line_no = 0;
  int last = 0;
  const auto fail = [&](size_t col, const std::string& what) {
    throw Error(path, SourceRef{0, line_no, static_cast<int32_t>(col) + 1}, what);
  };
  while (std::getline(in, text)) {
    ++line_no;
    size_t i = 0;
    while (i < text.size() && space(text[i])) ++i;
    const size_t num_at = i;
    size_t j = i;
    if (j < text.size() && (text[j] == '+' || text[j] == '-')) ++j;
    if (j >= text.size() || text[j] < '0' || text[j] > '9') continue;
    long long index = 0;
    const char* first = text.data() + i + (text[i] == '+' ? 1 : 0);
    const auto r = std::from_chars(first, text.data() + text.size(), index);
    size_t k = static_cast<size_t>(r.ptr - text.data());
    if (r.ec != std::errc() || index < 1 || index > kMaxParameter)
      fail(num_at, "parameter number out of range (1.." + std::to_string(kMaxParameter) + ")");
    if (k < text.size() && !space(text[k])) fail(k, "expected blanks after the parameter number");
    while (k < text.size() && space(text[k])) ++k;
    if (k >= text.size()) fail(k, "parameter " + std::to_string(index) + " has no value");
    double value = 0;
    const size_t value_at = k;
    const char* vfirst = text.data() + k + (text[k] == '+' ? 1 : 0);
    const auto rv = std::from_chars(vfirst, text.data() + text.size(), value);
    if (rv.ec != std::errc() || !std::isfinite(value)) fail(value_at, "bad value for parameter " + std::to_string(index));
    const size_t after = static_cast<size_t>(rv.ptr - text.data());
    if (after < text.size() && !space(text[after])) fail(after, "unexpected text after the value");
    if (index <= last)
      fail(num_at, "parameter file out of order: " + std::to_string(index) + " after " + std::to_string(last));
    last = static_cast<int>(index);
    read.emplace_back(static_cast<int>(index), value);
  }
  if (in.bad()) throw std::runtime_error(errno_text("cannot read parameter file", path));

  for (int i = 1; i <= kMaxParameter; ++i) {
    persistent_[static_cast<size_t>(i)] = required(i);
    if (required(i)) numbered_[static_cast<size_t>(i)] = 0.0;
  }
  for (const auto& [index, value] : read) {
    numbered_[static_cast<size_t>(index)] = value;
    persistent_[static_cast<size_t>(index)] = true;
  }
}

void Parameters::make_persistent(int index) {
  if (index >= 1 && index <= kMaxParameter) persistent_[static_cast<size_t>(index)] = true;
}

void write_file_atomically(const std::string& path, const std::string& data) {
  const size_t slash = path.rfind('/');
  const std::string dir = slash == std::string::npos ? "." : (slash == 0 ? "/" : path.substr(0, slash));
  std::string tmp = path + ".tmp.XXXXXX";
  Fd fd(::mkstemp(tmp.data()));
  if (fd.get() < 0) throw std::runtime_error(errno_text("cannot create a temporary file for", path));
  try {
    // mkstemp makes the file private; the var file keeps the mode it had.
    struct stat old {};
    const mode_t mode = ::stat(path.c_str(), &old) == 0 ? (old.st_mode & 07777) : 0644;
    if (::fchmod(fd.get(), mode) != 0) throw std::runtime_error(errno_text("cannot set the mode of", tmp));
    write_all(fd.get(), data, tmp);
    if (::fsync(fd.get()) != 0) throw std::runtime_error(errno_text("cannot sync", tmp));
    if (::close(fd.release()) != 0) throw std::runtime_error(errno_text("cannot close", tmp));
    if (::rename(tmp.c_str(), path.c_str()) != 0) throw std::runtime_error(errno_text("cannot rename the new parameter file to", path));
  } catch (...) {
    ::unlink(tmp.c_str());
    throw;
  }
  Fd d(::open(dir.c_str(), O_RDONLY | O_DIRECTORY));
  if (d.get() < 0 || ::fsync(d.get()) != 0) throw std::runtime_error(errno_text("cannot sync the folder of", path));
}

// LinuxCNC's line format "number<TAB>value"; written to a temporary file in the
// same folder, synced, renamed over the old one, and the folder synced so the
// rename itself survives a power loss.
void Parameters::write_var_file(const std::string& path) const {
  std::string data;
  for (int i = 1; i <= kMaxParameter; ++i) {
    if (!persistent_[static_cast<size_t>(i)]) continue;
    data += std::to_string(i);
    data += '\t';
    data += value_text(numbered_[static_cast<size_t>(i)]);
    data += '\n';
  }

  write_file_atomically(path, data);
}

}  // namespace cnc::rs274
