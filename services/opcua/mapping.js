"use strict";
// The cell's state, as the HMI's `status` message has it (docs/hmi-api.md), mapped to
// the values of OPC 40501-1 Machine Tools. Pure: no OPC UA, no sockets, no clock, so
// that test/mapping_test.js checks every row of docs/opcua.md's tables.

// ChannelState (MachineTool's enumeration).
const ChannelState = { Active: 0, Interrupted: 1, Reset: 2 };
// ChannelMode.
const ChannelMode = { Automatic: 0, MdaMdi: 1, JogManual: 2, JogIncrement: 3, TeachingHandle: 4, Remote: 5, Reference: 6, Other: 7 };
// MachineOperationMode.
const MachineOperationMode = { Manual: 0, Automatic: 1, Setup: 2, AutoWithManualIntervention: 3, Service: 4, Other: 5 };
// IA's SignalColor.
const SignalColor = { Off: 0, Red: 1, Green: 2, Blue: 3, Yellow: 4 };

// An MDI line or a touch-off runs as a one-line program of the server's own (mdi-*.ngc).
function isOperatorLine(path) {
  const name = String(path || "").split("/").pop();
  return name.startsWith("mdi-");
}

function programName(path) {
  return String(path || "").split("/").pop();
}

// The interpolator's state: idle, running, held, done, starved, fault.
function channelState(status) {
  const s = status.interp ? status.interp.state : "idle";
  if (s === "running" || s === "starved") return ChannelState.Active;
  if (s === "held" || s === "fault") return ChannelState.Interrupted;
  return ChannelState.Reset;
}

function channelMode(status) {
  const i = status.interp || {};
  if (i.mode === "home") return ChannelMode.Reference;
  if (i.mode === "jog") return /continuous/.test(i.mode_text || "") ? ChannelMode.JogManual : ChannelMode.JogIncrement;
  const p = status.program || {};
  return isOperatorLine(p.path) ? ChannelMode.MdaMdi : ChannelMode.Automatic;
}

function operationMode(status) {
  return channelMode(status) === ChannelMode.Automatic ? MachineOperationMode.Automatic : MachineOperationMode.Manual;
}

// ProductionStateMachineType's states for the program server's state: idle, loaded,
// running, held, done, refused, stopped, fault.
function programState(status) {
  const p = status.program ? status.program.state : "idle";
  switch (p) {
    case "running": return "Running";
    case "held": return "Interrupted";
    case "done": return "Ended";
    case "refused":
    case "stopped":
    case "fault": return "Aborted";
    default: return "Initializing";  // idle, loaded
  }
}

// The percent a 0..1.5 scale is.
function percent(scale) {
  return Number.isFinite(scale) ? Math.round(scale * 1e4) / 100 : 0;
}

// The stack light the cell's state would light: red for a fault (a drive's, the
// interpolator's) or a tripped E-stop, yellow while held, green while a program or an
// operator move runs; one colour at a time.
function stackLight(status) {
  const i = status.interp || {};
  const m = status.machine || {};
  const driveFault = (status.axes || []).some((a) => a.drive === "fault");
  const red = i.state === "fault" || driveFault || m.estop === "tripped" || (m.spindle && m.spindle.fault);
  const yellow = !red && i.state === "held";
  const green = !red && !yellow && (i.state === "running" || i.state === "starved");
  return { red: Boolean(red), yellow, green };
}

function spindle(status) {
  const s = status.machine && status.machine.spindle;
  if (!s) return null;
  return {
    // Turning, whatever was commanded: a spindle running down after M5 still turns.
    isRotating: Math.abs(Number(s.actual_rpm) || 0) >= 1,
    actualRpm: Number(s.actual_rpm) || 0,
    commandedRpm: Number(s.commanded_rpm) || 0,
  };
}

// OPC UA's severity (1 .. 1000) of the cell's alarm severities.
function alarmSeverity(severity) {
  return severity === "fault" ? 800 : severity === "warning" ? 500 : 200;
}

// The runs of programs, followed from one status to the next: a run begins when the
// program server says `running` under a token it had not run yet (or again after its
// end), and ends `done` (counted: a part) or aborted (stopped, fault). Operator lines
// (MDI, touch-off) are no production runs.
class RunTracker {
  constructor(partsBefore = 0) {
    this.parts = partsBefore;   // programs run to their end, over the server's life
    this.run = null;            // {id, name, token, state, completed}
    this.runs = 0;
    this.lastState = null;
    this.lastToken = null;
  }

  // Returns what changed: {started, ended} (both false when nothing did).
  update(status) {
    const p = status.program || {};
    const changed = { started: false, ended: false };
    if (!p.state || isOperatorLine(p.path)) return changed;
    const state = programState(status);
    const token = p.token;
    const newRun = state === "Running" && (this.run === null || this.run.token !== token ||
                                           this.run.state === "Ended" || this.run.state === "Aborted");
    if (newRun) {
      this.runs += 1;
      this.run = { id: `${programName(p.path)}#${token}.${this.runs}`, name: programName(p.path), token,
                   state: "Running", completed: 0 };
      changed.started = true;
    } else if (this.run !== null && this.run.token === token && this.run.state !== "Ended" &&
               this.run.state !== "Aborted" && state !== "Initializing") {
      if (state !== this.run.state) {
        this.run.state = state;
        if (state === "Ended") {
          this.run.completed = 1;
          this.parts += 1;
          changed.ended = true;
        }
      }
    } else if (this.run !== null && this.run.token !== token && this.run.state !== "Ended" &&
               this.run.state !== "Aborted") {
      // Another program was loaded before this one's end came: it was aborted.
      this.run.state = "Aborted";
    }
    return changed;
  }
}

module.exports = {
  ChannelState, ChannelMode, MachineOperationMode, SignalColor,
  channelState, channelMode, operationMode, programState, programName, isOperatorLine,
  percent, stackLight, spindle, alarmSeverity, RunTracker,
};
