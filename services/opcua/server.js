"use strict";
// cnc-opcua's server: node-opcua with the companion specifications' nodesets that
// node-opcua-nodesets ships (DI, Machinery, IA, ISA-95 job control, Machinery Jobs,
// MachineTool: OPC 40501-1 v1.02), one MachineToolType instance under Machinery's
// Machines folder, its values pushed from the HMI's status (hmi_client.js) through
// mapping.js, the cell's ALARMs raised as NotificationEventType events.
//
// Started by cnc-opcua (main.cc), which reads the machine config and passes the
// resolved settings in CNC_OPCUA_SETTINGS. docs/opcua.md has the node -> source table.
// A stop asked for while node-opcua loads and the server starts is carried out once it
// has started (SIGTERM's default would end node with 143, not a clean stop).
let stop = null;
let stopAsked = null;
const onSignal = (signal) => (stop ? stop(signal) : (stopAsked = signal));
process.on("SIGTERM", () => onSignal("SIGTERM"));
process.on("SIGINT", () => onSignal("SIGINT"));

const fs = require("node:fs");
const path = require("node:path");
const {
  OPCUAServer, OPCUACertificateManager, nodesets, SecurityPolicy, MessageSecurityMode, UserTokenType,
} = require("node-opcua");
const { HmiClient } = require("./hmi_client");
const { MachineToolModel } = require("./machine_tool");

const kExitBadInput = 2;

const log = {
  info: (m) => console.log(`[info] ${m}`),
  warn: (m) => console.error(`[warning] ${m}`),
  error: (m) => console.error(`[error] ${m}`),
};

function settings() {
  try {
    return JSON.parse(process.env.CNC_OPCUA_SETTINGS || "");
  } catch (e) {
    log.error("cnc-opcua: server.js is started by cnc-opcua (CNC_OPCUA_SETTINGS is not its JSON)");
    process.exit(kExitBadInput);
  }
  return null;
}

// The cell's counters (power-on time, parts) over restarts: STATE/counters.json.
function loadCounters(file) {
  try {
    const c = JSON.parse(fs.readFileSync(file, "utf8"));
    return { power_on_s: Number(c.power_on_s) || 0, parts: Number(c.parts) || 0 };
  } catch (e) {
    return { power_on_s: 0, parts: 0 };
  }
}

function saveCounters(file, c) {
  const tmp = file + ".tmp";
  fs.writeFileSync(tmp, JSON.stringify(c) + "\n");
  fs.renameSync(tmp, file);
}

async function main() {
  const s = settings();
  fs.mkdirSync(s.state_dir, { recursive: true, mode: 0o700 });
  let password = "";
  if (s.hmi.password_file) {
    try {
      password = fs.readFileSync(s.hmi.password_file, "utf8").split("\n")[0];
    } catch (e) {
      log.error(`cnc-opcua: config error: opcua.hmi_password_file: ${e.message}`);
      process.exit(kExitBadInput);
    }
  }
  const hmi = new HmiClient({ ...s.hmi, password }, log);

  // The server's certificate and key, made on the first start (10 years), and the
  // client certificates it trusts: STATE/pki (own/, trusted/, rejected/).
  const safe = (t) => String(t).replace(/[^A-Za-z0-9 ._-]/g, "_");
  OPCUACertificateManager.defaultCertificateSubject = `/O=${safe(s.identification.manufacturer)}`;
  const certificateManager = new OPCUACertificateManager({
    rootFolder: path.join(s.state_dir, "pki"),
    automaticallyAcceptUnknownCertificate: s.trust_unknown_clients,
  });

  // The pki folders are polled every second (node-opcua-pki's default: 5 s), so that a
  // client certificate an operator moves from rejected/ to trusted/certs/ is taken soon.
  certificateManager.folderPoolingInterval = 1000;
  // node-opcua-pki 5.7 forgets the file of a certificate it rejected while running: the
  // move out of rejected/ goes unnoticed, the fingerprint stays in its rejected index
  // and wins over the trusted file (and a client that tries again before the trusted
  // folder's watcher has the file is rejected anew). Once a second: a rejected entry
  // whose file was moved to trusted/certs is trusted, one whose file is gone forgotten.
  const forgetMovedRejections = setInterval(() => {
    const thumbs = certificateManager._thumbs;
    if (!thumbs || !thumbs.rejected) return;
    for (const [fingerprint, entry] of Object.entries(thumbs.rejected)) {
      if (!entry || !entry.filename || fs.existsSync(entry.filename)) continue;
      delete thumbs.rejected[fingerprint];
      const moved = path.join(certificateManager.trustedFolder, path.basename(entry.filename));
      if (fs.existsSync(moved)) {
        thumbs.trusted[fingerprint] = { certificate: entry.certificate, filename: moved };
        log.info(`cnc-opcua: client certificate ${path.basename(moved)} trusted (moved to ${certificateManager.trustedFolder})`);
      }
    }
  }, 1000);
  forgetMovedRejections.unref();

  const policies = [SecurityPolicy.Basic256Sha256];
  const modes = [MessageSecurityMode.SignAndEncrypt];
  if (s.allow_security_none) {
    policies.push(SecurityPolicy.None);
    modes.push(MessageSecurityMode.None);
  }
  const wildcard = s.listen === "0.0.0.0" || s.listen === "::";
  const server = new OPCUAServer({
    port: s.port,
    host: s.listen,
    hostname: wildcard ? undefined : s.listen,
    securityPolicies: policies,
    securityModes: modes,
    allowAnonymous: s.anonymous,
    serverCertificateManager: certificateManager,
    // No user is known by a certificate (below: that token is not offered); this PKI only
    // keeps node-opcua from making its default one in the user's home.
    userCertificateManager: new OPCUACertificateManager({
      rootFolder: path.join(s.state_dir, "user-pki"),
      automaticallyAcceptUnknownCertificate: false,
    }),
    disableDiscovery: false,
    nodeset_filename: [nodesets.standard, nodesets.di, nodesets.machinery, nodesets.ia, nodesets.isa95JobControl,
                       nodesets.machineryJobs, nodesets.machineTool],
    serverInfo: {
      applicationUri: `urn:cnc:${safe(s.cell)}:opcua`,
      productUri: "urn:cnc:opcua",
      applicationName: { text: `cnc-opcua ${safe(s.cell)}`, locale: "en" },
    },
    buildInfo: { productName: "cnc-opcua", softwareVersion: s.version, manufacturerName: s.identification.manufacturer },
    serverCapabilities: { maxSessions: 20 },
    // Users are the HMI's: a name and password are right when the HMI's login takes them.
    userManager: {
      isValidUserAsync: (user, pw, done) => {
        hmi.checkLogin(user, pw).then(
          (ok) => {
            log.info(`cnc-opcua: OPC UA login of '${user}' ${ok ? "accepted" : "refused"} by the HMI`);
            done(null, ok);
          },
          (e) => {
            log.warn(`cnc-opcua: OPC UA login of '${user}' refused: the HMI did not answer (${e.message})`);
            done(null, false);
          });
      },
    },
  });
  await server.initialize();
  // The user tokens offered: a user name and password (the HMI's users), and anonymous
  // when the config allows it. node-opcua also offers X509 user certificates; removed,
  // a session that presents one is refused.
  for (const e of server.endpoints)
    for (const d of e.endpointDescriptions())
      d.userIdentityTokens = (d.userIdentityTokens || []).filter((t) => t.tokenType !== UserTokenType.Certificate);

  const countersFile = path.join(s.state_dir, "counters.json");
  const counters = loadCounters(countersFile);
  const model = new MachineToolModel(server.engine.addressSpace, s, counters, log);

  hmi.on("hello", (m) => model.hello(m));
  hmi.on("status", (m) => model.status(m));
  hmi.on("alarms", (m) => model.alarmHistory(m.alarms || []));
  hmi.on("alarm", (m) => model.alarm(m));
  hmi.on("disconnected", () => model.lost());
  model.on("counters", () => saveCounters(countersFile, counters));

  await server.start();
  // A restricted None endpoint serves discovery only (GetEndpoints); no session is taken on it.
  const endpoints = server.endpoints.flatMap((e) => e.endpointDescriptions()).filter((d) => !d.restricted)
    .map((d) => `${d.securityPolicyUri.split("#")[1]}/${MessageSecurityMode[d.securityMode]}`);
  log.info(`cnc-opcua: ${s.endpoint_url} listening (node ${process.version}, ${[...new Set(endpoints)].join(", ")}; ` +
           `anonymous ${s.anonymous ? "read only" : "refused"}; certificate ${path.join(s.state_dir, "pki", "own", "certs", "certificate.pem")})`);
  console.log(`cnc-opcua: open ${s.endpoint_url}`);
  hmi.start();

  let stopping = false;
  stop = async (signal) => {
    if (stopping) return;
    stopping = true;
    log.info(`cnc-opcua: ${signal}: stopping`);
    hmi.stop();
    model.stop();
    saveCounters(countersFile, counters);
    await server.shutdown(500);
    log.info(`cnc-opcua: stopped (${model.eventsRaised} events raised, ${counters.parts} parts counted)`);
    process.exit(0);
  };
  if (stopAsked) stop(stopAsked);
}

main().catch((e) => {
  log.error(`cnc-opcua: ${e.stack || e.message}`);
  process.exit(1);
});
