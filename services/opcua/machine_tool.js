"use strict";
// The cell as one instance of OPC 40501-1's MachineToolType under Machinery's Machines
// folder, built from the companion specification's types (none invented), and kept up
// to date from the HMI's messages (hello, status, alarm). Every node here is read only:
// this version has no methods and nothing an OPC UA client may write (docs/opcua.md).
const { EventEmitter } = require("node:events");
const {
  BrowseDirection, DataType, StatusCodes, NodeId, promoteToStateMachine, standardUnits, LocalizedText,
} = require("node-opcua");
const map = require("./mapping");

const NS = {
  MT: "http://opcfoundation.org/UA/MachineTool/",
  MACHINERY: "http://opcfoundation.org/UA/Machinery/",
  IA: "http://opcfoundation.org/UA/IA/",
  DI: "http://opcfoundation.org/UA/DI/",
};
const kMachinesFolder = 1001;  // Machinery's Machines folder (ns Machinery, i=1001)
const kHasOrderedComponent = 49;

// A child of `node` by its browse name (any namespace): components, properties, add-ins.
function child(node, name) {
  for (const r of node.findReferencesEx("HierarchicalReferences", BrowseDirection.Forward)) {
    const c = node.addressSpace.findNode(r.nodeId);
    if (c && c.browseName.name === name) return c;
  }
  throw new Error(`${node.browseName.toString()} has no child ${name}`);
}

class MachineToolModel extends EventEmitter {
  constructor(addressSpace, settings, counters, log) {
    super();
    this.as = addressSpace;
    this.s = settings;
    this.counters = counters;
    this.log = log;
    this.values = new Map();  // node -> last value set (only changes are written)
    this.dynamic = [];        // the variables marked BadNoCommunication while the HMI is away
    this.eventsRaised = 0;
    this.lastAlarmUtime = null;  // the newest alarm raised (or seen at the first connect)
    this.connectedOnce = false;
    this.runs = new map.RunTracker(counters.parts);
    this.powerSince = null;
    this.build();
    // The hour meter: the time the cell's drive bridge runs, counted each second.
    this.meter = setInterval(() => this.tickPowerOn(), 1000);
    this.saver = setInterval(() => this.emit("counters"), 60000);
  }

  ns(uri) {
    const i = this.as.getNamespaceIndex(uri);
    if (i < 0) throw new Error(`the nodeset ${uri} is not loaded`);
    return i;
  }

  type(name, uri) {
    const t = this.as.findObjectType(name, this.ns(uri));
    if (!t) throw new Error(`no object type ${name} in ${uri}`);
    return t;
  }

  build() {
    const as = this.as;
    const s = this.s;
    const own = as.getOwnNamespace();
    this.own = own;
    const machines = as.findNode(new NodeId(NodeId.NodeIdType.NUMERIC, kMachinesFolder, this.ns(NS.MACHINERY)));
    const optionals = [
      "Identification.Model", "Identification.SoftwareRevision",
      "Monitoring.MachineTool.PowerOnDuration", "Monitoring.Stacklight",
      "Production.ActiveProgram.JobIdentifier", "Production.ProductionPlan",
      "Production.Statistics", "Production.Statistics.PartsProducedInLifetime",
      "Notification.Messages",
    ];
    if (s.identification.year_of_construction > 0) optionals.push("Identification.YearOfConstruction");
    const mt = this.type("MachineToolType", NS.MT).instantiate({
      browseName: { name: s.cell, namespaceIndex: own.index },
      organizedBy: machines,
      optionals,
    });
    this.machine = mt;

    // Identification: from the config (opcua.identification); the software's version from hello.
    const id = child(mt, "Identification");
    const idv = s.identification;
    this.set(child(id, "Manufacturer"), DataType.LocalizedText, new LocalizedText({ text: idv.manufacturer }));
    this.set(child(id, "Model"), DataType.LocalizedText, new LocalizedText({ text: idv.model }));
    this.set(child(id, "SerialNumber"), DataType.String, idv.serial_number);
    this.set(child(id, "ProductInstanceUri"), DataType.String, idv.product_instance_uri);
    if (idv.year_of_construction > 0) this.set(child(id, "YearOfConstruction"), DataType.UInt16, idv.year_of_construction);
    this.softwareRevision = child(id, "SoftwareRevision");
    this.set(this.softwareRevision, DataType.String, s.version);

    // Monitoring: the machine, the stack light, the channel and the spindle.
    const mon = child(mt, "Monitoring");
    const machineMon = child(mon, "MachineTool");
    this.operationMode = this.dyn(child(machineMon, "OperationMode"));
    this.powerOnDuration = child(machineMon, "PowerOnDuration");
    this.set(this.powerOnDuration, DataType.UInt32, Math.floor(this.counters.power_on_s / 3600));
    this.buildStacklight(child(mon, "Stacklight"));

    const channel = this.type("ChannelMonitoringType", NS.MT).instantiate({
      browseName: { name: "Channel1", namespaceIndex: own.index },
      componentOf: mon,
      optionals: ["RapidOverride", "ChannelModifiers", "ChannelModifiers.BlockSkip"],
    });
    this.set(child(channel, "Name"), DataType.String, "Channel 1");
    this.channelState = this.dyn(child(channel, "ChannelState"));
    this.channelMode = this.dyn(child(channel, "ChannelMode"));
    this.feedOverride = this.dyn(this.percentItem(child(channel, "FeedOverride"), 150));
    this.rapidOverride = this.dyn(this.percentItem(child(channel, "RapidOverride"), 100));
    const mods = child(channel, "ChannelModifiers");
    this.singleStep = this.dyn(child(mods, "SingleStep"));
    this.optionalStop = this.dyn(child(mods, "OptionalStop"));
    this.blockSkip = this.dyn(child(mods, "BlockSkip"));
    this.set(child(mods, "DryRun"), DataType.Boolean, false);  // the dry run is offline (cnc-plan), never the machine's

    if (s.spindle) {
      const sp = this.type("SpindleMonitoringType", NS.MT).instantiate({
        browseName: { name: "Spindle", namespaceIndex: own.index },
        componentOf: mon,
        optionals: ["Override"],
      });
      this.set(child(sp, "Name"), DataType.String, "Spindle");
      this.isRotating = this.dyn(child(sp, "IsRotating"));
      this.spindleOverride = this.dyn(this.percentItem(child(sp, "Override"), 150));
      // The speeds: the spec's SpindleMonitoringType has none; AnalogUnitType variables
      // of the cell's own namespace beside its components.
      const rpm = (name) => this.dyn(own.addAnalogDataItem({
        componentOf: sp,
        browseName: name,
        dataType: DataType.Double,
        engineeringUnits: standardUnits.revolutions_per_minute,
        engineeringUnitsRange: { low: 0, high: 100000 },
        accessLevel: "CurrentRead",
        userAccessLevel: "CurrentRead",
      }));
      this.actualSpeed = rpm("ActualSpeed");
      this.commandedSpeed = rpm("CommandedSpeed");
    }

    // Production: the active program, one job (the current or last run), the parts.
    const prod = child(mt, "Production");
    const active = child(prod, "ActiveProgram");
    this.activeName = this.dyn(child(active, "Name"));
    this.set(child(active, "NumberInList"), DataType.UInt16, 0);
    this.activeState = promoteToStateMachine(child(active, "State"));
    this.activeState.setState("Initializing");
    this.activeJob = this.dyn(child(active, "JobIdentifier"));
    this.set(this.activeName, DataType.String, "");
    this.set(this.activeJob, DataType.String, "");

    const plan = child(prod, "ProductionPlan");
    const job = this.type("ProductionJobType", NS.MT).instantiate({
      browseName: { name: "Job", namespaceIndex: own.index },
    });
    plan.addReference({ referenceType: NodeId.resolveNodeId(`i=${kHasOrderedComponent}`), nodeId: job.nodeId });
    this.job = job;
    this.jobIdentifier = this.dyn(child(job, "Identifier"));
    this.set(child(job, "NumberInList"), DataType.UInt16, 0);
    this.runsCompleted = this.dyn(child(job, "RunsCompleted"));
    this.runsPlanned = child(job, "RunsPlanned");
    this.jobState = promoteToStateMachine(child(job, "State"));
    this.jobState.setState("Initializing");
    const program = this.type("ProductionProgramType", NS.MT).instantiate({
      browseName: { name: "Program", namespaceIndex: own.index },
      optionals: ["State"],
    });
    child(job, "ProductionPrograms").addReference({
      referenceType: NodeId.resolveNodeId(`i=${kHasOrderedComponent}`), nodeId: program.nodeId,
    });
    this.jobProgramName = this.dyn(child(program, "Name"));
    this.set(child(program, "NumberInList"), DataType.UInt16, 0);
    this.jobProgramState = promoteToStateMachine(child(program, "State"));
    this.jobProgramState.setState("Initializing");
    this.set(this.jobIdentifier, DataType.String, "");
    this.set(this.jobProgramName, DataType.String, "");
    this.set(this.runsCompleted, DataType.UInt32, 0);
    this.set(this.runsPlanned, DataType.UInt32, 1);
    this.parts = child(child(prod, "Statistics"), "PartsProducedInLifetime");
    this.set(this.parts, DataType.UInt32, this.counters.parts);

    // Notification: the cell's ALARMs as events of Messages, which notifies the machine
    // and the Server object (subscribe to events on any of the three).
    const notification = child(mt, "Notification");
    this.messages = child(notification, "Messages");
    for (const n of [mt, notification, this.messages]) n.setEventNotifier(1);
    as.rootFolder.objects.server.addReference({ referenceType: "HasNotifier", nodeId: mt.nodeId });
    mt.addReference({ referenceType: "HasNotifier", nodeId: notification.nodeId });
    notification.addReference({ referenceType: "HasNotifier", nodeId: this.messages.nodeId });
    this.notificationEvent = this.type("NotificationEventType", NS.MT);

    this.lost(true);  // no value is good before the HMI's first status
  }

  // Three lights (red, yellow, green) as IA's StackElementLightType, ordered in the stack.
  buildStacklight(stack) {
    this.set(child(stack, "StacklightMode"), DataType.Int32, 0);  // Segmented
    const type = this.type("StackElementLightType", NS.IA);
    this.lights = {};
    ["red", "yellow", "green"].forEach((colour, i) => {
      const name = colour[0].toUpperCase() + colour.slice(1);
      const light = type.instantiate({
        browseName: { name: `${name}Light`, namespaceIndex: this.own.index },
        optionals: ["SignalOn", "SignalColor"],
      });
      stack.addReference({ referenceType: NodeId.resolveNodeId(`i=${kHasOrderedComponent}`), nodeId: light.nodeId });
      this.set(child(light, "NumberInList"), DataType.UInt32, i);
      this.set(child(light, "SignalColor"), DataType.Int32, map.SignalColor[name]);
      this.lights[colour] = this.dyn(child(light, "SignalOn"));
    });
  }

  // An AnalogUnitRangeType override in percent, 0 .. high.
  percentItem(v, high) {
    this.set(child(v, "EngineeringUnits"), DataType.ExtensionObject, standardUnits.percent);
    this.set(child(v, "EURange"), DataType.ExtensionObject,
             this.as.constructExtensionObject(NodeId.resolveNodeId("i=884"), { low: 0, high }));
    return v;
  }

  dyn(v) {
    this.dynamic.push(v);
    return v;
  }

  set(node, dataType, value) {
    const old = this.values.get(node);
    const same = old !== undefined && old.good && (old.value === value ||
      (typeof value === "object" && JSON.stringify(old.value) === JSON.stringify(value)));
    if (same) return;
    node.setValueFromSource({ dataType, value }, StatusCodes.Good);
    this.values.set(node, { value, good: true });
  }

  // The HMI is away: the values stay, marked BadNoCommunication until its next status
  // (before the first one: BadWaitingForInitialData).
  lost(initial = false) {
    for (const v of this.dynamic) {
      const old = this.values.get(v);
      if (old && !old.good) continue;
      v.setValueFromSource(v.readValue().value,
                           initial ? StatusCodes.BadWaitingForInitialData : StatusCodes.BadNoCommunication);
      this.values.set(v, { value: old ? old.value : undefined, good: false });
    }
    this.drivesRunning = false;
  }

  hello(m) {
    if (m.version) this.set(this.softwareRevision, DataType.String, m.version);
  }

  status(st) {
    this.drivesRunning = Boolean(st.services && st.services["cnc-drive-bridge"] &&
                                 !st.services["cnc-drive-bridge"].lost);
    const i = st.interp || {};
    this.set(this.operationMode, DataType.Int32, map.operationMode(st));
    this.set(this.channelState, DataType.Int32, map.channelState(st));
    this.set(this.channelMode, DataType.Int32, map.channelMode(st));
    this.set(this.feedOverride, DataType.Double, map.percent(i.feed_override));
    this.set(this.rapidOverride, DataType.Double, map.percent(i.rapid_override));
    this.set(this.singleStep, DataType.Boolean, Boolean(i.single_block));
    this.set(this.optionalStop, DataType.Boolean, Boolean(i.optional_stop));
    this.set(this.blockSkip, DataType.Boolean, Boolean(st.program && st.program.block_delete));
    const light = map.stackLight(st);
    for (const c of ["red", "yellow", "green"]) this.set(this.lights[c], DataType.Boolean, light[c]);
    if (this.isRotating) {
      const sp = map.spindle(st) || { isRotating: false, actualRpm: 0, commandedRpm: 0 };
      this.set(this.isRotating, DataType.Boolean, sp.isRotating);
      this.set(this.actualSpeed, DataType.Double, sp.actualRpm);
      this.set(this.commandedSpeed, DataType.Double, sp.commandedRpm);
      this.set(this.spindleOverride, DataType.Double, map.percent(i.spindle_override));
    }
    this.production(st);
  }

  production(st) {
    const p = st.program || {};
    if (!map.isOperatorLine(p.path)) {
      this.set(this.activeName, DataType.String, map.programName(p.path));
      const state = map.programState(st);
      if (this.activeState.getCurrentState() !== state) this.activeState.setState(state);
    }
    const changed = this.runs.update(st);
    const run = this.runs.run;
    if (run === null) {
      // No run since cnc-opcua started: an empty job, waiting in Initializing.
      this.set(this.activeJob, DataType.String, "");
      this.set(this.jobIdentifier, DataType.String, "");
      this.set(this.jobProgramName, DataType.String, "");
      this.set(this.runsCompleted, DataType.UInt32, 0);
    } else {
      this.set(this.activeJob, DataType.String, run.id);
      this.set(this.jobIdentifier, DataType.String, run.id);
      this.set(this.jobProgramName, DataType.String, run.name);
      this.set(this.runsCompleted, DataType.UInt32, run.completed);
      if (changed.started) {
        // A new run: the job's machine starts again from Initializing.
        this.jobState.setState("Initializing");
        this.jobProgramState.setState("Initializing");
      }
      if (this.jobState.getCurrentState() !== run.state) {
        this.jobState.setState(run.state);
        this.jobProgramState.setState(run.state);
      }
    }
    if (changed.ended) {
      this.counters.parts = this.runs.parts;
      this.set(this.parts, DataType.UInt32, this.counters.parts);
      this.emit("counters");
    }
  }

  tickPowerOn() {
    if (!this.drivesRunning) return;
    this.counters.power_on_s += 1;
    this.set(this.powerOnDuration, DataType.UInt32, Math.floor(this.counters.power_on_s / 3600));
  }

  // The HMI's last 200 alarms on (re)connect: none raised at the first connect (they
  // happened before this server); after a reconnect, those newer than the last raised.
  alarmHistory(list) {
    if (!this.connectedOnce) {
      this.connectedOnce = true;
      for (const a of list) this.lastAlarmUtime = Math.max(this.lastAlarmUtime || 0, a.utime || 0);
      if (this.lastAlarmUtime === null) this.lastAlarmUtime = 0;
      return;
    }
    for (const a of list) if ((a.utime || 0) > this.lastAlarmUtime) this.alarm(a);
  }

  alarm(a) {
    if (this.lastAlarmUtime !== null && (a.utime || 0) <= this.lastAlarmUtime && a.t !== "alarm") return;
    this.lastAlarmUtime = Math.max(this.lastAlarmUtime || 0, a.utime || 0);
    this.messages.raiseEvent(this.notificationEvent, {
      sourceName: { dataType: DataType.String, value: a.source || "" },
      message: { dataType: DataType.LocalizedText, value: { text: `${a.code}: ${a.text}` } },
      severity: { dataType: DataType.UInt16, value: map.alarmSeverity(a.severity) },
      time: { dataType: DataType.DateTime, value: a.utime ? new Date(a.utime / 1000) : new Date() },
      identifier: { dataType: DataType.String, value: a.code || "" },
    });
    this.eventsRaised += 1;
  }

  stop() {
    clearInterval(this.meter);
    clearInterval(this.saver);
  }
}

module.exports = { MachineToolModel };
