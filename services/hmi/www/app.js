// cnc-hmi's page: the cell's state from the WebSocket, the operator's actions to it.
// The API (README, "The browser HMI"): JSON text frames; the server sends hello,
// status (25 Hz), program, preview, alarms, alarm, result, programs, runs; the page
// sends {id, action, ...}.
'use strict';

const S = {
  ws: null, axes: [], mayControl: false, nextId: 1, unavailable: [],
  preview: null, bounds: null, trail: [], programLines: 0, currentLine: -1,
  jogTimer: null, jogAxis: null, sliderBusy: false, lastStatus: null,
};
// Measured in the page (the integration test reads it): status messages shown.
// rate: frames in the last second; minRate: the lowest such second after the first.
window.hmiStats = { status: 0, since: 0, rate: 0, minRate: 0, window: [], results: [], previewPoints: 0 };

const $ = (id) => document.getElementById(id);
const fmt = (v, d = 3) => (typeof v === 'number' ? v.toFixed(d) : '—');
// A wrapped rotary axis is shown as LinuxCNC shows it: its angle in [0, 360).
const wrap360 = (v) => (typeof v === 'number' ? ((v % 360) + 360) % 360 : v);

function send(action, extra = {}) {
  if (!S.ws || S.ws.readyState !== WebSocket.OPEN) { showMsg(false, 'not connected'); return -1; }
  const id = S.nextId++;
  S.ws.send(JSON.stringify(Object.assign({ id, action }, extra)));
  return id;
}

function showMsg(ok, text) {
  const m = $('msg');
  m.textContent = text;
  m.className = 'msg ' + (ok ? 'ok' : 'err');
}

function connect() {
  const ws = new WebSocket(`ws://${location.host}/ws`);
  S.ws = ws;
  ws.onopen = () => { $('conn').textContent = 'connected'; $('conn').className = 'badge ok'; };
  ws.onclose = () => {
    $('conn').textContent = 'disconnected'; $('conn').className = 'badge bad';
    stopJog();
    setTimeout(connect, 1000);
  };
  ws.onmessage = (ev) => {
    let m;
    try { m = JSON.parse(ev.data); } catch (e) { return; }
    const h = handlers[m.t];
    if (h) h(m);
  };
}

const handlers = {
  hello(m) {
    S.axes = m.axes; S.mayControl = m.may_control; S.unavailable = m.unavailable || [];
    S.maxUpload = m.upload_max_bytes || 0;
    if (typeof m.max_feed_override === 'number') $('feed-override').max = Math.round(m.max_feed_override * 100);
    buildMachine(m.devices || {});
    $('machine').textContent = `${m.machine} · cnc-hmi ${m.version}`;
    $('who').textContent = m.may_control ? (m.login ? `user ${m.user}` : 'local') : 'view only';
    $('logout').hidden = !m.login;
    document.body.classList.toggle('view-only', !m.may_control);
    buildAxes();
    if (window.preview3d) window.preview3d.setTravel(S.axes);
    fillPrograms(m.programs);
    $('program-dir').textContent = m.program_dir;
    for (const el of document.querySelectorAll('[data-control]')) el.disabled = !m.may_control;
    for (const el of document.querySelectorAll('[data-unavailable]')) {
      const missing = S.unavailable.includes(el.dataset.unavailable);
      el.disabled = missing || !m.may_control;
      el.title = missing ? 'not a cell command yet' : '';
    }
    if (!m.may_control) showMsg(false, 'view only: log in to operate the machine');
  },
  status(m) {
    const st = window.hmiStats;
    const now = performance.now();
    if (st.status++ === 0) st.since = now;
    st.window.push(now);
    while (st.window.length && st.window[0] < now - 1000) st.window.shift();
    st.rate = st.window.length;
    if (now - st.since > 1500 && !document.hidden) st.minRate = st.minRate ? Math.min(st.minRate, st.rate) : st.rate;
    $('rate').textContent = `${st.rate} Hz`;
    S.lastStatus = m;
    st.last = m;
    showBigDro(m);
    m.axes.forEach((a, i) => {
      const set = (k, v) => { const el = $(`dro-${a.name}-${k}`); if (el) el.textContent = v; };
      const w = S.axes[i] && S.axes[i].wrapped ? wrap360 : (v) => v;
      set('cmd', fmt(w(a.cmd))); set('act', fmt(w(a.act))); set('fe', fmt(a.fe, 4));
      set('dtg', fmt(a.dtg)); set('homed', a.homed === undefined ? '—' : (a.homed ? 'yes' : 'no'));
      set('drive', a.drive || '—');
      const row = $(`dro-${a.name}`);
      if (row) row.className = a.drive === 'fault' ? 'fault' : '';
    });
    $('feed').textContent = typeof m.feed === 'number' ? m.feed.toFixed(0) : '—';
    const it = m.interp || {}, pg = m.program || {};
    $('mode').textContent = it.mode ? `${it.mode}${it.mode_text ? ' (' + it.mode_text + ')' : ''}` : '—';
    $('states').innerHTML = '';
    const addState = (label, v, cls) => {
      const b = document.createElement('b'); b.textContent = `${label} ${v}`; b.className = 'badge ' + cls;
      b.id = `state-${label}`; $('states').appendChild(b);
    };
    addState('program', pg.state || '—', pg.state === 'fault' || pg.state === 'refused' ? 'bad' : pg.state === 'running' ? 'ok' : '');
    addState('interp', it.state || '—', it.state === 'fault' ? 'bad' : it.state === 'held' ? 'warn' : it.state === 'running' ? 'ok' : '');
    $('program-state').textContent = pg.state || '';
    // Run from line: the approach the cell will make, until it is confirmed.
    const pending = pg.approach_pending === true;
    $('approach-box').hidden = !(pg.from_line > 0 && pg.approach);
    $('approach-line').textContent = pg.from_line || '';
    $('approach').textContent = pg.approach || '';
    $('btn-confirm').hidden = !pending;
    if (typeof it.feed_override === 'number') {
      $('feed-override-cell').textContent = `${Math.round(it.feed_override * 100)} %`;
      if (!S.sliderBusy && document.activeElement !== $('feed-override')) {
        $('feed-override').value = Math.round(it.feed_override * 100);
        $('feed-override-out').textContent = `${Math.round(it.feed_override * 100)} %`;
      }
    }
    if (typeof it.rapid_override === 'number') {
      $('rapid-override-cell').textContent = `${Math.round(it.rapid_override * 100)} %`;
      if (document.activeElement !== $('rapid-override')) {
        $('rapid-override').value = Math.round(it.rapid_override * 100);
        $('rapid-override-out').textContent = `${Math.round(it.rapid_override * 100)} %`;
      }
    }
    for (const [id, on] of [['sw-single-block', it.single_block], ['sw-optional-stop', it.optional_stop],
      ['sw-block-delete', pg.block_delete]]) {
      if (typeof on === 'boolean' && document.activeElement !== $(id)) $(id).checked = on;
    }
    showMachine(m.machine, it);
    const line = typeof m.line === 'number' && m.line_in_program !== false ? m.line : -1;
    $('line-no').textContent = line >= 0 ? line : '—';
    highlight(line);
    const sv = $('services'); sv.innerHTML = '';
    for (const [name, s] of Object.entries(m.services || {})) {
      const d = document.createElement('span'); d.title = `${name}: ${s.state}, ${s.age} s ago`;
      if (s.lost || s.state !== 'running') d.className = 'lost';
      sv.appendChild(d);
    }
    const x = m.axes[0] && m.axes[0].act, y = m.axes[1] && m.axes[1].act;
    const z = m.axes[2] && m.axes[2].act;
    if (window.preview3d && typeof x === 'number' && typeof y === 'number') {
      const p3 = window.preview3d, running = pg.state === 'running' || pg.state === 'held';
      p3.setTool([x, y, typeof z === 'number' ? z : 0]);
      if (pg.token !== S.progressToken || (pg.state === 'loaded' && p3.progress > 0)) {
        S.progressToken = pg.token;
        p3.setProgress(0);
      }
      if (running && pg.token === S.previewToken) p3.follow([x, y, z || 0], line, true);
      if (pg.state === 'done' && pg.token === S.previewToken && p3.points && p3.progress < p3.points.length / 3 - 1)
        p3.setProgress(p3.points.length / 3 - 1);
    } else if (typeof x === 'number' && typeof y === 'number') {
      const last = S.trail[S.trail.length - 1];
      if (!last || Math.abs(last[0] - x) + Math.abs(last[1] - y) > 0.01) {
        S.trail.push([x, y]);
        if (S.trail.length > 3000) S.trail.shift();
      }
      drawPreview([x, y]);
    }
  },
  program(m) {
    $('program-name').textContent = m.name || '';
    const box = $('program-text');
    box.innerHTML = '';
    const lines = (m.text || '').split('\n');
    if (lines.length && lines[lines.length - 1] === '') lines.pop();
    const frag = document.createDocumentFragment();
    lines.forEach((t, i) => {
      const d = document.createElement('div');
      d.id = `L${i + 1}`;
      const ln = document.createElement('span'); ln.className = 'ln'; ln.textContent = i + 1;
      d.appendChild(ln); d.appendChild(document.createTextNode(t));
      frag.appendChild(d);
    });
    box.appendChild(frag);
    S.programLines = lines.length; S.currentLine = -1;
  },
  preview(m) {
    if (m.error) { showMsg(false, `preview: ${m.error}`); return; }
    S.preview = m.points; S.bounds = null; S.trail = [];
    S.previewToken = m.token; S.modes = m.modes || []; S.lastPreview = m;
    window.hmiStats.previewPoints = m.points.length / 3;
    window.hmiStats.previewRapids = (m.rapid || []).reduce((n, r) => n + r, 0);
    if (window.preview3d) window.preview3d.setPath(m.points, m.rapid, m.lines);
    else drawPreview(null);
  },
  offsets(m) { showOffsets(m); },
  alarms(m) { $('alarms-body').innerHTML = ''; for (const a of m.alarms) addAlarm(a); },
  alarm(m) { addAlarm(m); },
  result(m) {
    window.hmiStats.results.push({ id: m.id, ok: m.ok, text: m.text, at: performance.now() });
    showMsg(m.ok, m.text);
  },
  programs(m) { fillPrograms(m.programs); },
  playback(m) {
    // The run's commanded path from its log, animated in the preview at the chosen speed.
    S.preview = m.points; S.bounds = null; S.trail = [];
    if (window.preview3d) { window.preview3d.setPath(m.points, null, m.lines); S.previewToken = -1; }
    S.play = { log: m.log, pts: m.points, times: m.times, lines: m.lines, i: 0,
      speed: Number($('play-speed').value) || 1, t0: performance.now(), duration: m.duration_s };
    window.hmiStats.playbackFrames = 0; window.hmiStats.playbackDone = false;
    $('btn-play-stop').disabled = false;
    requestAnimationFrame(playFrame);
  },
  runs(m) {
    $('runs-dir').textContent = m.dir;
    const body = $('runs-body'); body.innerHTML = '';
    for (const r of m.runs) {
      const tr = document.createElement('tr');
      tr.dataset.log = r.log;
      const t = r.start || r.mtime;
      const date = new Date(t * 1000).toISOString().replace('T', ' ').slice(0, 19);
      const progs = (r.programs || []).map((p) => p.split('/').pop()).join(', ') +
        (r.mdi_lines ? ` (+${r.mdi_lines} MDI)` : '');
      const cells = [r.name, date, `${r.duration_s} s`, progs || '—',
        r.faults ? `${r.alarms} (${r.faults} fault)` : `${r.alarms}`];
      for (const c of cells) { const td = document.createElement('td'); td.textContent = c; tr.appendChild(td); }
      const td = document.createElement('td');
      if (r.report_url) {
        const a = document.createElement('a');
        a.href = r.report_url; a.target = '_blank'; a.rel = 'noopener'; a.textContent = 'open';
        a.className = 'report-link';
        td.appendChild(a);
      }
      const pb = document.createElement('button');
      pb.textContent = 'play'; pb.className = 'small play-run';
      pb.title = 'play the run back in the preview from its log (the machine is not involved)';
      pb.disabled = !S.mayControl;
      pb.onclick = () => send('playback', { log: r.log });
      td.appendChild(pb);
      const b = document.createElement('button');
      b.textContent = r.report_url ? 'again' : 'make'; b.className = 'small make-report';
      b.title = 'cnc-logexport and make_report.py on this log (as ./cnc report)';
      b.disabled = !S.mayControl;
      b.onclick = () => { b.disabled = true; b.textContent = '…'; send('report', { log: r.log }); };
      td.appendChild(b);
      tr.appendChild(td);
      body.appendChild(tr);
    }
  },
};

// The machine panel (spindle, coolant, safety chain, probe, M66, I/O points): built from
// hello's devices, filled from each status's machine.
function buildMachine(d) {
  S.devices = d;
  $('machine-panel').hidden = !d.spindle && !d.points;
  $('spindle-box').hidden = !d.spindle;
  if (d.spindle) {
    $('spindle-override').min = Math.round(d.spindle.min_override * 100);
    $('spindle-override').max = Math.round(d.spindle.max_override * 100);
  }
  $('coolant-box').hidden = !(d.coolant && (d.coolant.mist || d.coolant.flood));
  $('btn-coolant-mist').hidden = !(d.coolant && d.coolant.mist);
  $('btn-coolant-flood').hidden = !(d.coolant && d.coolant.flood);
  $('probe-box').hidden = !d.probe_input;
  const body = $('io-body'); body.innerHTML = '';
  (d.points || []).forEach((p, i) => {
    const tr = document.createElement('tr'); tr.id = `io-${p.name}`;
    for (const [k, v] of [['name', p.name], ['kind', p.kind], ['value', '—'], ['module', p.module], ['role', p.role]]) {
      const td = document.createElement('td'); td.textContent = v;
      if (k === 'value') td.id = `io-value-${i}`;
      tr.appendChild(td);
    }
    // A digital output (M62-M65 P n) switched from here by MDI M64/M65 P n, as an operator would type it.
    const td = document.createElement('td');
    const out = /M62-M65 P(\d+)/.exec(p.role || '');
    if (out) {
      const b = document.createElement('button');
      b.id = `io-toggle-${p.name}`; b.dataset.control = ''; b.textContent = 'toggle';
      b.title = `MDI M64/M65 P${out[1]}`;
      b.onclick = () => send('mdi', { line: `${S.ioValues && S.ioValues[i] ? 'M65' : 'M64'} P${out[1]}` });
      td.appendChild(b);
    }
    tr.appendChild(td);
    body.appendChild(tr);
  });
}

function showMachine(mc, it) {
  const d = S.devices || {};
  if (!mc) return;
  const sp = mc.spindle;
  if (sp) {
    $('spindle-dir').textContent = sp.direction > 0 ? 'forward (M3)' : sp.direction < 0 ? 'reverse (M4)' : 'off (M5)';
    $('spindle-state').textContent = sp.fault ? `fault: ${sp.fault}` : sp.state;
    $('spindle-state').className = 'badge ' + (sp.state === 'fault' ? 'bad' : sp.state === 'running' ? 'ok' : '');
    $('spindle-actual').textContent = sp.actual_rpm.toFixed(0);
    $('spindle-cmd').textContent = sp.commanded_rpm.toFixed(0);
    $('spindle-at-speed').textContent = sp.at_speed ? 'at speed' : 'not at speed';
    $('spindle-load').textContent = sp.load_a.toFixed(2);
  }
  if (typeof it.spindle_override === 'number') {
    const pct = Math.round(it.spindle_override * 100);
    $('spindle-override-cell').textContent = `${pct} %${it.spindle_override_enabled === false ? ' (off: M51 P0)' : ''}`;
    if (document.activeElement !== $('spindle-override')) {
      $('spindle-override').value = pct;
      $('spindle-override-out').textContent = `${pct} %`;
    }
  }
  if (mc.coolant) {
    $('coolant-mist').textContent = mc.coolant.mist ? 'on' : 'off';
    $('coolant-flood').textContent = mc.coolant.flood ? 'on' : 'off';
  }
  const sf = $('safety-box'); sf.innerHTML = '';
  const badge = (id, text, cls, title) => {
    const b = document.createElement('b'); b.id = id; b.textContent = text; b.className = 'badge ' + cls;
    if (title) b.title = title;
    sf.appendChild(b);
  };
  if (d.estop_input && mc.estop) badge('safety-estop', `E-stop ${mc.estop}`, mc.estop === 'ok' ? 'ok' : 'bad', d.estop_input);
  if (d.door_input && mc.door) badge('safety-door', `door ${mc.door}`, mc.door === 'closed' ? 'ok' : 'warn', d.door_input);
  if (d.hard_limits && mc.limit) {
    badge('safety-limit', `limits ${mc.limit}${mc.limit_input ? ' (' + mc.limit_input + ')' : ''}`,
      mc.limit === 'ok' ? 'ok' : 'bad');
  }
  if (d.probe_input) {
    $('probe-input').textContent = `${d.probe_input} ${mc.probe === 1 ? 'touching' : mc.probe === 0 ? 'open' : 'not read'}`;
    const r = mc.probe_result;
    const at = (v) => v.map((x, i) => `${(S.axes[i] || {}).name || i} ${x.toFixed(4)}`).join(' ');
    $('probe-result').textContent = !r ? 'no probing result'
      : `last probing (block ${r.block}, ${r.results} in all): ${r.tripped ? 'tripped at ' + at(r.trip) : 'no contact'}, rest at ${at(r.rest)}`;
  }
  const w = mc.input_wait;
  $('input-wait').hidden = !w && !mc.input_result;
  $('input-wait').textContent = w
    ? `M66 waits on ${w.input} (${w.name}), mode ${w.mode}, ${w.left_s >= 0 ? w.left_s.toFixed(1) + ' s left' : 'no timeout'}`
    : mc.input_result ? `M66 last read (block ${mc.input_result.block}): #5399 = ${mc.input_result.value}` : '';
  S.ioValues = mc.points || [];
  (mc.points || []).forEach((v, i) => {
    const td = $(`io-value-${i}`);
    if (!td) return;
    const p = d.points[i];
    const digital = p.kind.startsWith('digital');
    td.textContent = v === null ? '?' : digital ? String(v) : String(Number(Number(v).toPrecision(4)));
    td.className = v === null ? 'unread' : digital && v ? 'on' : '';
  });
}

function addAlarm(a) {
  const tr = document.createElement('tr');
  tr.className = a.severity;
  const t = new Date(a.utime / 1000);
  const cells = [t.toLocaleTimeString([], { hour12: false }) + '.' + String(t.getMilliseconds()).padStart(3, '0'),
    a.source, a.code, a.text];
  for (const c of cells) { const td = document.createElement('td'); td.textContent = c; tr.appendChild(td); }
  tr.dataset.code = a.code;
  const body = $('alarms-body');
  body.insertBefore(tr, body.firstChild);
  while (body.children.length > 200) body.removeChild(body.lastChild);
}

function fillPrograms(list) {
  const sel = $('program-list'); const keep = sel.value; sel.innerHTML = '';
  for (const p of list || []) { const o = document.createElement('option'); o.value = o.textContent = p; sel.appendChild(o); }
  if (keep) sel.value = keep;
}

function highlight(line) {
  if (line === S.currentLine) return;
  const old = $(`L${S.currentLine}`); if (old) old.classList.remove('current');
  S.currentLine = line;
  const el = $(`L${line}`);
  if (el) {
    el.classList.add('current');
    const box = $('program-text');
    if (el.offsetTop < box.scrollTop + 20 || el.offsetTop > box.scrollTop + box.clientHeight - 40)
      box.scrollTop = el.offsetTop - box.clientHeight / 3;
  }
}

// The large position display: work coordinates (machine minus the active offset),
// machine coordinates and the distance to go, and the active codes with F and S.
// The offset and codes: at the running line of the loaded program, the dry run's
// interpreter state there (preview.modes); between programs, the var file's system and G92.
function modesAt(line) {
  const rows = S.modes || [];
  let lo = 0, hi = rows.length - 1, best = null;
  while (lo <= hi) {
    const mid = (lo + hi) >> 1;
    if (rows[mid][0] <= line) { best = rows[mid]; lo = mid + 1; } else hi = mid - 1;
  }
  return best;
}

function showBigDro(m) {
  const pg = m.program || {}, it = m.interp || {};
  const running = (pg.state === 'running' || pg.state === 'held') && pg.token === S.previewToken;
  const line = typeof m.line === 'number' && m.line_in_program !== false ? m.line : -1;
  const row = running && line > 0 ? modesAt(line) : null;
  if (row) S.lastModes = row;
  let offset, coordName, codes, source;
  const os = S.offsets;
  if (row) {
    offset = S.axes.map((a) => ({ X: row[5][0], Y: row[5][1], Z: row[5][2] }[a.name] || 0));
    codes = row[1];
    coordName = (codes.match(/G5[4-9](\.\d)?/) || ['G54'])[0];
    source = `at line ${line} (the dry run's interpreter)`;
  } else if (os && os.systems) {
    const sys = os.systems[(os.coord || 1) - 1];
    offset = S.axes.map((a, i) => (sys.values[i] || 0) + (os.g92.active ? os.g92.values[i] || 0 : 0));
    coordName = sys.name + (os.g92.active ? ' + G92' : '');
    codes = coordName;
    source = 'between programs: the var file\'s system (the rest at a program\'s line)';
  } else {
    offset = S.axes.map(() => 0); coordName = 'G54'; codes = '—'; source = '';
  }
  $('work-coord').textContent = coordName;
  $('modal-codes').textContent = codes;
  $('modal-source').textContent = source;
  m.axes.forEach((a, i) => {
    const w = S.axes[i] && S.axes[i].wrapped ? wrap360 : (v) => v;
    const set = (k, v) => { const el = $(`big-${a.name}-${k}`); if (el) el.textContent = v; };
    set('work', typeof a.act === 'number' ? fmt(w(a.act - offset[i])) : '—');
    set('mach', fmt(w(a.act)));
    set('dtg', fmt(a.dtg));
  });
  $('f-prog').textContent = row ? row[2].toFixed(0) : '—';
  $('f-act').textContent = typeof m.feed === 'number' ? m.feed.toFixed(0) : '—';
  $('s-prog').textContent = row ? row[3].toFixed(0) : '—';
  const sp = m.machine && m.machine.spindle;
  $('s-act').textContent = sp ? sp.actual_rpm.toFixed(0) : '—';
}

// The work offsets (G54..G59.3, G92) and the tool table, as the var file and the tool
// table hold them; edited by the MDI line AXIS's touch-off would send.
function showOffsets(m) {
  S.offsets = m;
  const names = m.axes || S.axes.map((a) => a.name);
  $('offsets-head').innerHTML = '';
  const hr = document.createElement('tr');
  for (const h of ['', ...names, 'R']) { const th = document.createElement('th'); th.textContent = h; hr.appendChild(th); }
  $('offsets-head').appendChild(hr);
  const body = $('offsets-body'); body.innerHTML = '';
  const rows = (m.systems || []).map((sys) => [sys.name, sys.values, sys.rotation, sys.p === m.coord]);
  if (m.g92) rows.push([`G92${m.g92.active ? '' : ' (off)'}`, m.g92.values, null, false]);
  for (const [name, values, rot, active] of rows) {
    const tr = document.createElement('tr');
    tr.id = `offset-${name.split(' ')[0]}`;
    if (active) tr.className = 'active';
    const cells = [name, ...values.map((v) => v.toFixed(3)), rot === null ? '' : rot.toFixed(1)];
    cells.forEach((c, i) => {
      const td = document.createElement('td'); td.textContent = c;
      if (i > 0 && i <= values.length) td.id = `offset-${name.split(' ')[0]}-${names[i - 1]}`;
      tr.appendChild(td);
    });
    body.appendChild(tr);
  }
  const sel = $('os-system');
  if (!sel.options.length) {
    for (const sys of m.systems || []) { const o = document.createElement('option'); o.value = o.textContent = sys.name; sel.appendChild(o); }
    const ax = $('os-axis');
    for (const n of names) { const o = document.createElement('option'); o.value = o.textContent = n; ax.appendChild(o); }
  }
  const tb = $('tools-body'); tb.innerHTML = '';
  const zi = names.indexOf('Z');
  for (const t of m.tools || []) {
    const tr = document.createElement('tr'); tr.id = `tool-${t.number}`;
    for (const [k, c] of [['n', `T${t.number}`], ['p', t.pocket], ['z', (zi >= 0 ? t.offset[zi] : 0).toFixed(3)],
      ['d', t.diameter.toFixed(3)], ['c', t.comment]]) {
      const td = document.createElement('td'); td.textContent = c; td.id = `tool-${t.number}-${k}`; tr.appendChild(td);
    }
    tb.appendChild(tr);
  }
  $('tools-file').textContent = m.tool_table || '(program.tool_table not set)';
  // Refused while a program runs: said here, and the API refuses it too.
  $('offsets-locked').textContent = m.locked ? `locked: ${m.locked}` : '';
  for (const id of ['btn-set-offset', 'btn-clear-g92', 'btn-set-tool']) $(id).disabled = !S.mayControl || !!m.locked;
  if (m.error) showMsg(false, `offsets: ${m.error}`);
}

function uploadFile() {
  const f = $('upload-file').files[0];
  if (!f) return;
  if (S.maxUpload && f.size > S.maxUpload) {
    showMsg(false, `upload refused: '${f.name}' is ${f.size} bytes, more than hmi.upload_max_bytes (${S.maxUpload})`);
    return;
  }
  f.text().then((text) => {
    send('upload', { name: f.name, text, replace: $('upload-replace').checked });
    $('upload-file').value = '';
  });
}

function buildAxes() {
  const big = $('big-dro-body'); big.innerHTML = '';
  for (const a of S.axes) {
    const tr = document.createElement('tr');
    const name = document.createElement('td'); name.textContent = a.name; tr.appendChild(name);
    for (const k of ['work', 'mach', 'dtg']) {
      const td = document.createElement('td'); td.id = `big-${a.name}-${k}`; td.className = k; td.textContent = '—'; tr.appendChild(td);
    }
    big.appendChild(tr);
  }
  const dro = $('dro-body'); dro.innerHTML = '';
  const jog = $('jog-axes'); jog.innerHTML = '';
  const to = $('to-axis'); to.innerHTML = '';
  for (const a of S.axes) {
    const tr = document.createElement('tr'); tr.id = `dro-${a.name}`;
    const name = document.createElement('td'); name.textContent = a.name; tr.appendChild(name);
    for (const k of ['cmd', 'act', 'fe', 'dtg', 'homed', 'drive']) {
      const td = document.createElement('td'); td.id = `dro-${a.name}-${k}`; td.textContent = '—'; tr.appendChild(td);
    }
    dro.appendChild(tr);
    const row = document.createElement('div'); row.className = 'jog-row';
    const b = document.createElement('b'); b.textContent = a.name; row.appendChild(b);
    const mk = (label, id, title) => {
      const btn = document.createElement('button'); btn.textContent = label; btn.id = id; btn.title = title;
      btn.dataset.control = ''; row.appendChild(btn); return btn;
    };
    mk('−step', `jog-${a.name}-minus`, 'incremental jog by the step, negative').onclick = () => jogStep(a.name, -1);
    mk('+step', `jog-${a.name}-plus`, 'incremental jog by the step, positive').onclick = () => jogStep(a.name, 1);
    const cm = mk('◀ hold', `jog-${a.name}-cminus`, 'continuous jog while held');
    const cp = mk('hold ▶', `jog-${a.name}-cplus`, 'continuous jog while held');
    for (const [btn, dir] of [[cm, -1], [cp, 1]]) {
      btn.addEventListener('pointerdown', (e) => { e.preventDefault(); startJog(a.name, dir); });
      for (const ev of ['pointerup', 'pointerleave', 'pointercancel']) btn.addEventListener(ev, () => stopJog());
    }
    mk('home', `home-${a.name}`, `home ${a.name}`).onclick = () => send('home', { axis: a.name });
    jog.appendChild(row);
    const o = document.createElement('option'); o.value = o.textContent = a.name; to.appendChild(o);
  }
}

function jogFeed() { return Number($('jog-feed').value) || 0; }
function jogStep(axis, dir) {
  send('jog', { axis, value: dir * Number($('jog-step').value), feed: jogFeed(), continuous: false });
}
function startJog(axis, dir) {
  stopJog();
  S.jogAxis = axis;
  send('jog', { axis, value: dir, feed: jogFeed(), continuous: true });
  // The keepalive: the cell stops the jog 0.2 s after the last one (a lost page stops it).
  S.jogTimer = setInterval(() => send('jog_keepalive', { axis }), 50);
}
function stopJog() {
  if (S.jogTimer === null) return;
  clearInterval(S.jogTimer); S.jogTimer = null;
  send('jog_stop', { axis: S.jogAxis });
  S.jogAxis = null;
}
window.addEventListener('blur', stopJog);

function playFrame() {
  const p = S.play;
  if (!p) return;
  const t = (performance.now() - p.t0) / 1000 * p.speed;
  while (p.i + 1 < p.times.length && p.times[p.i + 1] <= t) p.i++;
  const k = p.i, done = k + 1 >= p.times.length;
  let at = [p.pts[3 * k], p.pts[3 * k + 1]];
  if (!done) {  // between two recorded points, by time
    const f = Math.min(1, Math.max(0, (t - p.times[k]) / (p.times[k + 1] - p.times[k] || 1)));
    at = [at[0] + f * (p.pts[3 * k + 3] - at[0]), at[1] + f * (p.pts[3 * k + 4] - at[1])];
  }
  S.playAt = at;
  if (window.preview3d) window.preview3d.setPlay([at[0], at[1], p.pts[3 * k + 2]]);
  window.hmiStats.playbackFrames++;
  $('playback').textContent = `${p.log}: ${Math.min(t, p.duration).toFixed(1)} / ${p.duration.toFixed(1)} s, line ${p.lines[k]}` +
    (done ? ' (end)' : '');
  if (!window.preview3d) drawPreview(null);
  if (done) { window.hmiStats.playbackDone = true; S.play = null; $('btn-play-stop').disabled = true; return; }
  requestAnimationFrame(playFrame);
}

function drawPreview(tool) {
  const cv = $('preview'), g = cv.getContext('2d');
  const w = cv.width, h = cv.height;
  g.clearRect(0, 0, w, h);
  let b = S.bounds;
  if (!b) {
    b = { x0: Infinity, y0: Infinity, x1: -Infinity, y1: -Infinity };
    const p = S.preview || [];
    for (let i = 0; i < p.length; i += 3) {
      b.x0 = Math.min(b.x0, p[i]); b.x1 = Math.max(b.x1, p[i]); b.y0 = Math.min(b.y0, p[i + 1]); b.y1 = Math.max(b.y1, p[i + 1]);
    }
    if (!isFinite(b.x0)) b = { x0: -10, y0: -10, x1: 110, y1: 110 };
    const mx = (b.x1 - b.x0) * 0.08 + 2, my = (b.y1 - b.y0) * 0.08 + 2;
    b = { x0: b.x0 - mx, x1: b.x1 + mx, y0: b.y0 - my, y1: b.y1 + my };
    S.bounds = b;
  }
  if (tool && (tool[0] < b.x0 || tool[0] > b.x1 || tool[1] < b.y0 || tool[1] > b.y1)) {
    S.bounds = { x0: Math.min(b.x0, tool[0] - 5), x1: Math.max(b.x1, tool[0] + 5), y0: Math.min(b.y0, tool[1] - 5), y1: Math.max(b.y1, tool[1] + 5) };
    b = S.bounds;
  }
  const s = Math.min(w / (b.x1 - b.x0), h / (b.y1 - b.y0));
  const X = (x) => (x - b.x0) * s + (w - (b.x1 - b.x0) * s) / 2;
  const Y = (y) => h - ((y - b.y0) * s + (h - (b.y1 - b.y0) * s) / 2);
  g.strokeStyle = '#333a42'; g.lineWidth = 1;
  g.beginPath(); g.moveTo(X(0), 0); g.lineTo(X(0), h); g.moveTo(0, Y(0)); g.lineTo(w, Y(0)); g.stroke();
  const p = S.preview;
  if (p && p.length >= 6) {
    g.strokeStyle = '#5b8fc7'; g.lineWidth = 1.2; g.beginPath(); g.moveTo(X(p[0]), Y(p[1]));
    for (let i = 3; i < p.length; i += 3) g.lineTo(X(p[i]), Y(p[i + 1]));
    g.stroke();
  }
  if (S.trail.length > 1) {
    g.strokeStyle = '#e3a33b'; g.lineWidth = 1.5; g.beginPath(); g.moveTo(X(S.trail[0][0]), Y(S.trail[0][1]));
    for (const q of S.trail) g.lineTo(X(q[0]), Y(q[1]));
    g.stroke();
  }
  if (S.playAt) {
    g.fillStyle = '#4bd16b'; g.beginPath(); g.arc(X(S.playAt[0]), Y(S.playAt[1]), 6, 0, 2 * Math.PI); g.fill();
  }
  if (tool) {
    g.fillStyle = '#ff4b4b'; g.beginPath(); g.arc(X(tool[0]), Y(tool[1]), 5, 0, 2 * Math.PI); g.fill();
  }
  g.fillStyle = '#889'; g.font = '11px sans-serif';
  g.fillText(`XY ${(b.x1 - b.x0).toFixed(0)} × ${(b.y1 - b.y0).toFixed(0)} mm`, 6, 14);
}

function wire() {
  $('btn-start').onclick = () => send('start');
  $('btn-hold').onclick = () => send('hold');
  $('btn-resume').onclick = () => send('resume');
  $('btn-stop').onclick = () => { stopJog(); send('stop'); };
  $('btn-reset').onclick = () => send('reset');
  $('btn-enable').onclick = () => send('enable');
  $('btn-home-all').onclick = () => send('home');
  $('btn-load').onclick = () => send('load', { path: $('program-list').value });
  $('btn-refresh').onclick = () => send('programs');
  $('btn-run-from-line').onclick = () => {
    const n = Number($('rfl-line').value);
    if (Number.isInteger(n) && n >= 1) send('load', { path: $('program-list').value, from_line: n });
  };
  $('btn-confirm').onclick = () => send('confirm');
  for (const [id, action] of [['sw-single-block', 'single_block'], ['sw-optional-stop', 'optional_stop'],
    ['sw-block-delete', 'block_delete']]) {
    $(id).addEventListener('change', () => { send(action, { value: $(id).checked }); $(id).blur(); });
  }
  $('btn-runs').onclick = () => send('runs');
  $('btn-play-stop').onclick = () => { S.play = null; S.playAt = null; $('btn-play-stop').disabled = true; $('playback').textContent = ''; };
  for (const [id, line] of [['btn-coolant-mist', 'M7'], ['btn-coolant-flood', 'M8'], ['btn-coolant-off', 'M9']])
    $(id).onclick = () => send('mdi', { line });
  $('btn-set-offset').onclick = () =>
    send('set_offset', { system: $('os-system').value, values: { [$('os-axis').value]: Number($('os-value').value) } });
  $('btn-clear-g92').onclick = () => send('clear_g92');
  $('btn-set-tool').onclick = () => {
    const msg = { tool: Number($('tl-tool').value), length: Number($('tl-length').value) };
    if ($('tl-diameter').value !== '') msg.diameter = Number($('tl-diameter').value);
    send('set_tool', msg);
  };
  $('upload-file').addEventListener('change', uploadFile);
  for (const b of document.querySelectorAll('[data-view]')) {
    b.onclick = () => { if (window.preview3d) window.preview3d.setView(b.dataset.view); };
  }
  for (const b of document.querySelectorAll('[data-goto]')) {
    b.onclick = () => $(b.dataset.goto).scrollIntoView({ block: 'start' });
  }
  $('btn-touch-off').onclick = () => send('touch_off', { axis: $('to-axis').value, value: Number($('to-value').value) });
  $('mdi-form').onsubmit = (e) => {
    e.preventDefault();
    const line = $('mdi-line').value.trim();
    if (line) send('mdi', { line });
  };
  const slider = $('feed-override');
  slider.addEventListener('input', () => {
    S.sliderBusy = true;
    $('feed-override-out').textContent = `${slider.value} %`;
  });
  slider.addEventListener('change', () => {
    S.sliderBusy = false;
    send('override', { value: Number(slider.value) / 100 });
  });
  const rapid = $('rapid-override');
  rapid.addEventListener('input', () => { $('rapid-override-out').textContent = `${rapid.value} %`; });
  rapid.addEventListener('change', () => send('rapid_override', { value: Number(rapid.value) / 100 }));
  const spindle = $('spindle-override');
  spindle.addEventListener('input', () => { $('spindle-override-out').textContent = `${spindle.value} %`; });
  spindle.addEventListener('change', () => send('spindle_override', { value: Number(spindle.value) / 100 }));
}

// The 3D preview (preview3d.js, a module) may come after this script: until it has
// said whether WebGL works, and without it, the flat XY view is drawn.
function preview3dReady() {
  const p3 = window.preview3d;
  $('preview3d').hidden = !p3; $('preview').hidden = !!p3; $('views').hidden = !p3;
  if (!p3) { drawPreview(null); return; }
  if (S.axes.length) p3.setTravel(S.axes);
  if (S.preview) p3.setPath(S.preview, S.lastPreview && S.lastPreview.rapid, S.lastPreview && S.lastPreview.lines);
}
window.addEventListener('preview3d', preview3dReady);
window.addEventListener('DOMContentLoaded', () => {
  wire(); connect();
  if (window.preview3d !== undefined) preview3dReady(); else drawPreview(null);
});
