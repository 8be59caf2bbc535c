"use strict";
// integration.opcua's OPC UA client: node-opcua's real client against cnc-opcua on a
// live cell (opcua_test.sh starts the cell, cnc-hmi and two cnc-opcua servers).
//   node opcua_client.js SETTINGS_JSON
// SETTINGS_JSON: {secure: URL, open: URL, server_pki, client_pki, user, password,
// ctl: [cnc-ctl, --machine, M], program, cell, identification {...}}.
// Every check prints "ok: ..." or fails (exit 1) naming what it expected and got.
const fs = require("node:fs");
const path = require("node:path");
const { execFile } = require("node:child_process");
const {
  OPCUAClient, OPCUACertificateManager, MessageSecurityMode, SecurityPolicy, AttributeIds, NodeClass,
  UserTokenType, TimestampsToReturn, StatusCodes, DataType, BrowseDirection, makeBrowsePath,
  constructEventFilter, ClientMonitoredItem, ClientSubscription,
} = require("node-opcua");

const cfg = JSON.parse(process.argv[2]);
const t0 = Date.now();
const elapsed = () => ((Date.now() - t0) / 1000).toFixed(2);
function ok(what) { console.log(`ok: ${what} (${elapsed()} s)`); }
function fail(what) {
  console.error(`FAIL: ${what}`);
  process.exit(1);
}
function expectEqual(what, got, want) {
  const g = JSON.stringify(got);
  const w = JSON.stringify(want);
  if (g !== w) fail(`${what}: expected ${w}, got ${g}`);
  ok(`${what} = ${g}`);
}
const sleep = (ms) => new Promise((r) => setTimeout(r, ms));

const NS_MT = "http://opcfoundation.org/UA/MachineTool/";
const NS_MACHINERY = "http://opcfoundation.org/UA/Machinery/";
const NS_IA = "http://opcfoundation.org/UA/IA/";

function makeClient(security, endpointMustExist = true) {
  return OPCUAClient.create({
    applicationName: "cnc-opcua-test-client",
    applicationUri: "urn:cnc:opcua-test-client",
    securityMode: security ? MessageSecurityMode.SignAndEncrypt : MessageSecurityMode.None,
    securityPolicy: security ? SecurityPolicy.Basic256Sha256 : SecurityPolicy.None,
    endpointMustExist,
    connectionStrategy: { maxRetry: 0, initialDelay: 100, maxDelay: 200 },
    requestedSessionTimeout: 20000,
    clientCertificateManager: new OPCUACertificateManager({
      rootFolder: cfg.client_pki,
      automaticallyAcceptUnknownCertificate: true,  // the test's own server
    }),
  });
}

// The error's text of `fn()`, failing when it succeeds.
async function refused(what, fn) {
  try {
    await fn();
  } catch (e) {
    return String(e.message || e);
  }
  fail(`${what}: succeeded, expected a refusal`);
  return "";
}

async function connect(url, security) {
  const client = makeClient(security);
  await client.connect(url);
  return client;
}

function ctl(args) {
  return new Promise((resolve) => {
    execFile(cfg.ctl[0], [...cfg.ctl.slice(1), ...args], { timeout: 60000 }, (err, stdout, stderr) =>
      resolve({ code: err ? (err.code ?? 1) : 0, out: stdout + stderr }));
  });
}

async function resolvePath(session, start, names) {
  const r = await session.translateBrowsePath(makeBrowsePath(start, names));
  if (r.statusCode !== StatusCodes.Good || !r.targets || r.targets.length !== 1)
    fail(`browse path ${names} from ${start}: ${r.statusCode.toString()}`);
  return r.targets[0].targetId;
}

async function main() {
  // 1. The endpoints the secure server offers: Basic256Sha256 with SignAndEncrypt only.
  {
    const client = makeClient(false);
    await client.connect(cfg.secure);  // GetEndpoints is allowed on a None channel (discovery)
    const eps = (await client.getEndpoints()).map((e) =>
      `${e.securityPolicyUri.split("#")[1]}/${MessageSecurityMode[e.securityMode]}`);
    await client.disconnect();
    expectEqual("secure server's endpoints", [...new Set(eps)].sort(), ["Basic256Sha256/SignAndEncrypt"]);
  }
  // 2. SecurityPolicy None is refused there. node-opcua's client will not even ask for a
  //    session on an endpoint the server does not offer; told that the secure endpoint
  //    is the one, it asks on the None channel, and the server must refuse.
  {
    const c = makeClient(false, false);
    await c.connect(cfg.secure);
    c.findEndpoint = () => undefined;
    c.findEndpointForSecurity = () => c._serverEndpoints[0];
    const why = await refused("a session over SecurityPolicy None on the secure server", async () => {
      const s = await c.createSession({ type: UserTokenType.UserName, userName: cfg.user, password: cfg.password });
      await s.close();
    });
    await c.disconnect();
    expectEqual("a session over SecurityPolicy None: the server's answer", (why.match(/Bad\w+/) || [why])[0],
                "BadSecurityModeRejected");
  }
  // 3. This client's certificate is unknown to the server (trust_unknown_clients: false):
  //    refused and kept in pki/rejected; moved to pki/trusted/certs as an operator would.
  {
    const why = await refused("an unknown client certificate", async () => {
      const c = await connect(cfg.secure, true);
      const s = await c.createSession({ type: UserTokenType.UserName, userName: cfg.user, password: cfg.password });
      await s.close();
      await c.disconnect();
    });
    const rejected = path.join(cfg.server_pki, "rejected");
    const files = fs.existsSync(rejected) ? fs.readdirSync(rejected).filter((f) => f.endsWith(".pem") || f.endsWith(".der")) : [];
    expectEqual("client certificates in the server's pki/rejected after the refusal", files.length, 1);
    ok(`unknown client certificate refused: ${why.split("\n")[0]}`);
    fs.renameSync(path.join(rejected, files[0]), path.join(cfg.server_pki, "trusted", "certs", files[0]));
  }
  // Trusted now (the server notices the moved file within a second or two).
  let client = null;
  let session = null;
  const trustBy = Date.now() + 15000;
  while (session === null && Date.now() < trustBy) {
    try {
      client = await connect(cfg.secure, true);
      session = await client.createSession({ type: UserTokenType.UserName, userName: cfg.user, password: cfg.password });
    } catch (e) {
      if (client) await client.disconnect().catch(() => {});
      client = null;
      await sleep(250);
    }
  }
  if (session === null) fail("the moved certificate was not trusted within 15 s");
  ok(`session as '${cfg.user}' over Basic256Sha256/SignAndEncrypt`);

  // 4. Browse: Objects/Machines (Machinery) holds the cell as a MachineToolType.
  const ns = async (uri) => {
    const arr = (await session.readNamespaceArray());
    const i = arr.indexOf(uri);
    if (i < 0) fail(`the server has no namespace ${uri}`);
    return i;
  };
  const nsMT = await ns(NS_MT);
  const nsMa = await ns(NS_MACHINERY);
  const nsIA = await ns(NS_IA);
  const machines = `ns=${nsMa};i=1001`;
  const br = await session.browse({ nodeId: machines, browseDirection: BrowseDirection.Forward, resultMask: 63,
                                    referenceTypeId: "Organizes", includeSubtypes: true, nodeClassMask: NodeClass.Object });
  const mine = br.references.filter((r) => r.browseName.name === cfg.cell);
  expectEqual(`Machines folder holds '${cfg.cell}'`, mine.length, 1);
  const machine = mine[0].nodeId.toString();
  expectEqual("its type definition", mine[0].typeDefinition.toString(), `ns=${nsMT};i=13`);  // MachineToolType
  const top = await session.browse({ nodeId: machine, browseDirection: BrowseDirection.Forward,
                                     referenceTypeId: "HierarchicalReferences", includeSubtypes: true, resultMask: 63 });
  const names = [...new Set(top.references.map((r) => r.browseName.name))].sort();
  for (const m of ["Equipment", "Identification", "Monitoring", "Notification", "Production"])
    if (!names.includes(m)) fail(`the machine has no mandatory ${m} (it has ${names})`);
  ok(`the machine's mandatory components: ${names.join(", ")}`);

  // Every variable below the machine reads Good with a value (the mandatory ones and
  // the optional ones this server adds).
  {
    const vars = [];
    const methods = [];
    const walk = async (id, where) => {
      const r = await session.browse({ nodeId: id, browseDirection: BrowseDirection.Forward, resultMask: 63,
                                       referenceTypeId: "HasChild", includeSubtypes: true });
      for (const ref of r.references) {
        const here = `${where}/${ref.browseName.name}`;
        if (ref.nodeClass === NodeClass.Variable) vars.push([here, ref.nodeId]);
        if (ref.nodeClass === NodeClass.Method) methods.push(here);
        if (ref.nodeClass === NodeClass.Object || ref.nodeClass === NodeClass.Variable) await walk(ref.nodeId, here);
      }
    };
    await walk(machine, cfg.cell);
    const dvs = await session.read(vars.map(([, nodeId]) => ({ nodeId, attributeId: AttributeIds.Value })));
    const bad = vars.filter((v, i) => dvs[i].statusCode !== StatusCodes.Good || dvs[i].value.value === null)
      .map(([p], i) => p);
    expectEqual(`variables below the machine (${vars.length}) that do not read Good with a value`, bad, []);
    expectEqual("methods below the machine", methods, []);
  }
  const node = (p) => resolvePath(session, machine, p);
  const read = async (p) => {
    const dv = await session.read({ nodeId: await node(p), attributeId: AttributeIds.Value });
    if (dv.statusCode !== StatusCodes.Good) fail(`${p}: ${dv.statusCode.toString()}`);
    return dv.value.value;
  };
  const P = (...parts) => parts.map((x) => (x.includes(":") ? x : `${nsMT}:${x}`)).map((x) => `/${x}`).join("");
  const di = await ns("http://opcfoundation.org/UA/DI/");
  const id = cfg.identification;
  expectEqual("Identification/Manufacturer", (await read(`/${di}:Identification/${di}:Manufacturer`)).text, id.manufacturer);
  expectEqual("Identification/Model", (await read(`/${di}:Identification/${di}:Model`)).text, id.model);
  expectEqual("Identification/SerialNumber", await read(`/${di}:Identification/${di}:SerialNumber`), id.serial_number);
  expectEqual("Identification/ProductInstanceUri", await read(`/${di}:Identification/${di}:ProductInstanceUri`),
              `urn:cnc:${cfg.cell}:${id.serial_number}`);
  expectEqual("Monitoring/MachineTool/OperationMode (Automatic)", await read(P("Monitoring", "MachineTool", "OperationMode")), 1);
  expectEqual("Monitoring/MachineTool/PowerOnDuration (h)", await read(P("Monitoring", "MachineTool", "PowerOnDuration")), 0);
  const ch = `${P("Monitoring")}/1:Channel1`;  // placeholders are instances of the cell's namespace (1)
  expectEqual("Channel1/ChannelState (Reset)", await read(`${ch}${P("ChannelState")}`), 2);
  expectEqual("Channel1/ChannelMode (Automatic)", await read(`${ch}${P("ChannelMode")}`), 0);
  expectEqual("Channel1/FeedOverride (%)", await read(`${ch}${P("FeedOverride")}`), 100);
  expectEqual("Channel1/RapidOverride (%)", await read(`${ch}${P("RapidOverride")}`), 100);
  expectEqual("Spindle/IsRotating", await read(`${P("Monitoring")}/1:Spindle${P("IsRotating")}`), false);
  expectEqual("Stacklight/StacklightMode (Segmented)", await read(`${P("Monitoring", "Stacklight")}/${nsIA}:StacklightMode`), 0);
  const active = P("Production", "ActiveProgram");
  expectEqual("ActiveProgram/State/CurrentState", (await read(`${active}${P("State")}/0:CurrentState`)).text, "Initializing");
  const parts0 = await read(P("Production", "Statistics", "PartsProducedInLifetime"));
  expectEqual("PartsProducedInLifetime before the run", parts0, 0);

  // 5. Subscriptions: the channel state, the program's and the job's states, the parts;
  //    NotificationEventType events on the Server object.
  const sub = ClientSubscription.create(session, { requestedPublishingInterval: 50, requestedMaxKeepAliveCount: 20,
                                                   publishingEnabled: true, maxNotificationsPerPublish: 1000 });
  const seen = {};
  const watch = async (name, p, pick = (v) => v) => {
    seen[name] = [];
    const item = ClientMonitoredItem.create(sub, { nodeId: await node(p), attributeId: AttributeIds.Value },
                                            { samplingInterval: 0, discardOldest: false, queueSize: 100 },
                                            TimestampsToReturn.Both);
    item.on("changed", (dv) => {
      const v = pick(dv.value.value);
      const list = seen[name];
      if (list.length === 0 || list[list.length - 1] !== v) list.push(v);
    });
  };
  await watch("ChannelState", `${ch}${P("ChannelState")}`);
  await watch("ActiveProgram", `${active}${P("State")}/0:CurrentState`, (v) => v && v.text);
  const job = `${P("Production", "ProductionPlan")}/1:Job`;  // the cell's own namespace (1)
  await watch("Job", `${job}${P("State")}/0:CurrentState`, (v) => v && v.text);
  await watch("RunsCompleted", `${job}${P("RunsCompleted")}`);
  await watch("Parts", P("Production", "Statistics", "PartsProducedInLifetime"));
  const spindle = `${P("Monitoring")}/1:Spindle`;
  await watch("IsRotating", `${spindle}${P("IsRotating")}`);
  await watch("CommandedSpeed", `${spindle}/1:CommandedSpeed`);
  let topSpeed = 0;
  await watch("ActualSpeed", `${spindle}/1:ActualSpeed`, (v) => { topSpeed = Math.max(topSpeed, v); return 0; });
  await watch("GreenLight", `${P("Monitoring", "Stacklight")}/1:GreenLight/${nsIA}:SignalOn`);
  const events = [];
  const fields = ["EventType", "SourceName", "Message", "Severity", `${nsMT}:Identifier`];
  const evItem = ClientMonitoredItem.create(sub, { nodeId: "i=2253", attributeId: AttributeIds.EventNotifier },
                                            { queueSize: 100, filter: constructEventFilter(fields), discardOldest: false },
                                            TimestampsToReturn.Both);
  evItem.on("changed", (f) => events.push({ type: f[0].value.toString(), source: f[1].value, message: f[2].value && f[2].value.text,
                                            severity: f[3].value, identifier: f[4].value }));
  await sleep(500);

  // 6. A short program, run by the operator (cnc-ctl, through the interlock).
  const run = await ctl(["--do", "run", "--program", cfg.program, "--timeout", "40"]);
  if (run.code !== 0) fail(`cnc-ctl --do run: exit ${run.code}: ${run.out}`);
  ok("the program ran to its end (cnc-ctl)");
  await sleep(800);
  expectEqual("ChannelState's changes during the run (Reset, Active, Reset)", seen.ChannelState, [2, 0, 2]);
  expectEqual("ActiveProgram's states", seen.ActiveProgram.slice(-2), ["Running", "Ended"]);
  expectEqual("the job's states", seen.Job, ["Initializing", "Running", "Ended"]);
  expectEqual("the job's RunsCompleted", seen.RunsCompleted, [0, 1]);
  expectEqual("PartsProducedInLifetime", seen.Parts, [0, 1]);
  expectEqual("the green light", seen.GreenLight, [false, true, false]);
  // The spindle: M3 S6000 until M5; it runs down after the program's end (about 0.5 s).
  for (let i = 0; i < 30 && seen.IsRotating[seen.IsRotating.length - 1] !== false; i++) await sleep(100);
  expectEqual("Spindle/IsRotating", seen.IsRotating, [false, true, false]);
  expectEqual("Spindle/1:CommandedSpeed (rpm)", seen.CommandedSpeed, [0, 6000, 0]);
  if (!(topSpeed >= 5880 && topSpeed <= 6120)) fail(`Spindle/1:ActualSpeed's top ${topSpeed} rpm: expected 6000 within 2 %`);
  ok(`Spindle/1:ActualSpeed's top ${topSpeed.toFixed(1)} rpm (6000 within 2 %)`);

  // 7. Alarms as events: a RESET (the interpolator's `reset`, INFO) and a wrong password
  //    (the HMI's `hmi_login_refused`, WARNING) reach the subscriber with code and source.
  const reset = await ctl(["--do", "reset", "--timeout", "20"]);
  if (reset.code !== 0) fail(`cnc-ctl --do reset: exit ${reset.code}: ${reset.out}`);
  {
    const why = await refused("a wrong password", async () => {
      const c = await connect(cfg.secure, true);
      try {
        await c.createSession({ type: UserTokenType.UserName, userName: cfg.user, password: cfg.password + "x" });
      } finally {
        await c.disconnect();
      }
    });
    if (!/BadUserAccessDenied|BadIdentityTokenRejected/.test(why)) fail(`wrong password refused, but with: ${why}`);
    ok(`wrong password refused: ${why.match(/Bad\w+/)[0]}`);
  }
  // Anonymous: the secure server offers no anonymous token, nor a user certificate;
  // told it does, the client asks, and the server must refuse.
  {
    const c = makeClient(true, false);
    await c.connect(cfg.secure);
    const tokens = c._serverEndpoints.flatMap((e) => e.userIdentityTokens.map((t) => UserTokenType[t.tokenType]));
    expectEqual("the secure server's user tokens", [...new Set(tokens)], ["UserName"]);
    for (const e of c._serverEndpoints)
      e.userIdentityTokens.push({ policyId: "anonymous", tokenType: UserTokenType.Anonymous, securityPolicyUri: null });
    const why = await refused("an anonymous session on the secure server", async () => {
      const s = await c.createSession();
      await s.close();
    });
    await c.disconnect();
    expectEqual("an anonymous session on the secure server: the server's answer", (why.match(/Bad\w+/) || [why])[0],
                "BadIdentityTokenInvalid");
  }
  for (let i = 0; i < 50 && !(events.some((e) => e.identifier === "reset") &&
                               events.some((e) => e.identifier === "hmi_login_refused")); i++) await sleep(100);
  const ev = (code) => events.find((e) => e.identifier === code);
  const r = ev("reset");
  if (!r) fail(`no event with Identifier 'reset' (got ${JSON.stringify(events)})`);
  expectEqual("the reset event's type (NotificationEventType)", r.type, `ns=${nsMT};i=35`);
  expectEqual("the reset event's SourceName", r.source, "cnc-interpolator");
  expectEqual("the reset event's Severity (INFO)", r.severity, 200);
  const l = ev("hmi_login_refused");
  if (!l) fail(`no event with Identifier 'hmi_login_refused' (got ${JSON.stringify(events)})`);
  expectEqual("the refused login's SourceName", l.source, "cnc-hmi");
  expectEqual("the refused login's Severity (WARNING)", l.severity, 500);
  if (!/^hmi_login_refused: 1 login\(s\) refused/.test(l.message)) fail(`the refused login's Message: ${l.message}`);
  ok(`the refused login's Message: ${l.message}`);

  // 8. Nothing is writable, even to the user who logged in.
  {
    const st = await session.write({ nodeId: await node(`${ch}${P("FeedOverride")}`), attributeId: AttributeIds.Value,
                                     value: { value: { dataType: DataType.Double, value: 50 } } });
    expectEqual("a write of FeedOverride by the user", st.name, "BadNotWritable");
  }
  await sub.terminate();
  await session.close();
  await client.disconnect();

  // 9. The open server (anonymous: true, allow_security_none: true): anonymous reads over None.
  {
    const c = await connect(cfg.open, false);
    const eps = (await c.getEndpoints()).map((e) => `${e.securityPolicyUri.split("#")[1]}/${MessageSecurityMode[e.securityMode]}`);
    expectEqual("open server's endpoints", [...new Set(eps)].sort(), ["Basic256Sha256/SignAndEncrypt", "None/None"]);
    const s = await c.createSession();
    const arr = await s.readNamespaceArray();
    const mt = arr.indexOf(NS_MT);
    const ma = arr.indexOf(NS_MACHINERY);
    const r2 = await s.translateBrowsePath(makeBrowsePath(`ns=${ma};i=1001`,
      `/1:${cfg.cell}/${mt}:Monitoring/1:Channel1/${mt}:ChannelState`));
    const dv = await s.read({ nodeId: r2.targets[0].targetId, attributeId: AttributeIds.Value });
    expectEqual("anonymous read of ChannelState over None (Reset)", [dv.statusCode.name, dv.value.value], ["Good", 2]);
    const st = await s.write({ nodeId: r2.targets[0].targetId, attributeId: AttributeIds.Value,
                               value: { value: { dataType: DataType.Int32, value: 0 } } });
    expectEqual("an anonymous write of ChannelState", st.name, "BadNotWritable");
    await s.close();
    await c.disconnect();
  }
  console.log(`opcua client: all checks passed in ${elapsed()} s`);
  process.exit(0);
}

main().catch((e) => fail(e.stack || e.message));
