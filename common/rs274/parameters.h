#pragma once
// RS274NGC parameters as LinuxCNC keeps them: numbered #1..#5601 (#1..#30 are a
// subroutine's arguments and local to each call), named locals (#<name>, one scope
// per call level) and named globals (#<_name>), and the var file that keeps the
// persistent ones (LinuxCNC's list: 5161-5390 and the ones the var file names)
// between runs.
//
// The var file is LinuxCNC's format: one "number<TAB or spaces>value" per line,
// ascending numbers; lines that do not start with a number are ignored as comments.
// It is written atomically (write to a temporary file in the same folder, fsync,
// rename), so a crash leaves the old file or the new one, never half of one.
#include <array>
#include <string>
#include <unordered_map>
#include <vector>

namespace cnc::rs274 {

constexpr int kMaxParameter = 5601;  // LinuxCNC: RS274NGC_MAX_PARAMETERS - 1

// Writes `data` to `path` atomically: a temporary file in the same folder (with the
// old file's mode), synced, renamed over the old one, and the folder synced so the
// rename itself survives a power loss. Throws std::runtime_error with the path.
void write_file_atomically(const std::string& path, const std::string& data);

class Parameters {
 public:
  Parameters();

  // Numbered. Index 1..kMaxParameter, else throws Error(column, ...).
  double get(int index, int column = 0) const;
  void set(int index, double value, int column = 0);
  // A real-valued index must be within 1e-4 of an integer (LinuxCNC's rule).
  static int index_of(double index, int column);

  // Named: a name starting with '_' is global, else local to the current call level.
  // get_named throws Error for an unset name.
  double get_named(const std::string& name, int column = 0) const;
  bool find_named(const std::string& name, double* value) const;
  void set_named(const std::string& name, double value);

  // Call levels: push_call saves #1..#30 and the named locals and clears them (the
  // caller then sets the arguments); pop_call restores the caller's. A Fanuc M98
  // call (scoped_args false) shares #1..#30 with its caller: only the named locals
  // get a new scope (LinuxCNC 2.9).
  void push_call(bool scoped_args = true);
  void pop_call();
  int call_depth() const { return static_cast<int>(frames_.size()); }

  // Persistent parameters: which numbers the var file keeps. LinuxCNC's defaults
  // (5161-5186 G28/G30 homes, 5211-5230 G92, 5220-5390 coordinate systems) plus any
  // number listed in a var file that is read.
  bool persistent(int index) const;
  // Makes `index` persistent (kept in the var file written next).
  void make_persistent(int index);

  // Reads a var file; a line that starts with a number must hold a parameter index
  // in range and a finite value, else throws Error naming "file:line". Lines must be
  // in ascending order (LinuxCNC refuses others).
  void read_var_file(const std::string& path);
  // Writes the persistent parameters (ascending) atomically. Throws std::runtime_error
  // with the path and errno text on failure.
  void write_var_file(const std::string& path) const;

 private:
  struct Frame {
    std::array<double, 30> args{};
    bool scoped_args = true;
    std::unordered_map<std::string, double> locals;
  };
  std::vector<double> numbered_;  // [0] unused
  std::vector<bool> persistent_;
  std::unordered_map<std::string, double> globals_;
  std::unordered_map<std::string, double> locals_;
  std::vector<Frame> frames_;
};

}  // namespace cnc::rs274
