// cnc-ctl: operator commands to a running cell, and `--do run`, which loads a
// program, starts it, waits for its end and for the axes to settle.
//
//   cnc-ctl --machine M --do run --program P [--timeout S]
//   cnc-ctl --machine M --do load --program P | start | hold | resume | stop | override --value 0.8
//   cnc-ctl --machine M --do rapid-override --value 0.25    G0 at a quarter of its speed (0 .. 1)
//   cnc-ctl --machine M --do spindle-override --value 0.8   the spindle at 80 % of S (spindle.min_override ..
//                                                  max_override, 0.5 .. 1.0 by default; M51 P0 disables it)
//   cnc-ctl --machine M --do enable [--timeout S] | disable | fault-reset    (drive bridge, DRIVE_CMD)
//   cnc-ctl --machine M --do reset [--timeout S]   after a fault: enable the drives (DRIVE_CMD), then
//                                                  RESET (the interpolator takes their position)
//   cnc-ctl --machine M --do home [--axis X]       home one axis, or all in the configured order
//   cnc-ctl --machine M --do jog --axis X --value D [--feed F]          incremental jog by D mm
//   cnc-ctl --machine M --do jog --axis X --value +1|-1 --hold S [--feed F]
//                                                  continuous jog, held for S s (a keepalive every
//                                                  50 ms; SIGINT/SIGTERM releases it), then STOP
//   cnc-ctl --machine M --do touch-off --axis X --value V   G10 L20 P0 (--tool: G10 L10, the length of the tool in the spindle)
//   cnc-ctl --machine M --do mdi --line "G0 X10"   one line through the program server's interpreter
//   cnc-ctl --machine M --do coolant --value flood|mist|off        M8, M7, M9 by MDI
//   cnc-ctl --machine M --do output --point NAME --value on|off|V  a digital output (M64/M65 P n) or an
//                                                  analog one (M68 E n Q V) of the machine file's io:, by MDI
//   cnc-ctl --machine M --do status [--timeout S]  the cell's services (host, pid, version, state)
//   cnc-ctl --machine M --do run|load --program P --from N [--confirm]
//                                                  run from line N: the approach is printed; run waits
//                                                  for a CONFIRM (--confirm: its own, or --do confirm)
//   cnc-ctl --machine M --do confirm               accept the approach of a program loaded from a line
//   cnc-ctl --machine M --do single-block|optional-stop|block-delete --value on|off
//                                                  the switches (at the next block boundary; block
//                                                  delete at the next load). With single block on,
//                                                  start and resume run one line and wait until the
//                                                  path holds again (or the program ends)
//
// A command the cell refuses in its state (LOAD or START while a program runs, ...)
// ends cnc-ctl at once with the reason from PROGRAM_STATE and exit 3.
// Exit codes: 0 done; 1 the command could not be sent; 2 bad flags or config;
// 3 program or command refused; 4 timeout; 5 fault; 6 run: the program was stopped (STOP).
#include "common/service/service.h"
#include "tools/ctl/ctl.h"

int main(int argc, char** argv) {
  cnc::service::Spec spec{"cnc-ctl",
                          "operator commands to a running cell",
                          {{"do", "CMD",
                            "run (default), load, start, hold, resume, stop, override, rapid-override, spindle-override, enable, disable, "
                            "fault-reset, "
                            "reset, home, jog, touch-off, mdi, coolant, output, status, single-block, optional-stop, block-delete, confirm"},
                           {"program", "FILE", "the part program of run and load"},
                           {"value", "X",
                            "override factor, jog distance or direction (+1|-1), touch-off value; on|off for the switches and "
                            "outputs; flood|mist|off for coolant"},
                           {"timeout", "S", "how long run, enable, reset and status wait (default 600)", true},
                           {"axis", "NAME", "the axis of home, jog and touch-off"},
                           {"feed", "F", "jog feed, mm/min", true},
                           {"hold", "S", "continuous jog held for S s, then STOP", true},
                           {"line", "TEXT", "the line of mdi (e.g. \"G0 X10\")"},
                           {"point", "NAME", "the I/O point of output (io.points[].name)"},
                           {"from", "N", "run or load from line N (an approach first, confirmed before START)", true}},
                          {{"tool", "", "touch-off of the tool (refused: not available yet)"},
                           {"confirm", "", "run --from: confirm the approach itself"}}};
  return cnc::service::run(spec, argc, argv, [](const cnc::config::MachineConfig& cfg, const cnc::service::Args& args) {
    return cnc::ctl::Ctl(cfg, args).run_verb();
  });
}
