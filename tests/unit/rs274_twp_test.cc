// The tilted work plane (G68.2, G53.1, G69): the frame's points, lines and arcs
// against transforms computed by hand, the circle an arc of a tilted plane is in space,
// the round trip back to work coordinates, the refusals with their place, and G53.1
// through the five-axis kinematics of the example trunnion and head machines.
#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <string>
#include <vector>

#include "common/config/machine_config.h"
#include "common/kinematics/kinematics.h"
#include "common/rs274/canon.h"
#include "common/rs274/interpreter.h"
#include "services/part_program_server/program_server.h"
#include "tests/unit/temp_dir.h"

namespace cnc::rs274 {
namespace {

struct Move {
  std::string kind;  // G0 G1 NURBS
  Pose end{};
  std::vector<NurbsPoint> points;
  std::vector<double> knots;
  int line = 0;
};

class Recorder : public Canon {
 public:
  std::vector<Move> moves;
  void straight_traverse(const SourceRef& r, const Pose& p) override { moves.push_back({"G0", p, {}, {}, r.line}); }
  void straight_feed(const SourceRef& r, const Pose& p) override { moves.push_back({"G1", p, {}, {}, r.line}); }
  void arc_feed(const SourceRef& r, double, double, double, double, int, double, const Pose& p) override {
    moves.push_back({"ARC", p, {}, {}, r.line});
  }
  void nurbs_feed(const SourceRef& r, int, const std::vector<NurbsPoint>& pts, const std::vector<double>& knots,
                  const Pose& p) override {
    moves.push_back({"NURBS", p, pts, knots, r.line});
  }
  void dwell(const SourceRef&, double) override {}
};

struct Outcome {
  Recorder canon;
  std::vector<std::array<double, 3>> p5420;  // #5420-#5422 after each line marked (snap)
};

void run(Outcome& out, const std::string& text, const MachineSetup& setup = MachineSetup{}) {
  test::TempDir dir;
  const std::string path = dir.write("main.ngc", text);
  Interpreter in(setup, out.canon);
  in.open(path);
  while (in.execute_next())
    if (in.current_text().find("(snap)") != std::string::npos)
      out.p5420.push_back({in.parameters().get(5420), in.parameters().get(5421), in.parameters().get(5422)});
}

Error refusal(const std::string& text, const MachineSetup& setup = MachineSetup{}) {
  Outcome r;
  try {
    run(r, text, setup);
  } catch (const Error& e) {
    return e;
  }
  ADD_FAILURE() << "accepted: " << text;
  return Error(0, "accepted");
}

constexpr double kTol = 1e-9;
const double kS30 = 0.5, kC30 = std::sqrt(3.0) / 2, kR2 = std::sqrt(0.5);

void expect_xyz(const Pose& p, double x, double y, double z, const std::string& what) {
  EXPECT_NEAR(p[0], x, kTol) << what;
  EXPECT_NEAR(p[1], y, kTol) << what;
  EXPECT_NEAR(p[2], z, kTol) << what;
}

TEST(Rs274Twp, APointOfAPlaneTilted30DegreesAboutX) {
  // Euler Z-X-Z with I0 J30 K0: the frame is Rx(30°) about its origin (10, 20, 5):
  // frame (10, 10, 0) -> (10 + 10, 20 + 10 cos30, 5 + 10 sin30).
  Outcome r;
  run(r, "G21 G90\nG68.2 X10 Y20 Z5 I0 J30 K0\nG1 X10 Y10 Z0 F100 (snap)\nM2\n");
  ASSERT_EQ(r.canon.moves.size(), 1u);
  expect_xyz(r.canon.moves[0].end, 20, 20 + 10 * kC30, 5 + 10 * kS30, "G1");
  // The program reads its own frame's coordinates back.
  ASSERT_EQ(r.p5420.size(), 1u);
  EXPECT_NEAR(r.p5420[0][0], 10, kTol);
  EXPECT_NEAR(r.p5420[0][1], 10, kTol);
  EXPECT_NEAR(r.p5420[0][2], 0, kTol);
}

TEST(Rs274Twp, ALineOfAPlaneTilted45DegreesEulerZxz) {
  // I90 J45 K0: Rz(90°)·Rx(45°). Frame Y is (−cos45, 0, sin45)... by hand:
  // Rx(45)(0, 10, 0) = (0, 7.071, 7.071); Rz(90)(x, y, z) = (−y, x, z) = (−7.071, 0, 7.071).
  // Frame X is Rz(90)(1, 0, 0) = (0, 1, 0). A rapid to the frame's origin, then G91 lines.
  Outcome r;
  run(r,
      "G21 G90 G0 X0 Y0 Z50\n"
      "G68.2 X100 Y0 Z0 I90 J45 K0\n"
      "G0 X0 Y0 Z0\n"
      "G91 G1 Y10 F500\n"
      "G1 X5\n"
      "G1 Z-2\n"
      "G90 G1 X0 Y0 Z0\n"
      "M2\n");
  ASSERT_EQ(r.canon.moves.size(), 6u);
  expect_xyz(r.canon.moves[1].end, 100, 0, 0, "origin");
  expect_xyz(r.canon.moves[2].end, 100 - 10 * kR2, 0, 10 * kR2, "frame Y10");
  expect_xyz(r.canon.moves[3].end, 100 - 10 * kR2, 5, 10 * kR2, "frame X5");
  // Frame Z is Rz(90)Rx(45)(0, 0, 1) = Rz(90)(0, −sin45, cos45) = (sin45, 0, cos45).
  expect_xyz(r.canon.moves[4].end, 100 - 10 * kR2 + 2 * -kR2, 5, 10 * kR2 - 2 * kR2, "frame Z-2");
  expect_xyz(r.canon.moves[5].end, 100, 0, 0, "back");
}

TEST(Rs274Twp, RollPitchYawP1TurnsAboutXYZInQsOrder) {
  // P1 Q123 I30 J0 K90: Rx(30)·Ry(0)·Rz(90). Frame X = Rx(30)(0, 1, 0) = (0, cos30, sin30).
  // Q321 with the same words: Rz(90)·Ry(0)·Rx(30): frame X = Rz(90)(1, 0, 0) = (0, 1, 0).
  Outcome r;
  run(r, "G68.2 P1 I30 J0 K90\nG0 X10\nG69\nG68.2 P1 Q321 I30 J0 K90\nG0 X10 Y0 Z0\nM2\n");
  ASSERT_EQ(r.canon.moves.size(), 2u);
  expect_xyz(r.canon.moves[0].end, 0, 10 * kC30, 10 * kS30, "Q123");
  expect_xyz(r.canon.moves[1].end, 0, 10, 0, "Q321");
}

Pose pose_of(const NurbsPoint& p) { return Pose{p.x, p.y, p.z, 0, 0, 0, 0, 0, 0}; }

// The rational quadratic pieces of the NURBS (interior knots doubled: each span is a
// Bezier of three control points) at `per_span` parameters each, in program units.
std::vector<std::array<double, 3>> sample(const Move& m, int per_span) {
  std::vector<std::array<double, 3>> out;
  const size_t spans = (m.points.size() - 1) / 2;
  for (size_t k = 0; k < spans; ++k) {
    const NurbsPoint* p = &m.points[2 * k];
    for (int i = 0; i <= per_span; ++i) {
      const double t = static_cast<double>(i) / per_span;
      const double b[3] = {(1 - t) * (1 - t) * p[0].w, 2 * t * (1 - t) * p[1].w, t * t * p[2].w};
      const double sum = b[0] + b[1] + b[2];
      out.push_back({(b[0] * p[0].x + b[1] * p[1].x + b[2] * p[2].x) / sum,
                     (b[0] * p[0].y + b[1] * p[1].y + b[2] * p[2].y) / sum,
                     (b[0] * p[0].z + b[1] * p[1].z + b[2] * p[2].z) / sum});
    }
  }
  return out;
}

TEST(Rs274Twp, AnArcOfATiltedPlaneIsTheExactCircleInSpace) {
  // A full G17 circle of radius 10 about the frame's origin in a plane tilted 30° about
  // X: in work coordinates the circle about (0, 0, 0) in the plane with normal
  // (0, −sin30, cos30). Then a 90° G2 from frame (10, 0) to (0, −10).
  Outcome r;
  run(r,
      "G21 G90 G17\n"
      "G68.2 X0 Y0 Z0 I0 J30 K0\n"
      "G0 X10 Y0 Z0\n"
      "G3 X10 Y0 I-10 J0 F300\n"
      "G2 X0 Y-10 I-10 J0\n"
      "M2\n");
  ASSERT_EQ(r.canon.moves.size(), 3u);
  const Move& full = r.canon.moves[1];
  ASSERT_EQ(full.kind, "NURBS");
  EXPECT_EQ(full.points.size(), 9u);  // four quarters
  EXPECT_EQ(full.knots, (std::vector<double>{0, 0, 0, 1, 1, 2, 2, 3, 3, 4, 4, 4}));
  const std::array<double, 3> n{0, -kS30, kC30};
  double worst_r = 0, worst_plane = 0;
  for (const Move* m : {&r.canon.moves[1], &r.canon.moves[2]})
    for (const auto& q : sample(*m, 50)) {
      worst_r = std::max(worst_r, std::fabs(std::hypot(q[0], q[1], q[2]) - 10));
      worst_plane = std::max(worst_plane, std::fabs(q[0] * n[0] + q[1] * n[1] + q[2] * n[2]));
    }
  EXPECT_LT(worst_r, 1e-12);
  EXPECT_LT(worst_plane, 1e-12);
  // Counterclockwise about the frame's Z: a quarter on from (10, 0) is frame (0, 10).
  expect_xyz(pose_of(full.points[2]), 0, 10 * kC30, 10 * kS30, "a quarter of G3");
  const Move& quarter = r.canon.moves[2];
  EXPECT_EQ(quarter.points.size(), 3u);
  expect_xyz(quarter.end, 0, -10 * kC30, -10 * kS30, "G2's end");
  // Its middle control point where the tangents meet: frame (10, −10), weight cos45.
  expect_xyz(pose_of(quarter.points[1]), 10, -10 * kC30, -10 * kS30, "G2's corner point");
  EXPECT_NEAR(quarter.points[1].w, kR2, 1e-15);
}

TEST(Rs274Twp, AFullCircleStaysFullThroughTheFramesRounding) {
  // In a frame turned 90/90 the start's round trip through work coordinates is off by
  // ~1e-15: the circle back to its start is still the full turn (four quarters).
  Outcome r;
  run(r, "G68.2 X20 Y0 Z0 I90 J90 K0\nG0 X8 Y0 Z0\nG3 X8 Y0 I-8 J0 F100\nG2 X8 Y0 I-8 J0\nM2\n");
  ASSERT_EQ(r.canon.moves.size(), 3u);
  EXPECT_EQ(r.canon.moves[1].points.size(), 9u);
  EXPECT_EQ(r.canon.moves[2].points.size(), 9u);
}

TEST(Rs274Twp, CannedCyclesDrillAlongTheFramesZ) {
  // The same cycles with and without a frame turned 30° about X at (5, 0, 2): every
  // move's end is the frame's image of the plain run's (G98 and G99, G81 G83 G82, L2).
  const std::string cycles = "G0 X0 Y0 Z10\nG99 G81 X10 Y5 Z-2 R1 F100\nG91 X3 L2\nG90 G98 G83 X0 Y0 Z-4 R2 Q1.5\n"
                             "G82 X-5 Z-1 R2 P0.5\nG80 G0 Z20\nM2\n";
  Outcome plain, tilted;
  run(plain, cycles);
  run(tilted, "G68.2 X5 Y0 Z2 I0 J30 K0\n" + cycles);
  ASSERT_GT(plain.canon.moves.size(), 15u);
  ASSERT_EQ(tilted.canon.moves.size(), plain.canon.moves.size());
  for (size_t i = 0; i < plain.canon.moves.size(); ++i) {
    const Pose& f = plain.canon.moves[i].end;
    EXPECT_EQ(tilted.canon.moves[i].kind, plain.canon.moves[i].kind) << i;
    expect_xyz(tilted.canon.moves[i].end, 5 + f[0], f[1] * kC30 - f[2] * kS30, 2 + f[1] * kS30 + f[2] * kC30,
               "move " + std::to_string(i));
  }
}

TEST(Rs274Twp, G18ArcsAndRFormatLieInTheFramesPlanes) {
  // G18 in a frame turned 90° about Z (I90 J0 K0: frame X = work Y, frame Y = −work X):
  // the frame's XZ plane is the work's YZ plane at work X = −(frame Y) = 0.
  Outcome r;
  run(r, "G21 G18\nG68.2 I90 J0 K0\nG0 X0 Y0 Z0\nG2 X10 Z10 R10 F200\nM2\n");
  ASSERT_EQ(r.canon.moves.size(), 2u);
  const Move& arc = r.canon.moves[1];
  ASSERT_EQ(arc.kind, "NURBS");
  expect_xyz(arc.end, 0, 10, 10, "end");
  // G2 R10 from (0, 0) to (X10, Z10) in the ZX plane: clockwise about +Y (−Z to +X
  // from the centre), so its centre is frame (X0, Z10): every point 10 from work (0, 0, 10).
  for (const auto& q : sample(arc, 40)) {
    EXPECT_NEAR(q[0], 0, 1e-12);
    EXPECT_NEAR(std::hypot(q[1], q[2] - 10), 10, 1e-12);
  }
}

TEST(Rs274Twp, G69GoesBackToWorkCoordinatesWhereTheToolIs) {
  // A round trip: in the frame to frame (5, 5, 5), G69, then G91 X1 from where it stands
  // (work coordinates), then G90 in work coordinates; the G54 offset under it all.
  Outcome r;
  run(r,
      "G21 G10 L2 P1 X100 Y0 Z0\nG54 G0 X0 Y0 Z0\n"
      "G68.2 X10 Y0 Z0 I0 J45 K0\n"
      "G0 X5 Y5 Z5 (snap)\n"
      "G69 (snap)\n"
      "G91 G0 X1\nG90 G0 X0 Y0 Z0\nM2\n");
  ASSERT_EQ(r.canon.moves.size(), 4u);
  // Rx(45)(5, 5, 5) = (5, 0, 7.071) about (10, 0, 0).
  expect_xyz(r.canon.moves[1].end, 15, 0, 10 * kR2, "in the frame");
  expect_xyz(r.canon.moves[2].end, 16, 0, 10 * kR2, "G69 G91 X1");
  expect_xyz(r.canon.moves[3].end, 0, 0, 0, "G90 after G69");
  ASSERT_EQ(r.p5420.size(), 2u);
  EXPECT_NEAR(r.p5420[0][1], 5, kTol);  // the frame's
  EXPECT_NEAR(r.p5420[1][0], 15, kTol);  // the work's again
  EXPECT_NEAR(r.p5420[1][2], 10 * kR2, kTol);
}

TEST(Rs274Twp, InchesScaleTheOriginAndTheWords) {
  Outcome r;
  run(r, "G20\nG68.2 X1 Y0 Z0 I0 J30 K0\nG0 X0 Y1 Z0\nM2\n");
  ASSERT_EQ(r.canon.moves.size(), 1u);
  expect_xyz(r.canon.moves[0].end, 1, kC30, kS30, "inches in, inches out");
}

void expect_refused(const std::string& text, int line, int column, const std::string& part,
                    const MachineSetup& setup = MachineSetup{}) {
  const Error e = refusal(text, setup);
  EXPECT_EQ(e.where().line, line) << text;
  EXPECT_EQ(e.column(), column) << text;
  EXPECT_NE(e.detail().find(part), std::string::npos) << e.detail();
}

TEST(Rs274Twp, RefusalsNameTheirPlace) {
  const std::string on = "G68.2 X0 Y0 Z0 I0 J30 K0\n";
  expect_refused(on + "G92 X0\n", 2, 1, "G92 in a tilted work plane (G68.2): G69 first");
  expect_refused(on + "G52 X1\n", 2, 1, "G52");
  expect_refused(on + "G0 X1\nG55\n", 3, 1, "G55 in a tilted work plane");
  expect_refused(on + "G28\n", 2, 1, "G28");
  expect_refused(on + "G10 L2 P1 X3\n", 2, 1, "G10 L2 of the active coordinate system");
  expect_refused(on + "G41 D0\n", 2, 1, "cutter radius compensation G41");
  expect_refused(on + "G5.2 X0 Y0 P1 L3\n", 2, 1, "G5.2 in a tilted work plane (G68.2) is not supported");
  expect_refused(on + "G0 @10 ^30\n", 2, 4, "polar coordinates");
  expect_refused(on + "G68.2 I0 J0 K0\n", 2, 1, "G69 first");
  expect_refused(on + "G1 X5 Z1 F100\nG2 X0 Y5 Z2 I-5 J0\n", 3, 1, "a helix in a tilted work plane");
  expect_refused("G68.2 P2 X0 Y0 Z0\n", 1, 7, "G68.2 P2 (three points) is not supported");
  expect_refused("G68.2 Q123 I0 J30 K0\n", 1, 7, "Euler order");
  expect_refused("G68.2 R5 I0 J30 K0\n", 1, 7, "R word with G68.2");
  expect_refused("G1 G68.2 X0 Y0 Z0 F10\n", 1, 4, "no motion or other code that uses axis words");
  expect_refused("G10 L2 P1 R30\nG68.2 I0 J30 K0\n", 2, 1, "rotated by G10 L2 R");
  expect_refused("G53.1\n", 1, 1, "G53.1 without a tilted work plane (G68.2 first)");
  expect_refused(on + "G53.1\n", 2, 1, "G53.1 needs a machine with five-axis kinematics");
  // G69 on the line lets the rest go on in work coordinates; M2 cancels the frame too.
  Outcome r;
  run(r, on + "G69 G55\nG68.2 I0 J30 K0\nM2\n");
  run(r, "G68.2 I0 J30 K0\nM2\n");
}

// The interpreter's set-up of a machine file, as the program server and the dry run make it.
MachineSetup machine(const std::string& file) {
  const config::MachineConfig cfg =
      config::load_machine_config(std::string(CNC_SOURCE_DIR) + "/tests/unit/kinematics_machines/" + file);
  return pps::program_setup(cfg).machine;
}

// The tool's direction at the machine position the program's G53.1 left: the rotary
// axes of its last G0 (A or B, then C) through the kinematics of the same file.
std::array<double, 3> tool_after(const std::string& file, const Pose& end) {
  const config::MachineConfig cfg =
      config::load_machine_config(std::string(CNC_SOURCE_DIR) + "/tests/unit/kinematics_machines/" + file);
  const auto kin = kinematics::make_kinematics(cfg);
  kinematics::Pose j{};
  static const std::string kLetters = "XYZABCUVW";
  for (size_t a = 0; a < cfg.axes.size(); ++a) j[a] = end[kLetters.find(cfg.axes[a].name)];
  const kinematics::ToolDirection d = kin->tool_direction(j);
  return {d.i, d.j, d.k};
}

TEST(Rs274Twp, G53_1PointsTheToolAlongTheFramesZOnTrunnionsAndHeads) {
  // The frame's Z in work coordinates, by hand: Rz(α)Rx(β)(0, 0, 1) = (sinα sinβ, −cosα sinβ, cosβ).
  for (const std::string file : {"xyzac-trt.yaml", "xyzbc-trt.yaml", "xyzac-head.yaml", "xyzbc-head-table.yaml"}) {
    for (const auto& [alpha, beta] : {std::pair{0.0, 30.0}, std::pair{90.0, 45.0}, std::pair{-60.0, 20.0}}) {
      Outcome r;
      char prog[160];
      std::snprintf(prog, sizeof prog, "G21\nG68.2 X0 Y0 Z0 I%g J%g K0\nG53.1\nM2\n", alpha, beta);
      run(r, prog, machine(file));
      ASSERT_EQ(r.canon.moves.size(), 1u) << file << " " << prog;
      EXPECT_EQ(r.canon.moves[0].kind, "G0");
      expect_xyz(r.canon.moves[0].end, 0, 0, 0, "the linear axes stay");
      const auto d = tool_after(file, r.canon.moves[0].end);
      const double a = alpha * M_PI / 180, b = beta * M_PI / 180;
      EXPECT_NEAR(d[0], std::sin(a) * std::sin(b), 1e-12) << file << " " << prog;
      EXPECT_NEAR(d[1], -std::cos(a) * std::sin(b), 1e-12) << file << " " << prog;
      EXPECT_NEAR(d[2], std::cos(b), 1e-12) << file << " " << prog;
    }
  }
}

TEST(Rs274Twp, G53_1PChoosesTheSolutionAndRefusesOneOutOfTravel) {
  // xyzac-trt: A travels −30..120. A frame tilted 40° takes A ±40: P1 the tilt >= 0
  // one, P2 the other, out of travel and refused naming joint A.
  const MachineSetup trt = machine("xyzac-trt.yaml");
  Outcome r;
  run(r, "G68.2 I0 J40 K0\nG53.1 P1\nM2\n", trt);
  ASSERT_EQ(r.canon.moves.size(), 1u);
  EXPECT_NEAR(r.canon.moves[0].end[3], 40, 1e-9);
  expect_refused("G68.2 I0 J40 K0\nG53.1 P2\n", 2, 1, "joint A would stand at -40.000 degrees, outside its travel [-30, 120]",
                 trt);
  // A tool length offset acts along the part's Z here: not with a tool G53.1 turned.
  expect_refused("G0 X0\nG43.1 Z10\nG68.2 I0 J40 K0\nG53.1\n", 4, 1, "G53.1 with a tool length offset in effect", trt);
  expect_refused("G0 X0\nG68.2 I0 J40 K0\nG53.1\nG43.1 Z10\n", 4, 1, "G43.1 with the tool turned by G53.1", trt);
  Outcome vertical;
  run(vertical, "G0 X0\nG43.1 Z10\nG68.2 I30 J0 K0\nG53.1\nG69\nG43.1 Z5\nM2\n", trt);  // a frame turned about Z only
  // P0 takes what kinematics.solution (nearest) picks: the one in travel here.
  Outcome r0;
  run(r0, "G68.2 I0 J40 K0\nG53.1\nM2\n", trt);
  ASSERT_EQ(r0.canon.moves.size(), 1u);
  EXPECT_NEAR(r0.canon.moves[0].end[3], 40, 1e-9);
}

}  // namespace
}  // namespace cnc::rs274
