#pragma once
// The configuration of one cell: plain structs with defaults, loaded strictly from
// `config/machines/NAME.yaml`.
#include <cstdint>
#include <limits>
#include <span>
#include <string>
#include <string_view>
#include <vector>

namespace cnc::config {

struct DriveConfig {
  std::string transport = "modbus_tcp";  // a name of common/drive/transport.h
  std::string host = "127.0.0.1";        // modbus_tcp
  int port = 1502;                       // modbus_tcp
  std::string device;                    // modbus_rtu: serial device
  int baud = 115200;                     // modbus_rtu
  std::string parity = "none";           // modbus_rtu: none | even | odd
  int stop_bits = 1;                     // modbus_rtu: 1 | 2
  int unit_id = 1;                       // Modbus slave / unit id
  std::string profile = "sim";           // config/drives/<profile>.yaml (or a path to a profile file)
  double response_timeout_s = 0.05;

  // The link this drive is on: drives with the same key share one connection.
  std::string link_key() const;
};

// The drive bridge (section `drive_bridge:`).
struct DriveBridgeConfig {
  bool enable_on_start = false;       // enable the drives when the bridge starts; else wait for ENABLE
  double enable_timeout_s = 2.0;      // the drives must reach "enabled" within this after ENABLE
  double link_loss_timeout_s = 0.25;  // a drive that answers nothing for this long has lost its link
  double reconnect_min_s = 0.1;       // back-off between attempts to reopen a lost link, doubling up to max
  double reconnect_max_s = 2.0;
  // How many coarse cycles the fine interpolation plays behind the newest setpoint
  // (the jitter buffer). 2 on a clean network; a lossy one with jitter wants 4: a run
  // of three setpoints lost comes back with the next (each carries the three before
  // it) before the playback needs them.
  double lead_cycles = 2.0;
};

struct ServoSimAxisConfig {
  double bandwidth_hz = 40.0;  // closed position loop bandwidth
  double damping = 1.0;
  double max_velocity_mm_s = 0;  // 0: the axis's max_velocity_mm_s
  // The drive's communication watchdog (0: off): enabled and no Modbus request for
  // comm_timeout_s, it brakes at comm_stop_decel_mm_s2 (0: the axis's max_accel_mm_s2)
  // and faults, as a real drive's communication-loss reaction does.
  double comm_timeout_s = 0;
  double comm_stop_decel_mm_s2 = 0;
  // A home switch: closed beyond home_switch_mm in the axis's home
  // direction (axes[].home.direction), where each closing happens at home_switch_mm
  // plus a normal draw of sigma (drawn anew each time it opens; seeded), and opens
  // again hysteresis_mm back. The drive latches its position at each closing edge.
  bool has_home_switch = false;
  double home_switch_mm = 0;
  double home_switch_sigma_mm = 0.002;
  double home_switch_hysteresis_mm = 0.05;
  uint64_t home_switch_seed = 1;
  // Hard-limit switches of the simulated machine (the axis's safety.hard_limits inputs):
  // open (0) at and beyond these positions; NaN: none at that end.
  double limit_min_mm = std::numeric_limits<double>::quiet_NaN();
  double limit_max_mm = std::numeric_limits<double>::quiet_NaN();
};

// Homing of one axis (axes[].home), LinuxCNC's sequence: search towards the
// switch at search_velocity, back off, approach again at latch_velocity; the position
// latched at the switch's edge is switch_position_mm in machine coordinates; then the
// axis moves to position_mm. `absolute`: the drive's position is the machine's.
struct HomeConfig {
  std::string method = "none";  // none (needs no homing) | switch | absolute
  double search_velocity_mm_s = 10;
  double latch_velocity_mm_s = 1;
  int direction = -1;               // towards the switch: -1 or +1
  double switch_position_mm = 0;    // machine coordinate of the switch's closing point (LinuxCNC HOME_OFFSET)
  double position_mm = 0;           // where the axis goes after homing (LinuxCNC HOME)
  double backoff_mm = 2;            // back off the switch this far before the latch approach
  int order = 0;                    // homing all: lower first, equal together one after another
};

// A gantry (axes[].gantry): the axis is driven by two drives, its own (`drive`, the
// first joint) and this second one, LinuxCNC's two joints on one axis. Both follow the
// axis's setpoint, the second plus its squaring offset: after homing, the difference
// of the two sides' offsets (each latches its own switch, whose machine coordinate is
// home.switch_position_mm and switch_position_mm here), before it the difference at
// the drives' enabling. The drive bridge faults (a controlled stop) when the two
// sides' actual positions, less that offset, differ by more than skew_limit_mm.
struct GantryConfig {
  bool enabled = false;  // the section is present
  std::string name;      // the second joint's name (alarms, JOINT_STATUS), e.g. Y2
  DriveConfig drive;
  double switch_position_mm = 0;  // machine coordinate of its switch's closing point (its own HOME_OFFSET)
  double skew_limit_mm = 0.5;
  // Homing: the second side's switch must close within this travel of the first's.
  double home_max_difference_mm = 5;
  ServoSimAxisConfig sim;  // the second simulated drive (cnc-servo-sim only): its own switch
};

// The travel of a wrapped rotary axis (axes[].wrapped): none in effect, finite.
inline constexpr double kWrappedTravelDeg = 1e9;

struct AxisConfig {
  std::string name;  // X, Y, Z, ...
  // A rotary axis (A, B or C only) counts in degrees: every `_mm` below is then deg
  // (deg/s, deg/s², deg/s³), and LinuxCNC's feed rules treat it as rotary.
  bool rotary = false;
  // LinuxCNC's WRAPPED_ROTARY (rotary only): G90 words are angles modulo 360 reached in
  // the direction of the word's sign; no travel limits.
  bool wrapped = false;
  double min_mm = 0;
  double max_mm = 0;
  double max_velocity_mm_s = 0;
  double max_accel_mm_s2 = 0;
  double max_jerk_mm_s3 = 0;
  double max_following_error_mm = 1.0;
  double home_mm = 0;  // where the simulated drive starts
  DriveConfig drive;
  ServoSimAxisConfig sim;  // used by cnc-servo-sim only
  HomeConfig home;
  double jog_velocity_mm_s = 0;  // jogging's speed (0: a tenth of max_velocity_mm_s)
  GantryConfig gantry;
};

// The simulated VFD of a spindle (spindle.sim, cnc-servo-sim only): a first-order
// speed response and a load figure (output current).
struct SpindleSimConfig {
  double time_constant_s = 0.5;     // the output frequency follows the setpoint with this time constant
  double load_current_a = 2.0;      // output current at max_rpm, turning steadily
  double inertia_current_a = 6.0;   // extra current while accelerating at max_rpm / time_constant_s
};

// A spindle driven by a VFD on the bus (section `spindle:`, optional). Without the
// section the cell has no spindle device and M3/M4/M5/S stay events in the log.
struct SpindleConfig {
  bool enabled = false;  // the section is present
  DriveConfig drive;     // transport, address, unit id and a profile with state_machine delta_vfd or huanyang
  double max_rpm = 24000;          // S is limited to this
  double rpm_per_hz = 60;          // spindle rpm per Hz of the drive's output frequency (2-pole motor: 60)
  double at_speed_tolerance = 0.05;  // at speed: |actual - commanded| <= this fraction of commanded
  double at_speed_timeout_s = 10;    // a change not at speed within this is a fault
  // The spindle override's range (LinuxCNC's [DISPLAY] MIN_SPINDLE_OVERRIDE and
  // MAX_SPINDLE_OVERRIDE, whose defaults these are).
  double min_override = 0.5;
  double max_override = 1.0;
  // The spindle's encoder (a servo spindle, or a VFD with an encoder input): counts per
  // revolution, 0 none. With one, G33, G33.1 and M19 run: the path follows the
  // spindle's measured position.
  int64_t encoder_counts_per_rev = 0;
  // How long the axes take to reach a setpoint after the bridge plays it (its smoothing
  // and the drives' following): a synchronised move follows the spindle's position
  // predicted this much further ahead, so the axes, not their setpoints, meet the
  // spindle (a rigid tap's way down and up on one helix).
  double sync_lead_s = 0.0;
  // M19's angle is R plus this, degrees (LinuxCNC's [RS274NGC]ORIENT_OFFSET): where the
  // encoder's index lies from the spindle's reference angle.
  double orient_offset_deg = 0.0;
  bool measured_position() const { return enabled && encoder_counts_per_rev > 0; }
  // Orientation (M19; needs the encoder): the bridge's position loop turns the spindle
  // at orient_gain_per_s revolutions per second per revolution of error, at most
  // orient_rpm; oriented within orient_tolerance_deg of the angle and at rest; not
  // oriented within orient_timeout_s of the command is a fault naming that key.
  double orient_tolerance_deg = 0.5;
  double orient_timeout_s = 10;
  double orient_rpm = 60;
  double orient_gain_per_s = 2;
  SpindleSimConfig sim;
};

// An I/O module on the bus (io.modules[]): its link as a drive's (transport, address,
// line settings, unit id), no profile: its points say what it holds.
struct IoModuleConfig {
  std::string name;
  DriveConfig link;  // `profile` unused
};

// A named point of an I/O module (io.points[]): one coil, discrete input, input
// register or holding register. A register's value is its raw count times `scale`.
enum class IoKind : int8_t { kCoil, kDiscreteInput, kInputRegister, kHoldingRegister };
const char* to_string(IoKind k);
struct IoPointConfig {
  std::string name;
  int module = 0;  // index into IoConfig::modules
  IoKind kind = IoKind::kCoil;
  int address = 0;      // 0 .. 65535 in the kind's table
  double scale = 1.0;   // registers: value = raw x scale
  bool is_signed = false;  // registers: the raw count is two's complement
};

// I/O modules and what the program's codes switch (section `io:`, optional). Without
// it M7/M8/M9 and M62-M65 stay events in the log, as before.
struct IoConfig {
  bool enabled = false;  // the section is present
  std::vector<IoModuleConfig> modules;
  std::vector<IoPointConfig> points;
  int coolant_mist = -1;   // the coil point M7 switches (index into points), -1: none
  int coolant_flood = -1;  // the coil point M8 switches
  std::vector<int> digital_outputs;  // M62-M65 P n: the coil point points[digital_outputs[n]]
  std::vector<int> digital_inputs;   // discrete inputs: M66 P n waits on points[digital_inputs[n]]
  std::vector<int> analog_inputs;    // input or holding registers: M66 E n reads the n-th
  std::vector<int> analog_outputs;   // holding registers: M67/M68 E n sets the n-th (value / scale)
  int point_index(const std::string& name) const;
  // How an alarm names a point: "NAME on module MODULE", the config's names both.
  std::string point_label(int point) const;
};

// The hardware safety chain (section `safety:`, optional; needs io:). Inputs are
// normally closed: 1 while all is well, so 0 (pressed, a broken wire) or a module that
// does not answer is the condition.
struct SafetyConfig {
  int estop_input = -1;  // safety.estop.input: the discrete-input point (index into io.points), -1: none
  // safety.hard_limits[]: an axis's limit switches, discrete-input points (-1: none at that end).
  struct HardLimit {
    int axis = 0;  // index into axes
    int min_input = -1;
    int max_input = -1;
  };
  std::vector<HardLimit> hard_limits;
  int door_input = -1;  // safety.door.input: the guard door's switch (1: shut), -1: none
  bool enabled() const { return estop_input >= 0 || !hard_limits.empty() || door_input >= 0; }
};

// A touch probe (section `probe:`, optional; needs io:): G38.2-G38.5 stop where its
// input changes, and a contact during any other move stops the machine with a fault.
struct ProbeConfig {
  int input = -1;  // probe.input: a discrete-input point (index into io.points), 1 while touching; -1: none
  // probe.latch: "drives": every axis drive latches its own position at the probe's
  // edges (its touch-probe function); "input" (default): the drives' positions of the
  // I/O round that sampled the edge.
  bool drive_latch = false;
  // The servo simulator's fixture (probe.sim_box): an axis-aligned box in machine
  // coordinates of the first three axes; the input reads 1 while the tool tip is in it.
  bool sim_box = false;
  double box_min_mm[3] = {0, 0, 0}, box_max_mm[3] = {0, 0, 0};
  // A vertical bore through it (bore_diameter_mm > 0): the tip in the bore is not in the box.
  double bore_xy_mm[2] = {0, 0}, bore_diameter_mm = 0;
  bool enabled() const { return input >= 0; }
};

// Operator functions (section `operator:`).
struct OperatorConfig {
  // No program, MDI or homing-free motion other than jogging until every axis with
  // a home method is homed.
  bool homing_required = false;
  // A continuous jog stops (jerk-limited, recorded) when no JOG_KEEPALIVE came for this long.
  double jog_keepalive_timeout_s = 0.2;
  // Where MDI lines and touch-offs are written as one-line programs ("" = the system's temp folder).
  std::string mdi_directory;
  // Run from line N: the approach lifts Z to this height (machine coordinates, mm)
  // before it moves across to the line's start point. NaN (default): Z's max_mm.
  double safe_z_mm = std::numeric_limits<double>::quiet_NaN();
};

// The map between joints and axes (section `kinematics:`, optional; common/kinematics).
// The names make_kinematics knows: a config naming another is refused here.
// xyz?c-trt: tilting table (A or B) carrying a rotary table C, LinuxCNC's kinematics of
// the same names; xyz?c-head: a spindle head turning about C and tilting about A or B;
// xyz?c-head-table: a head tilting about A or B over a rotary table C.
inline constexpr const char* kKinematicsTypes[] = {"identity",   "xyzac-trt",        "xyzbc-trt",       "xyzac-head",
                                                   "xyzbc-head", "xyzac-head-table", "xyzbc-head-table"};
struct KinematicsConfig {
  std::string type = "identity";  // joint i is axis i, with axes[i]'s limits
  // A rotary table C (trt, head-table): its centre of rotation in machine coordinates
  // (LinuxCNC's x-, y-, z-rot-point). trt: the tilt axis's centre relative to the C
  // axis's (LinuxCNC's x-offset for B, y-offset for A, z-offset).
  double x_rot_point_mm = 0;
  double y_rot_point_mm = 0;
  double z_rot_point_mm = 0;
  double x_offset_mm = 0;
  double y_offset_mm = 0;
  double z_offset_mm = 0;
  // Table axes turn the table by the right-hand rule about +X, +Y, +Z for a positive
  // angle (LinuxCNC's default); true: the other way, so that the tool turns that way
  // relative to the workpiece (RS274's convention, LinuxCNC's conventional-directions).
  bool conventional_directions = false;
  double pivot_mm = 0;  // head: from the tilt axis to the spindle's gauge line
  // Which of the two rotary solutions of a tool direction: nearest | positive_tilt | negative_tilt.
  std::string solution = "nearest";
  // A tool direction closer than this to the C axis keeps C where it is.
  double pole_tolerance_deg = 1e-6;
};

// The browser HMI cnc-hmi (section `hmi:`): where it listens, who may use it.
struct HmiConfig {
  std::string listen = "127.0.0.1";  // any other address needs users_file
  int port = 8080;
  std::string users_file;            // "user:$argon2id$..." lines (crypto_pwhash_str); relative to the config
  bool read_only_without_login = false;  // a view-only page for a browser that has not logged in
  std::string program_dir;           // the only folder programs are loaded from ("" = ../programs beside the config)
  double status_rate_hz = 25;        // status pushed to each browser (>= 20)
  std::string runs_dir;              // the recorded runs the page lists ("" = logger.directory)
  int64_t upload_max_bytes = int64_t{8} << 20;  // the largest program a browser may upload into program_dir
};

// The OPC UA server cnc-opcua (section `opcua:`, optional; docs/opcua.md): OPC 40501-1
// Machine Tools over the HMI's API. Absent: no server (./cnc up does not start it).
struct OpcuaConfig {
  bool enabled = false;              // the section is there
  std::string listen = "127.0.0.1";  // the address the endpoint listens on
  int port = 4840;                   // opc.tcp port (4840: IANA's for OPC UA)
  bool anonymous = false;            // anonymous sessions (read only); off: a user of hmi.users_file must log in
  bool allow_security_none = false;  // an endpoint with SecurityPolicy None beside Basic256Sha256 SignAndEncrypt
  // A client application's certificate that the server does not know: trusted on first
  // use (true), or refused and kept in the state's pki/rejected until moved to pki/trusted.
  bool trust_unknown_clients = false;
  // The HMI user cnc-opcua logs in as (hmi.users_file) and the file with its password
  // (owner-only, relative to the config); needed when the HMI asks for a login.
  std::string hmi_user;
  std::string hmi_password_file;
  // Identification (MachineToolIdentificationType).
  std::string manufacturer;
  std::string model;
  std::string serial_number;
  std::string product_instance_uri;  // "" = urn:cnc:<cell.name>:<serial_number>
  int year_of_construction = 0;      // 0: not given
};

struct ProcessConfig {
  // Choi et al. 2005's roughness feed law; all zero = not set.
  double ball_radius_mm = 0;
  int flutes = 0;
  double pick_feed_mm = 0;
  double target_rmax_um = 0;
  double spindle_rpm = 0;
};

// The cutting-force model live (section `cutting:`, optional):
// the monitor predicts force and tool deflection per setpoint and alarms over the
// tolerance, and with feed_limit the interpolator's planner limits the feed so the
// predicted deflection (and force, when max_force_n is set) stays within them. The
// engagement is estimated from a Z-map stock (a box) that the tool's envelope is
// removed from as it moves. Paths are relative to the config file's folder.
struct CuttingConfig {
  bool enabled = false;           // the section is present
  std::string tool_file;          // config/tools/*.yaml (a flat end mill)
  std::string material_file;      // config/materials/*.yaml
  std::string model;              // "" = the material file's law; linear_edge | chip_thickness_law
  double stock_x_min_mm = 0, stock_y_min_mm = 0, stock_x_max_mm = 0, stock_y_max_mm = 0;
  double stock_top_z_mm = 0;
  double stock_pitch_mm = 0.05;
  double deflection_tolerance_mm = 0;  // tool-tip deflection (peak over a tooth period)
  double max_force_n = 0;              // peak |F| in XY; 0 = no force limit
  bool feed_limit = false;             // the interpolator limits the feed (limit = force)
  double station_mm = 0.1;             // the planner's engagement stations along a cutting block
  double disc_height_mm = 0.1;         // the force model's axial discs
  int angles_per_tooth = 16;           // rotation angles per tooth period for the peaks
};

// The part-program language's machine-dependent settings (LinuxCNC's [RS274NGC]
// section and tool/var files). Paths are relative to the config file's folder.
struct ProgramConfig {
  std::vector<std::string> subroutine_path;  // folders searched for o<name> call files
  // program.m6_remap: M6 calls o<NAME> (LinuxCNC's REMAP=M6 ngc=NAME); "" = the built-in M6.
  std::string m6_remap;
  std::string tool_table;                    // LinuxCNC tool table (mm); "" = no tools
  std::string var_file;                      // LinuxCNC var file (mm); "" = parameters not kept
  bool probe = false;                        // G38.x needs a probe input
  int digital_inputs = 0;                    // M66 needs inputs
  int analog_inputs = 0;
  int digital_outputs = 8;                   // M62-M65 P index range
  int analog_outputs = 4;                    // M67/M68 E index range
  bool block_delete = true;                  // '/' lines are skipped
  bool optional_stop = true;                 // M1 stops
  int64_t max_validation_lines = 200'000'000;  // lines interpreted to validate a program at load
  // The dry run (cnc-plan, the HMI's preview) gives up after this much program time:
  // a week: LinuxCNC's test good-arc.medium (half a circle of r 1,000 mm at F1, 52 h) runs.
  double dry_run_max_time_s = 7 * 86400.0;
  // G64 P: runs of short G1 moves fitted to splines within P (else only corner blends).
  bool g64_fit = true;
  double g64_fit_max_segment_mm = 2.0;  // longer moves are not part of a fitted run...
  double g64_fit_max_segment_per_p = 100.0;  // ...unless within this many times P
  double g64_fit_max_turn_deg = 30.0;   // a sharper turn between two moves ends a run
  // The path tolerance of G64 without P (and of a program with no G64 word, which
  // starts in G64): 0 keeps the programmed lines exactly, as G61 does; never unbounded.
  double default_path_tolerance_mm = 0.0;
};

// Signed channels (section `security:`): see common/bus/auth.h.
struct SecurityConfig {
  bool signing = false;         // the shipped configs say true; a config without the section runs unsigned (warned)
  std::string key_file;         // relative to the config file's folder; required when signing
  double max_age_s = 2.0;       // freshness window of a message's time stamp at its receiver
};

// The MQTT publisher cnc-mqtt (section `mqtt:`, optional; docs/mqtt.md): the cell's
// state, alarms and job records to a broker, read-only. Absent: no publisher.
struct MqttConfig {
  bool enabled = false;              // the section is there
  std::string host = "127.0.0.1";    // the broker
  int port = 1883;                   // 1883 plain, 8883 with TLS (the default when ca_file is set)
  std::string topic_prefix = "cnc";  // topics are PREFIX/CELL/...
  std::string client_id;             // "" = cnc-CELL: fixed, so the broker keeps the session
  int keepalive_s = 10;              // the broker declares the cell offline 1.5 keepalives after it went silent
  double state_period_s = 1.0;       // the retained state at most this often, and on each program state change
  std::string username;              // the cell's own broker user
  std::string password_file;         // its password (first line; owner-only); relative to the config
  std::string ca_file;               // TLS on: the CA that signed the broker's certificate
  std::string cert_file;             // TLS client certificate (with key_file)
  std::string key_file;
};

struct MachineConfig {
  std::string source_file;
  std::string source_text;  // the YAML as loaded: the interpolator records it in the log for replay

  // cell
  std::string name;
  std::string channel_prefix;  // e.g. "SIM3." — prepended to every channel
  std::string lcm_url;         // "" = LCM default

  // timing
  double ipo_period_s = 0.004;
  double servo_period_s = 0.001;
  double setpoint_timeout_s = 0.05;
  double stop_decel_mm_s2 = 1000.0;
  double heartbeat_period_s = 1.0;
  // A peer whose heartbeat is missing this long is lost: the services that depend on
  // it raise an ALARM naming it (common/service/peer_watch.h). Default: 4 periods.
  double heartbeat_timeout_s = 4.0;
  int realtime_priority = 0;  // SCHED_FIFO priority of the cyclic services; 0 = normal scheduling
  // CPUs the cyclic threads (interpolator, drive bridge servo loop, servo simulator)
  // are pinned to, with the threads they start; empty = no pinning.
  std::vector<int> realtime_cpus;

  std::vector<AxisConfig> axes;
  SpindleConfig spindle;
  IoConfig io;
  SafetyConfig safety;
  KinematicsConfig kinematics;
  ProbeConfig probe;

  // motion
  double default_feed_mm_per_min = 1000.0;
  double chord_tolerance_mm = 0.001;
  double path_accel_mm_s2 = 1000.0;
  double path_jerk_mm_s3 = 20000.0;
  int block_window = 32;  // blocks the interpolator keeps requested ahead
  // Planning work per interpolation cycle: blocks are applied to the core until
  // this many curve samples were planned in the cycle (at least one block). Keeps a
  // cycle's compute time bounded when many or large NURBS blocks arrive at once;
  // counted in samples, not time, so the cycle a block is applied at is deterministic.
  int plan_budget_samples = 1500;
  // Curve-parameter update per cycle: first_order (u += Δs/|P'|), taylor2 (Choi et al. 2005
  // eq. 7), corrected (eq. 7, then Newton so the step's chord has the commanded length).
  std::string param_update = "corrected";

  ProcessConfig process;
  CuttingConfig cutting;
  ProgramConfig program;

  OperatorConfig operator_;
  HmiConfig hmi;
  OpcuaConfig opcua;
  MqttConfig mqtt;

  DriveBridgeConfig drive_bridge;
  // drive_bridge.profile_dir: where drive profiles are; "" = config/drives beside the machine's folder.
  std::string drive_profile_dir;

  // logger
  std::string log_directory = "runs";
  double log_rotate_mb = 512.0;
  double log_flush_period_s = 0.5;

  SecurityConfig security;

  // monitor
  double monitor_rmax_margin = 0.1;  // alarm when R_max > target·(1 + margin)

  // Channel names with the prefix applied.
  std::string channel(const std::string& base) const { return channel_prefix + base; }
  int axis_index(const std::string& name) const;  // -1 when absent
};

// Loads and validates; throws ConfigError naming the key path.
MachineConfig load_machine_config(const std::string& file);
MachineConfig parse_machine_config(const std::string& yaml_text, const std::string& file_label);

// The keys the reader accepts, one table per mapping: `path` is the mapping's dotted
// path ("" the top level, "axes[]" each item of `axes`). The reader checks every
// file against these tables; docs/config.md documents each key (a test keeps both equal).
struct KeySection {
  std::string_view path;
  std::span<const std::string_view> keys;
};
std::span<const KeySection> machine_config_keys();

// Channel base names of the cell.
namespace channels {
inline constexpr const char* kProgramCmd = "PROGRAM_CMD";
inline constexpr const char* kProgramState = "PROGRAM_STATE";
inline constexpr const char* kProgramAnswers = "PROGRAM_ANSWERS";
inline constexpr const char* kProgramBlocks = "PROGRAM_BLOCKS";
inline constexpr const char* kBlockRequest = "BLOCK_REQUEST";
inline constexpr const char* kSetpoints = "SETPOINTS";
inline constexpr const char* kInterpState = "INTERP_STATE";
inline constexpr const char* kInterpInput = "INTERP_INPUT";
inline constexpr const char* kInterpConfig = "INTERP_CONFIG";
inline constexpr const char* kAxisStatus = "AXIS_STATUS";
inline constexpr const char* kMonitor = "MONITOR";
inline constexpr const char* kAlarm = "ALARM";
inline constexpr const char* kHeartbeat = "HEARTBEAT";
inline constexpr const char* kDriveCmd = "DRIVE_CMD";
inline constexpr const char* kSpindleCmd = "SPINDLE_CMD";
inline constexpr const char* kSpindleStatus = "SPINDLE_STATUS";
inline constexpr const char* kIoCmd = "IO_CMD";
inline constexpr const char* kIoStatus = "IO_STATUS";
inline constexpr const char* kJointStatus = "JOINT_STATUS";
}  // namespace channels

}  // namespace cnc::config
