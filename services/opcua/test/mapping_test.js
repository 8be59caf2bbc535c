"use strict";
// docs/opcua.md's mapping tables, row by row: the HMI's status -> the spec's values.
//   node --test services/opcua/test/mapping_test.js   (ctest: opcua_mapping)
const test = require("node:test");
const assert = require("node:assert/strict");
const m = require("../mapping");

const st = (interp, program, extra = {}) => ({ interp, program, ...extra });

test("ChannelState: running and starved are Active, held and fault Interrupted, the rest Reset", () => {
  const want = { idle: 2, running: 0, starved: 0, held: 1, fault: 1, done: 2 };
  for (const [state, cs] of Object.entries(want)) assert.equal(m.channelState(st({ state })), cs, state);
  assert.equal(m.channelState({}), m.ChannelState.Reset);
});

test("ChannelMode: home is Reference, jogs JogManual or JogIncrement, MDI lines MdaMdi, programs Automatic", () => {
  assert.equal(m.channelMode(st({ mode: "home" })), m.ChannelMode.Reference);
  assert.equal(m.channelMode(st({ mode: "jog", mode_text: "jog X+ continuous" })), m.ChannelMode.JogManual);
  assert.equal(m.channelMode(st({ mode: "jog", mode_text: "jog X +10 mm" })), m.ChannelMode.JogIncrement);
  assert.equal(m.channelMode(st({ mode: "program" }, { path: "/tmp/mdi-12-3.ngc" })), m.ChannelMode.MdaMdi);
  assert.equal(m.channelMode(st({ mode: "program" }, { path: "/p/part.ngc" })), m.ChannelMode.Automatic);
  assert.equal(m.operationMode(st({ mode: "program" }, { path: "/p/part.ngc" })), m.MachineOperationMode.Automatic);
  assert.equal(m.operationMode(st({ mode: "jog", mode_text: "jog X+ continuous" })), m.MachineOperationMode.Manual);
});

test("the program server's states are ProductionStateMachineType's", () => {
  const want = { idle: "Initializing", loaded: "Initializing", running: "Running", held: "Interrupted",
                 done: "Ended", refused: "Aborted", stopped: "Aborted", fault: "Aborted" };
  for (const [state, s] of Object.entries(want)) assert.equal(m.programState(st({}, { state })), s, state);
});

test("overrides are percent, the stack light one colour", () => {
  assert.equal(m.percent(1), 100);
  assert.equal(m.percent(0.333333), 33.33);
  assert.equal(m.percent(undefined), 0);
  assert.deepEqual(m.stackLight(st({ state: "running" })), { red: false, yellow: false, green: true });
  assert.deepEqual(m.stackLight(st({ state: "held" })), { red: false, yellow: true, green: false });
  assert.deepEqual(m.stackLight(st({ state: "idle" })), { red: false, yellow: false, green: false });
  assert.deepEqual(m.stackLight(st({ state: "running" }, {}, { axes: [{ drive: "fault" }] })),
                   { red: true, yellow: false, green: false });
  assert.deepEqual(m.stackLight(st({ state: "idle" }, {}, { machine: { estop: "tripped" } })),
                   { red: true, yellow: false, green: false });
});

test("the spindle turns while its actual speed is 1 rpm or more", () => {
  assert.equal(m.spindle({}), null);
  const sp = (state, actual, commanded) => ({ machine: { spindle: { state, actual_rpm: actual, commanded_rpm: commanded } } });
  assert.deepEqual(m.spindle(sp("running", 5990, 6000)), { isRotating: true, actualRpm: 5990, commandedRpm: 6000 });
  assert.equal(m.spindle(sp("stopped", 350, 0)).isRotating, true);  // running down after M5
  assert.equal(m.spindle(sp("stopped", 0.4, 0)).isRotating, false);
  assert.equal(m.spindle(sp("running", -6000, -6000)).isRotating, true);  // M4
});

test("alarm severities", () => {
  assert.equal(m.alarmSeverity("info"), 200);
  assert.equal(m.alarmSeverity("warning"), 500);
  assert.equal(m.alarmSeverity("fault"), 800);
});

test("runs: a program run to its end is a part; a stopped one is aborted; MDI lines are no runs", () => {
  const r = new m.RunTracker(7);
  const p = (state, token, path = "/p/part.ngc") => st({}, { state, token, path });
  assert.deepEqual(r.update(p("loaded", 1)), { started: false, ended: false });
  assert.equal(r.run, null);
  assert.deepEqual(r.update(p("running", 1)), { started: true, ended: false });
  assert.equal(r.run.id, "part.ngc#1.1");
  r.update(p("held", 1));
  assert.equal(r.run.state, "Interrupted");
  r.update(p("running", 1));
  assert.deepEqual(r.update(p("done", 1)), { started: false, ended: true });
  assert.deepEqual([r.run.state, r.run.completed, r.parts], ["Ended", 1, 8]);
  assert.deepEqual(r.update(p("done", 1)), { started: false, ended: false });  // the same end once
  // An MDI line between two runs changes nothing.
  assert.deepEqual(r.update(p("running", 2, "/tmp/mdi-1-2.ngc")), { started: false, ended: false });
  assert.equal(r.run.token, 1);
  // The same program started again: a new run; stopped: aborted, no part.
  assert.deepEqual(r.update(p("running", 1)), { started: true, ended: false });
  assert.equal(r.run.id, "part.ngc#1.2");
  r.update(p("stopped", 1));
  assert.deepEqual([r.run.state, r.parts], ["Aborted", 8]);
  // A run whose program is replaced before its end is aborted.
  r.update(p("running", 3));
  r.update(p("loaded", 4));
  assert.equal(r.run.state, "Aborted");
});
