#pragma once
// Cutter radius compensation (G41/G42/G41.1/G42.1, G40) as LinuxCNC 2.9 does it, as
// a filter between the interpreter and the canonical calls it makes: the interpreter
// always calls this Canon; while compensation is off every call passes straight on.
// While it is on, a move is held until the next move shows the corner it makes with
// it (LinuxCNC's queue), then the compensated move is emitted, with the calls that
// came between the two moves kept in their order. LinuxCNC's rules hold: the entry
// move (the first move after G41/G42) and the exit move (the first after G40) are
// straight lines from/to the uncompensated point; a concave corner that the tool
// cannot reach without gouging is refused; an arc whose radius is not larger than
// the tool's on its inside is refused. Refusals throw Error(0, detail): the
// interpreter names the place (the line of the move that revealed the fault).
#include <memory>
#include <vector>

#include "common/rs274/canon_forward.h"

namespace cnc::rs274 {

class CutterComp : public CanonForward {
 public:
  explicit CutterComp(Canon& out);
  ~CutterComp() override;

  // G41 (side = +1, left of the path) / G42 (side = -1), radius in program units
  // (> 0; 0 makes compensation a no-op as in LinuxCNC), in the XY or XZ plane.
  // `programmed` is where the tool stands (program coordinates).
  void start(int side, double radius, Plane plane, const Pose& programmed);
  // G40: the next move is the exit move; compensation is off after it.
  void stop();
  bool active() const;
  // Where the tool stands in the compensation plane (program units; u, v: X, Y in G17,
  // Z, X in G18) when that is not the programmed point. stopped = false: while
  // compensating after the entry move (LinuxCNC's current point, which #5420-#5422
  // show). stopped = true: after G40 until the next move (LinuxCNC's current point is
  // the programmed one again, but the machine stays at the compensated point, and
  // LinuxCNC re-reads that after a tool change). False otherwise.
  bool tool_point(bool stopped, Plane& plane, double& u, double& v) const;
  // Emits everything held (end of program, and before anything that must not be
  // reordered: a tool change, a stop).
  void flush();

  // The calls LinuxCNC queues behind a waiting move (the rest pass straight on).
  void set_feed_rate(const SourceRef&, double) override;
  void set_feed_mode(const SourceRef&, FeedMode) override;
  void dwell(const SourceRef&, double seconds) override;
  void set_spindle_speed(const SourceRef&, double) override;
  void set_spindle_mode(const SourceRef&, double) override;
  void orient_spindle(const SourceRef&, double, int) override;
  void start_spindle_clockwise(const SourceRef&) override;
  void start_spindle_counterclockwise(const SourceRef&) override;
  void stop_spindle_turning(const SourceRef&) override;
  void mist_on(const SourceRef&) override;
  void mist_off(const SourceRef&) override;
  void flood_on(const SourceRef&) override;
  void flood_off(const SourceRef&) override;
  void comment(const SourceRef&, const std::string&) override;
  void set_process(const SourceRef&, const ProcessSettings&) override;
  // Calls that change the filter's own state.
  void use_length_units(const SourceRef&, Units) override;
  void on_reset(const SourceRef&) override;
  // Calls that end what is held first.
  void start_change(const SourceRef&) override;
  void change_tool(const SourceRef&, int) override;
  void change_tool_number(const SourceRef&, int) override;
  void program_stop(const SourceRef&) override;
  void optional_program_stop(const SourceRef&) override;
  void pallet_shuttle(const SourceRef&) override;
  void program_end(const SourceRef&) override;
  void finish(const SourceRef&) override;
  // Motion.
  void straight_traverse(const SourceRef&, const Pose& end) override;
  void straight_feed(const SourceRef&, const Pose& end) override;
  void arc_feed(const SourceRef&, double first_end, double second_end, double first_axis, double second_axis,
                int rotation, double axis_end, const Pose& end) override;
  void nurbs_feed(const SourceRef&, int order, const std::vector<NurbsPoint>& points, const std::vector<double>& knots,
                  const Pose& end) override;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace cnc::rs274
