#pragma once
// The RS274NGC interpreter (LinuxCNC 2.9's dialect, milling): modal state, parameters,
// O-word control flow and subroutines, coordinate systems, tools, and the canonical
// calls it makes, one program line at a time. It reads its files as it goes, so a
// loop that runs a million times, or a 200,000-line program, is interpreted in
// bounded memory; the caller pulls lines (execute_next) only as fast as it needs
// their canonical calls.
//
// Errors: every refusal throws Error with the file, line and column of the word at
// fault and the chain of subroutine calls that led there; the canonical calls of
// the refused line are not made (the line is checked, then executed).
#include <array>
#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <unordered_map>
#include <vector>

#include "common/rs274/canon.h"
#include "common/rs274/cutter_comp.h"
#include "common/rs274/lexer.h"
#include "common/rs274/parameters.h"
#include "common/rs274/tool_table.h"

namespace cnc::rs274 {

// The interpreter's state between two lines, as run from line N rebuilds it and its
// test compares it field by field with a full run's (README "Run from line N").
struct ModalState {
  int motion = 800;           // G code in tenths (800 = G80)
  int plane = 0;              // Plane
  bool incremental = false, arc_incremental = true;
  int feed_mode = 0, units = 0;
  int comp = 400;
  double comp_radius = 0;
  int tool_length = 490, coord = 1;
  bool retract_r = true;
  int path = 0;
  double path_p = 0, path_q = 0, feed = 0, speed = 0;
  int spindle = 0;
  bool mist = false, flood = false;
  bool feed_override = true, speed_override = true, adaptive_feed = false, feed_hold = true;
  bool lathe_diameter = false;  // G7
  int tool = 0, selected_tool = -1;
  Pose tool_offset{}, g92{};
  bool g92_active = false;
  double rotation_deg = 0;
  // G68.2: the tilted work plane's rotation (row-major, column j its axis j) and origin.
  bool tilted_plane = false;
  std::array<double, 12> tilted_frame{};
  Pose position{};  // program coordinates and units
  // Parameters 5161..5390: G28 and G30 homes, G92 offsets, G54..G59.3 and their rotations.
  std::array<double, 230> offsets{};
  bool operator==(const ModalState&) const = default;
};

// G53.1: the rotary axes' machine positions that point the tool along a direction.
struct ToolOrientation {
  int tilt_axis = -1, rotary_axis = -1;  // indices into a Pose (3 A, 4 B, 5 C)
  double tilt_deg = 0, rotary_deg = 0;
};
// The direction (i, j, k) in the work coordinates, the machine position now (mm,
// degrees) and G53.1's P (0: the machine's rule, 1: the tilt >= 0 solution, 2: the
// tilt <= 0 one). Throws std::invalid_argument naming what refused it (a joint out of
// travel, a machine that cannot turn the tool).
using OrientTool = std::function<ToolOrientation(const std::array<double, 3>& direction, const Pose& machine, int choice)>;

struct MachineSetup {
  std::string axes = "XYZ";                // axis letters the machine has (of XYZABCUVW)
  std::string wrapped;                     // of A B C: LinuxCNC's WRAPPED_ROTARY axes
  Units machine_units = Units::kMm;        // of the tool table and the var file's offsets
  std::vector<std::string> subroutine_path;  // folders searched for o<name> call files (the first 10 that exist)
  std::string tool_table;                  // LinuxCNC tool table; empty: no tools
  std::string var_file;                    // LinuxCNC var file; empty: parameters are not kept
  bool write_var_file = true;              // at program end (M2/M30/%), atomically
  // The tool in the spindle (#5400) is kept in the var file: a program starts with the
  // tool the last one that ended left there (LinuxCNC's task keeps it across
  // programs), G49 still in effect. False: every program starts with no tool (rs274).
  bool tool_in_var_file = false;
  // A tool table changed by G10 L1/L10/L11 is written back at program end (with the
  // var file, when write_var_file), atomically, as LinuxCNC writes its table.
  bool write_tool_table = false;
  bool has_probe = false;                  // G38.x needs one
  // G33, G33.1, G76 and M19 need a spindle whose position the machine measures (an encoder).
  bool spindle_sync = false;
  // M19's angle is R plus this, degrees (LinuxCNC's [RS274NGC]ORIENT_OFFSET).
  double orient_offset_deg = 0;
  // What the program reads from the machine: G38.x's result (#5061-#5070 and where the
  // machine stopped) and M66's input (#5399). false, the interpreter takes them as
  // LinuxCNC's rs274 does (the probe at the move's end, #5070 = 0; #5399 as it was,
  // a digital input 0 or 1); true, execute_next() reads no further line until
  // set_probe_result() or set_input_result() supplies it.
  bool machine_results_supplied = false;
  int digital_inputs = 0;                  // M66 P indices 0..n-1
  int analog_inputs = 0;                   // M66 E indices 0..n-1
  int digital_outputs = 64;                // M62-M65 indices 0..n-1
  int analog_outputs = 64;                 // M67/M68
  bool block_delete = true;                // '/' lines are skipped (LinuxCNC's switch on)
  bool optional_stop = true;               // M1 stops
  Pose start_position{};                   // machine coordinates where the program starts
  int64_t max_call_depth = 100;
  // M6 remapped (LinuxCNC's REMAP=M6 ... ngc=NAME): M6 calls o<NAME> with the locals
  // #<selected_tool>, #<tool_in_spindle>, #<selected_pocket>, #<current_pocket>; an M6 in
  // it is the built-in change; a negative return value aborts; the rest of the M6's block
  // runs after the return. "" = the built-in M6.
  std::string m6_remap;
  // Fanuc-style subprograms (LinuxCNC 2.9): a bare O-word heads one, M98 P<n> L<k>
  // calls it k times, M99 returns. LinuxCNC's [RS274NGC]DISABLE_FANUC_STYLE_SUB = 1
  // is fanuc_subs = false (M98, M99 in a call and bare O-words are then refused).
  bool fanuc_subs = true;
  // M99 in the main program: false ends the program as M2 does (LinuxCNC's
  // standalone rs274, and what lets a program be validated to its end); true loops
  // back to its first line, as LinuxCNC's task does (the program then never ends).
  bool loop_on_main_m99 = false;
  // MDI (README "MDI"): the modes a line starts in, the ones the last MDI line left
  // (units, distance modes, plane, motion mode, feed mode and rate, coordinate system,
  // tool length offset); nullopt: a program's start.
  std::optional<ModalState> initial_modes;
  // G53.1 (tool normal to the tilted work plane) through the machine's kinematics;
  // empty: G53.1 is refused (no five-axis kinematics).
  OrientTool orient_tool;
};

class Interpreter {
 public:
  Interpreter(MachineSetup setup, Canon& canon);
  ~Interpreter();
  Interpreter(const Interpreter&) = delete;
  Interpreter& operator=(const Interpreter&) = delete;

  // Opens the main program, reads the var file and tool table, and makes the
  // initial canonical calls (units, offsets, plane) as rs274 does. Throws Error.
  void open(const std::string& path);

  // Executes the next line of the program. Returns false once the program has
  // ended (M2, M30, a closing '%'); further calls return false. Throws Error.
  bool execute_next();

  bool ended() const { return ended_; }
  // Probing (machine_results_supplied): a G38.x move was made and its result is awaited;
  // execute_next() does nothing meanwhile.
  bool waiting_for_probe() const { return probe_wait_; }
  // The G38.x move's end in machine coordinates (mm, degrees for A B C).
  const Pose& probe_target_machine() const { return probe_target_machine_; }
  int64_t probes_made() const { return probes_made_; }
  // The result of the awaited G38.x move, machine coordinates: where the probe input
  // changed (#5061-#5069 in the current work coordinates) and where the machine came
  // to rest (the current point from now on). Throws std::logic_error when none is awaited.
  void set_probe_result(bool tripped, const Pose& trip_machine, const Pose& rest_machine);
  // M66 (machine_results_supplied): the wait was made and the input's value is awaited;
  // execute_next() does nothing meanwhile.
  bool waiting_for_input() const { return input_wait_; }
  int64_t input_waits_made() const { return input_waits_; }
  // What LinuxCNC's rs274 reads (its simulated machine's inputs keep #5399: a digital
  // input 1 if it was not 0, an analog one #5399 itself).
  double simulated_input() const;
  // The value the awaited M66 read (-1: its wait timed out) into #5399. Throws
  // std::logic_error when none is awaited.
  void set_input_result(double value);
  // Lines read so far, executed or skipped (a loop that skips over a long block
  // every iteration costs that block each time: the bound on this number bounds the work).
  int64_t lines_executed() const { return lines_executed_; }
  const std::vector<std::string>& file_names() const { return file_names_; }
  const Parameters& parameters() const { return params_; }
  const MachineSetup& setup() const { return setup_; }
  // The raw text of the line being executed (for rs274's N field and error reports).
  const std::string& current_text() const { return text_; }
  ModalState modal_state() const;
  // Called before each line is executed (the state is the one after the line
  // before): the file index (file_names()) and the line number. Run from line N.
  void set_line_hook(std::function<void(int32_t file, int32_t line)> hook) { line_hook_ = std::move(hook); }

 private:
  struct SourceFile;
  struct Frame;
  struct Loop;
  struct Words;
  struct SubDef {
    int32_t file = 0;
    int64_t offset = 0;  // the byte after the `sub` line
    int32_t line = 0;    // that `sub` line's number
    int64_t start = 0;   // the byte where that line starts
    bool fanuc = false;  // a bare `O<n>` head (M98 calls it) rather than `O<n> sub`
  };

  // Reading.
  bool read_line();
  void execute_line();
  void execute_o(const OStatement& o);
  double o_condition(const OStatement& o);
  void o_sub(const OStatement& o, const std::string& name);
  void o_return(const OStatement& o, const std::string& name);
  void o_program(const OStatement& o, const std::string& name);
  void o_call(const OStatement& o, const std::string& name);
  void o_loop(const OStatement& o, const std::string& name);
  void o_if(const OStatement& o, const std::string& name);
  void o_break_continue(const OStatement& o, const std::string& name);
  void skip_to(const std::string& name, uint32_t kinds_mask);
  std::string o_name(const OStatement& o);
  std::vector<std::string> subroutine_dirs() const;
  int fanuc_m_code();
  void fanuc_call();
  void fanuc_return();
  void return_from_call(double value, bool has_value, int column);
  // o<name> call (m98 false) or M98 P<name> (true): where the subroutine starts.
  SubDef find_sub(const std::string& name, int column, bool m98);
  Frame call_frame(const std::string& name, int column) const;
  void enter_sub(Frame fr, const SubDef& def);
  std::string beyond_sub_dirs(const std::string& file) const;
  [[noreturn]] void fail_at_def(const SubDef& def, const std::string& detail);

  // Blocks.
  void collect_words(Words& w);
  void check_words(const Words& w);
  void apply_settings();
  void execute_block(Words& w);
  void execute_block_after_m6(Words& w);
  void comments_of_line();
  // execute_block's steps, in its order.
  bool continue_nurbs(Words& w);
  bool wrapped(char axis) const;
  double unwrap_rotary(const Words& w, char axis, double commanded, double at) const;
  double unwrap_rotary(int column, char axis, double commanded, double at, double sign_of) const;
  void g93_g95(const Words& w);
  void f_s_t(const Words& w);
  void m62_m68(const Words& w);
  void m6_m61(Words& w);
  void m3_m5(const Words& w);
  void m70_m73(const Words& w);
  void m7_m9(const Words& w);
  void m48_m53(const Words& w);
  void g4(const Words& w);
  void g17_g19(const Words& w);
  void g20_g21(const Words& w);
  void g7_g8(Words& w);
  void g40_g42(const Words& w);
  void g43_g49(Words& w);
  void g54_g59(const Words& w);
  void g61_g64(const Words& w);
  void g90_g91(const Words& w);
  void g98_g99(const Words& w);
  void homes_and_offsets(Words& w);
  void motion_block(Words& w);
  void stops(const Words& w);
  void motion(Words& w);
  void arc(Words& w, bool cw, const Pose& end);
  void nurbs_fanuc_open(Words& w);
  void nurbs_fanuc_line(Words& w);
  void nurbs_fanuc_close();
  void nurbs_g5_open(Words& w);
  void nurbs_g5_point(Words& w);
  void nurbs_g5_close();
  void g10(Words& w);
  void g10_coord_system(Words& w, int l, int p);
  void g10_tool(Words& w, int l, int p);
  void g28_g30(Words& w, bool g30);
  void g92(Words& w);
  // The tilted work plane (interpreter_twp.cc).
  void g68_2_g69(Words& w);
  void g53_1(const Words& w);
  void refuse_in_tilted_plane(const Words& w) const;
  Pose frame_of(const Pose& work_mm) const;  // X Y Z of work coordinates in the tilted frame
  Pose work_of(const Pose& frame_mm) const;
  // An arc of the tilted frame's plane (its axes a1 a2, normal a3; centre in mm) as
  // the exact curve it is in space: a rational quadratic NURBS.
  void frame_arc(int col, const std::array<int, 3>& plane_axes, double cen1_mm, double cen2_mm, bool cw, int turns,
                 const Pose& from_frame, const Pose& to_frame, const Pose& end);
  void tool_change(Words& w);
  void set_tool_params();
  Pose current_point(bool after_g40 = false) const;
  void reread_position();
  struct SavedModes;
  void restore_modes(const SavedModes& s, int column);
  void cycle(Words& w);
  void spline(Words& w, bool cubic, int col);
  void straight_probe(Words& w, int g, int col);
  void synced_move(Words& w, int g, int col);  // G33, G33.1
  void threading_cycle(Words& w, int col);     // G76
  int spindle_number(const Words& w) const;    // the $ word, as LinuxCNC keeps it (an int)
  int motion_to_be(const Words& w) const;      // the motion the block makes (G code in tenths), -1 none
  void wait_input(const Words& w);
  void set_coord_system(int index);
  void end_program(bool m30);
  void persist();  // the var file and (when changed) the tool table, at program end
  void update_position_params();

  Pose axis_target(const Words& w, bool machine) const;  // G53: machine coordinates
  double to_program(double machine_units_value) const;
  double to_program_axis(int axis, double mm_or_degrees) const;
  Pose program_pose(const Pose& mm) const;
  double length_scale() const;
  double param_len(int base, int i) const;
  Pose machine_of(const Pose& program_mm, int cs) const;
  Pose program_of(const Pose& machine_mm, int cs) const;
  void set_param_len(int base, int i, double mm);
  [[noreturn]] void fail(int column, const std::string& detail) const;
  SourceRef ref(int column = 0) const;

  // Parameters as expressions read them (predefined names included).
  class Reader;
  double named_value(const std::string& name, int column) const;
  bool named_exists(const std::string& name) const;

  MachineSetup setup_;
  // Every canonical call goes through the cutter-compensation filter, which passes
  // calls straight on while compensation is off.
  std::unique_ptr<CutterComp> comp_filter_;
  Canon& canon_;
  Parameters params_;
  ToolTable tools_;
  std::unique_ptr<Reader> reader_;

  std::vector<std::string> file_names_;
  std::vector<std::unique_ptr<SourceFile>> files_;
  int32_t file_ = 0;              // the file being read
  int32_t line_no_ = 0;           // its current line number
  Line line_;                     // the current line, lexed
  std::string text_;              // its text
  std::vector<Frame> frames_;     // subroutine calls
  std::vector<int64_t> m98_runs_left_;  // per caller level: M98 L runs still to make, -1 idle
  std::vector<Loop> loops_;       // open while/do/repeat/if statements
  std::unordered_map<std::string, SubDef> subs_;
  bool ended_ = false;
  bool started_ = false;          // the first line (maybe '%') was read
  bool percent_open_ = false;
  int64_t lines_executed_ = 0;
  double last_returned_ = 0;

  // Modal state (LinuxCNC's groups).
  int motion_ = 800;              // G code in tenths; 800 = G80, -1 = none
  Plane plane_ = Plane::kXY;
  bool incremental_ = false;      // G91
  bool arc_incremental_ = true;   // G91.1 (LinuxCNC's default)
  bool lathe_diameter_ = false;   // G7 (LinuxCNC's lathe diameter mode): X words are diameters
  FeedMode feed_mode_ = FeedMode::kUnitsPerMinute;
  Units units_ = Units::kMm;
  int comp_ = 400;                // 400, 410, 420 (tenths); 411/421 for G41.1/G42.1
  double comp_radius_ = 0;
  int tool_length_ = 490;         // 430, 431, 432 or 490
  int coord_ = 1;                 // 1..9 = G54..G59.3
  bool retract_r_ = true;         // G99 (rs274 starts in it)
  PathMode path_ = PathMode::kContinuous;  // G64 without P (rs274 starts in it)
  double path_p_ = 0, path_q_ = 0;
  double feed_ = 0;
  double speed_ = 0;
  int spindle_ = 0;               // 0 off, 1 cw, -1 ccw
  bool mist_ = false, flood_ = false;
  bool feed_override_ = true, speed_override_ = true, adaptive_feed_ = false, feed_hold_ = true;
  bool remap_called_ = false;     // M6 called its remap: the rest of the block waits for the return
  int tool_ = 0;                  // in the spindle
  bool tools_changed_ = false;    // G10 L1/L10/L11 changed the table
  int selected_tool_ = -1;        // T word given
  Pose tool_offset_{};
  Pose g92_{};
  bool g92_active_ = false;
  double rotation_deg_ = 0;
  // G68.2 (Fanuc's feature coordinate system): while twp_, the program's X Y Z (and
  // arcs' centres) are in a frame turned by twp_r_ (row-major: column j is the frame's
  // axis j in work coordinates) about twp_o_ (work coordinates, mm). position_ stays in
  // work coordinates.
  bool twp_ = false;
  bool twp_tool_tilted_ = false;  // G53.1 turned the tool off the work's Z
  std::array<double, 9> twp_r_{};
  std::array<double, 3> twp_o_{};
  double mu_ = 1.0;               // mm per machine unit
  Pose position_{};               // current position, program coordinates and units
  double cycle_old_z_ = 0;        // canned cycles: sticky values
  double cycle_r_ = 0, cycle_q_ = 0, cycle_p_ = 0, cycle_z_ = 0, cycle_i_ = 0, cycle_j_ = 0, cycle_k_ = 0;
  int prev_motion_ = 800;         // the motion mode before this block's
  std::array<double, 2> spline_pq_{};  // the last G5's P Q (mm), for a following G5 without I J
  bool spline_continues_ = false;
  int32_t fanuc_closed_line_ = 0;  // the line where the last G6.2 curve's knots were complete
  int32_t w53_column_ = 0;         // column of the G5.3 closing the curve
  bool in_cycle_ = false;
  bool probe_wait_ = false;
  bool input_wait_ = false;
  bool input_analog_ = false;
  int64_t input_waits_ = 0;
  Pose probe_target_machine_{};
  int64_t probes_made_ = 0;

  // NURBS collection (G5.2 / Fanuc G6.2): control points until the curve closes.
  struct NurbsCollect;
  std::unique_ptr<NurbsCollect> nurbs_;

  // M70-M73: saved modal state.
  std::vector<SavedModes> saved_;
  std::function<void(int32_t, int32_t)> line_hook_;
};

}  // namespace cnc::rs274
