"use strict";
// The fleet page: cnc-fleet's /fleet.json (the cells' cnc-mqtt records) once a second.

function text(v) { return v === null || v === undefined ? "" : String(v); }

function cellRow(c) {
  const tr = document.createElement("tr");
  tr.dataset.cell = c.cell;
  const td = (t, cls) => { const e = document.createElement("td"); e.textContent = t; if (cls) e.className = cls; tr.appendChild(e); return e; };
  const st = c.status || {}, s = c.state || {};
  td(c.cell);
  td(text(st.status) + (st.status === "offline" && st.reason ? " (" + st.reason + ")" : ""), st.status === "online" ? "online" : "offline")
    .dataset.status = text(st.status);
  const p = s.program || {};
  td(text(p.name));
  td(text(p.state) + (s.interp ? " / " + s.interp.state : "")).dataset.state = text(p.state);
  td(s.overrides && s.overrides.feed !== null ? Math.round(s.overrides.feed * 100) + " %" : "");
  td(s.spindle ? text(s.spindle.state) + " " + Math.round(s.spindle.actual_rpm || 0) + " rpm" : "");
  td(s.position_mm ? Object.entries(s.position_mm).map(([a, v]) => a + " " + (v === null ? "?" : v.toFixed(3))).join("  ") : "");
  const jobs = td("", "jobs");
  for (const j of c.jobs || []) {
    const d = document.createElement("div");
    d.className = text(j.outcome);
    d.dataset.job = text(j.job);
    const when = new Date(j.end_utime / 1000).toLocaleString();
    d.textContent = `${j.program} ${j.outcome} ${Number(j.duration_s).toFixed(1)} s, ${j.alarms} alarms, ` +
      `FE ${j.max_following_error_mm === null ? "?" : (j.max_following_error_mm * 1000).toFixed(1) + " µm"} (${when})`;
    jobs.appendChild(d);
  }
  return tr;
}

async function refresh() {
  try {
    const r = await fetch("fleet.json", { cache: "no-store" });
    const f = await r.json();
    document.getElementById("broker").textContent =
      `broker ${f.broker.host}:${f.broker.port} ${f.broker.connected ? "connected" : "not connected"}, ${f.records} records`;
    const body = document.querySelector("#cells tbody");
    body.replaceChildren(...f.cells.map(cellRow));
    document.getElementById("empty").hidden = f.cells.length > 0;
  } catch (e) {
    document.getElementById("broker").textContent = "cnc-fleet not reachable";
  }
}

refresh();
setInterval(refresh, 1000);
