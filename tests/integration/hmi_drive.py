#!/usr/bin/python3
"""hmi_drive.py URL OUT_DIR CTL_CMD...: drives cnc-hmi's page in headless Chromium
(Debian's chromium with its chromium-driver, python3-selenium) as an operator would,
for integration.hmi. The cell runs with a users file (user `operator`, password from
$HMI_PASSWORD) and the test's program `square.ngc` in the program directory.

Every wait is on a condition with a generous time limit, never a sleep as
synchronisation. Timings (command to visible effect) are measured in the page: the
click and a MutationObserver on the element that shows the effect, both in the
page's clock. Writes OUT_DIR/*.png and OUT_DIR/timings.json; exit 1 on a failure.
CTL_CMD (cnc-ctl --machine M) injects a fault from outside the page: DRIVE_CMD DISABLE.
"""
import json
import math
import os
import subprocess
import sys
import time

from selenium import webdriver
from selenium.common.exceptions import TimeoutException
from selenium.webdriver.chrome.service import Service
from selenium.webdriver.common.by import By
from selenium.webdriver.support.ui import WebDriverWait

URL, OUT = sys.argv[1], sys.argv[2]
CTL = sys.argv[3:]
VIEW_URL = os.environ.get("HMI_VIEW_URL", "")  # a second cnc-hmi, read_only_without_login
PASSWORD = os.environ["HMI_PASSWORD"]
os.makedirs(OUT, exist_ok=True)
timings = {}
T0 = time.monotonic()


def note(msg):
    print(f"# [{time.monotonic() - T0:5.1f} s] {msg}", file=sys.stderr, flush=True)


def fail(msg):
    note("FAIL: " + msg)
    try:
        shot("failure")
        with open(os.path.join(OUT, "failure.html"), "w") as f:
            f.write(driver.page_source)
    except Exception:  # noqa: BLE001 - the failure itself is what matters
        pass
    sys.exit(1)


def shot(name):
    path = os.path.join(OUT, name + ".png")
    driver.save_screenshot(path)
    note(f"screenshot {path}")


opts = webdriver.ChromeOptions()
opts.binary_location = "/usr/bin/chromium"
# A 1280 x 800 touch panel's screen; WebGL (the 3D preview) in software (SwiftShader).
for a in ("--headless=new", "--no-sandbox", "--use-angle=swiftshader", "--enable-unsafe-swiftshader",
          "--disable-dev-shm-usage", "--no-first-run",
          "--disable-background-networking", "--disable-component-update", "--disable-sync",
          "--window-size=1280,800", f"--user-data-dir={os.path.join(OUT, 'chromium-profile')}"):
    opts.add_argument(a)
driver = webdriver.Chrome(service=Service("/usr/bin/chromedriver"), options=opts)
# The page's viewport exactly the panel's 1280 x 800 (the window's size includes its frame).
driver.execute_cdp_cmd("Emulation.setDeviceMetricsOverride", {"width": 1280, "height": 800, "deviceScaleFactor": 1,
                                                               "mobile": False})
driver.set_script_timeout(60)


def wait(what, cond, timeout=20.0):
    try:
        return WebDriverWait(driver, timeout, poll_frequency=0.05).until(lambda d: cond())
    except TimeoutException:
        fail(f"{what}: not seen within {timeout} s")


def text(el_id):
    return driver.execute_script("const e = document.getElementById(arguments[0]); return e ? e.textContent : null;",
                                 el_id)


def num(el_id):
    try:
        return float(text(el_id))
    except (TypeError, ValueError):
        return None


# In the page: click `button` (or run `action`: a small set of named steps), then watch
# element `el` until the predicate holds; milliseconds from the click to the change, in
# the page's own clock (the frame that shows the change), or -1 after `timeout_ms`.
EFFECT_JS = r"""
const [button, el, kind, value, tol, timeoutMs, done] = arguments;
const t0 = performance.now();
const read = () => { const e = document.getElementById(el); return e ? e.textContent : ''; };
const base = parseFloat(read());
const holds = () => {
  const t = read(), v = parseFloat(t);
  if (kind === 'moves') return isFinite(v) && isFinite(base) && Math.abs(v - base) > tol;
  if (kind === 'near') return isFinite(v) && Math.abs(v - value) <= tol;
  if (kind === 'equals') return t === value;
  if (kind === 'contains') return t.includes(value);
  return false;
};
let finished = false;
const finish = (ms) => { if (finished) return; finished = true; obs.disconnect(); done({ms, text: read()}); };
const obs = new MutationObserver(() => { if (holds()) finish(performance.now() - t0); });
obs.observe(document.body, {subtree: true, childList: true, characterData: true});
setTimeout(() => finish(-1), timeoutMs);
if (button.startsWith('override:')) {
  const s = document.getElementById('feed-override');
  s.value = button.slice(9);
  s.dispatchEvent(new Event('input'));
  s.dispatchEvent(new Event('change'));
} else {
  document.getElementById(button).click();
}
if (holds()) finish(0);
"""


def effect(name, button, el, kind, value=None, tol=0.0, timeout_s=20.0):
    r = driver.execute_async_script(EFFECT_JS, button, el, kind, value, tol, int(timeout_s * 1000))
    if r["ms"] < 0:
        fail(f"{name}: clicking {button} did not show on #{el} within {timeout_s} s ({kind} {value}, "
             f"shows '{r['text']}')")
    timings[name] = round(r["ms"], 1)
    note(f"{name}: {r['ms']:.0f} ms from the click to #{el} = '{r['text']}'")
    return r


# In the page: click a view button of the 3D preview; milliseconds from the click to
# the frame rendered with that view (the preview renders on demand, once a frame).
VIEW_JS = r"""
const [view, done] = arguments;
const st = window.hmiStats, f0 = st.preview3dFrames || 0, t0 = performance.now();
document.getElementById('view-' + view).click();
const poll = () => {
  if (st.preview3dView === view && (st.preview3dFrames || 0) > f0) { done(performance.now() - t0); return; }
  if (performance.now() - t0 > 5000) { done(-1); return; }
  requestAnimationFrame(poll);
};
requestAnimationFrame(poll);
"""

# Upload a file from "this computer" as the file chooser would hand it to the page.
UPLOAD_JS = r"""
const [name, text, replace] = arguments;
const dt = new DataTransfer();
dt.items.add(new File([text], name, {type: 'text/plain'}));
document.getElementById('upload-replace').checked = replace;
const input = document.getElementById('upload-file');
input.files = dt.files;
input.dispatchEvent(new Event('change'));
"""

# The touch layout at this size: no horizontal scrolling, every control the finger
# may use at least 44 px high (the hidden ones not counted), nothing that needs hover.
LAYOUT_JS = r"""
const small = [];
for (const e of document.querySelectorAll('button, .button, select, input:not([type=checkbox]):not([type=file])')) {
  const r = e.getBoundingClientRect();
  if (r.width === 0 && r.height === 0) continue;
  if (r.height < 43.5) small.push(`${e.id || e.textContent.trim() || e.tagName} ${r.height.toFixed(0)}px`);
}
return {scrollWidth: document.documentElement.scrollWidth, width: window.innerWidth, height: window.innerHeight, small};
"""


def last_result():
    return driver.execute_script("const r = window.hmiStats.results; return r.length ? r[r.length - 1] : null;")


def results_since(n):
    return driver.execute_script("return window.hmiStats.results.slice(arguments[0]);", n)


def n_results():
    return driver.execute_script("return window.hmiStats.results.length;")


def wait_result(n0, what, timeout=30.0, ok=True):
    """The first result after n0 whose text matches `what` (a substring); must be ok (or not)."""
    def found():
        for r in results_since(n0):
            if what in r["text"] or (not r["ok"] and ok):
                return r
        return None
    r = wait(f"result '{what}'", found, timeout)
    if r["ok"] != ok:
        fail(f"expected {'success' if ok else 'a refusal'} for '{what}', got: {r['text']}")
    note(f"result: {r['text']}")
    return r


def state(label):
    t = text(f"state-{label}") or ""
    return t.split(" ", 1)[1] if " " in t else t


try:
    # 1. No password: the login page, and a WebSocket without a session is refused.
    driver.get(URL)
    wait("the login page", lambda: driver.find_elements(By.ID, "login-form"))
    if "/login.html" not in driver.current_url:
        fail(f"without a session the browser should land on the login page, got {driver.current_url}")
    shot("01-login")
    ws = driver.execute_async_script("""
      const done = arguments[0];
      const ws = new WebSocket(`ws://${location.host}/ws`);
      ws.onopen = () => { ws.send(JSON.stringify({action: 'jog', axis: 'X', value: 50})); done('opened'); };
      ws.onerror = () => done('refused');
      setTimeout(() => done('timeout'), 5000);""")
    if ws != "refused":
        fail(f"a WebSocket without a session was not refused: {ws}")
    note("no session: the login page; the WebSocket (a jog of X by 50 mm in it) refused")

    # 2. Wrong passwords (a known user, an unknown one): refused, the same page, no hint.
    pages = []
    for user, pw in (("operator", "not-the-password"), ("nobody", PASSWORD)):
        driver.find_element(By.ID, "user").send_keys(user)
        driver.find_element(By.ID, "password").send_keys(pw)
        driver.find_element(By.ID, "login-button").click()
        wait("the refusal", lambda: driver.find_elements(By.ID, "refused"))
        pages.append(driver.find_element(By.ID, "refused").text)
    if pages[0] != pages[1] or pages[0] != "Login refused.":
        fail(f"the refusals differ or hint: {pages}")
    shot("02-login-refused")
    timings["login_refusals"] = 2
    note("2 wrong logins refused with the same text: " + pages[0])

    # 3. Log in.
    driver.find_element(By.ID, "user").send_keys("operator")
    driver.find_element(By.ID, "password").send_keys(PASSWORD)
    driver.find_element(By.ID, "login-button").click()
    wait("the page, connected", lambda: text("conn") == "connected", 20)
    wait("the drives enabled", lambda: text("dro-X-drive") == "enabled" and text("dro-Y-drive") == "enabled", 20)
    wait("a status rate", lambda: driver.execute_script("return window.hmiStats.rate") >= 15, 10)
    x0 = num("dro-X-act")
    if x0 is None or abs(x0) > 0.01:
        fail(f"X should stand at 0 (nothing changed before the login), shows {text('dro-X-act')}")
    note(f"logged in; X at {x0:.3f}: the refused clients changed nothing")
    # 3b. The touch layout on a 1280 x 800 panel; the 3D preview there (WebGL).
    lay = driver.execute_script(LAYOUT_JS)
    if lay["width"] != 1280 or lay["height"] != 800 or lay["scrollWidth"] > lay["width"]:
        fail(f"the page at {lay['width']} x {lay['height']} scrolls sideways: {lay['scrollWidth']} px wide")
    if lay["small"]:
        fail(f"controls lower than 44 px: {lay['small']}")
    if not driver.execute_script("return !!window.preview3d"):
        fail("no 3D preview: " + str(driver.execute_script("return window.preview3dError || 'preview3d.js not run'")))
    note(f"layout at {lay['width']} x {lay['height']}: no sideways scrolling, every control >= 44 px; 3D preview on")
    wait("the login refusals alarm", lambda: driver.execute_script(
        "return document.querySelector('#alarms-body tr[data-code=hmi_login_refused]') !== null"), 10)

    # 4. Home X on its switch, then jog X by +10 mm.
    n0 = n_results()
    effect("home_x_to_mode_shown", "home-X", "mode", "contains", "home", timeout_s=10)
    wait("X homed", lambda: text("dro-X-homed") == "yes", 30)
    wait("homing done", lambda: state("interp") in ("idle", "done") and (text("mode") or "").startswith("program"), 20)
    wait("X back at 0", lambda: abs((num("dro-X-act") or 99)) < 0.005, 10)
    note(f"X homed ({text('dro-X-homed')}) at {text('dro-X-act')}")
    driver.execute_script("document.getElementById('jog-step').value = '10';")
    effect("jog_x_click_to_position_moves", "jog-X-plus", "dro-X-act", "moves", tol=0.001, timeout_s=10)
    wait("X at 10", lambda: abs((num("dro-X-act") or 0) - 10) < 0.005, 20)
    note(f"jogged: X {text('dro-X-act')}")
    shot("03-jogged")

    # 5. Touch off X: this position reads 0 (G10 L20 P0 X0) through the program server.
    driver.execute_script("document.getElementById('to-axis').value = 'X'; document.getElementById('to-value').value = '0';")
    n0 = n_results()
    driver.find_element(By.ID, "btn-touch-off").click()
    wait_result(n0, "touch_off started")
    wait("the touch-off line's end", lambda: state("program") == "done", 20)
    # 5b. The var file's G54 X (10: the touch-off at X 10) in the offsets table, and the
    #     large display's work X (machine minus it) at 0 beside machine X 10.
    wait("G54 X 10 in the offsets", lambda: text("offset-G54-X") == "10.000", 10)
    wait("work X 0, machine X 10", lambda: abs((num("big-X-work") or 99)) < 0.005 and
         abs((num("big-X-mach") or 0) - 10) < 0.005, 5)
    note(f"after the touch-off: G54 X {text('offset-G54-X')}; work X {text('big-X-work')}, machine X {text('big-X-mach')}")
    # 5c. Work offsets and the tool table edited from the page (G10 L2 / G10 L1 as MDI):
    #     the click to the table showing the value the var file / tool table now holds.
    driver.execute_script("document.getElementById('os-system').value = 'G55'; document.getElementById('os-axis').value = 'X';"
                          "document.getElementById('os-value').value = '5.25';")
    effect("set_offset_g55_x_to_table", "btn-set-offset", "offset-G55-X", "equals", "5.250", timeout_s=15)
    driver.execute_script("document.getElementById('tl-tool').value = '1'; document.getElementById('tl-length').value = '12.5';"
                          "document.getElementById('tl-diameter').value = '6';")
    effect("set_tool_1_to_table", "btn-set-tool", "tool-1-z", "equals", "12.500", timeout_s=15)
    if text("tool-1-d") != "6.000":
        fail(f"tool 1's diameter shows {text('tool-1-d')}, expected 6.000")
    # 5d. Upload a program from the browser; the same name again is kept (refused).
    n0 = n_results()
    t_up = driver.execute_script("return performance.now()")
    driver.execute_script(UPLOAD_JS, "uploaded.ngc", "G21 G90\nG0 X5 Y5\nM2\n", False)
    wait_result(n0, "uploaded uploaded.ngc (20 bytes)")
    wait("the upload in the program list", lambda: driver.execute_script(
        "return [...document.getElementById('program-list').options].some(o => o.value === 'uploaded.ngc')"), 5)
    timings["upload_click_to_listed_ms"] = round(driver.execute_script("return performance.now()") - t_up, 1)
    n0 = n_results()
    driver.execute_script(UPLOAD_JS, "uploaded.ngc", "M2\n", False)
    r = wait_result(n0, "exists", ok=False)
    if "kept (replace it on purpose" not in r["text"]:
        fail(f"the second upload of the same name: {r['text']}")
    note(f"upload listed in {timings['upload_click_to_listed_ms']} ms; the same name again refused: {r['text']}")
    # 6. Load and start the program; the highlighted line moves.
    driver.execute_script("document.getElementById('program-list').value = 'square.ngc';")
    n0 = n_results()
    driver.find_element(By.ID, "btn-load").click()
    wait_result(n0, "loaded")
    wait("the program text", lambda: driver.execute_script("return document.querySelectorAll('#program-text div').length") >= 8)
    wait("the preview", lambda: driver.execute_script("return (window.hmiStats.previewPoints || 0) > 4"), 30)
    if driver.execute_script("return window.hmiStats.previewRapids || 0") < 2:
        fail("the preview has no rapid moves (square.ngc starts with G0)")
    for view in ("top", "front", "side", "iso"):
        ms = driver.execute_async_script(VIEW_JS, view)
        if ms < 0:
            fail(f"the 3D view button '{view}' rendered no frame within 5 s")
        timings[f"view_{view}_click_to_frame"] = round(ms, 1)
        if view == "top":
            shot("03b-preview-top")
    note("3D views, click to the frame drawn: " + ", ".join(f"{v} {timings[f'view_{v}_click_to_frame']} ms"
                                                            for v in ("top", "front", "side", "iso")))
    # 6a. A finger orbits the preview (a one-finger drag of 100 px, as a touch panel sends
    #     it) and the mouse wheel zooms it: the camera turns about its target, then nears it.
    cam_js = ("const p = window.preview3d; const c = p.camera.position, t = p.controls.target;"
              "return [c.x - t.x, c.y - t.y, c.z - t.z, window.hmiStats.preview3dFrames || 0];")
    r = driver.execute_script("const r = document.getElementById('preview3d-canvas').getBoundingClientRect();"
                              "return [r.left + r.width / 2, r.top + r.height / 2];")
    cx, cy = r[0], r[1]
    c0 = driver.execute_script(cam_js)
    driver.execute_cdp_cmd("Emulation.setTouchEmulationEnabled", {"enabled": True, "maxTouchPoints": 2})
    t_touch = time.monotonic()
    driver.execute_cdp_cmd("Input.dispatchTouchEvent", {"type": "touchStart", "touchPoints": [{"x": cx, "y": cy}]})
    for k in range(1, 6):
        driver.execute_cdp_cmd("Input.dispatchTouchEvent", {"type": "touchMove", "touchPoints": [{"x": cx + 20 * k, "y": cy}]})
    driver.execute_cdp_cmd("Input.dispatchTouchEvent", {"type": "touchEnd", "touchPoints": []})
    driver.execute_cdp_cmd("Emulation.setTouchEmulationEnabled", {"enabled": False})

    def turned():
        c = driver.execute_script(cam_js)
        dot = sum(a * b for a, b in zip(c[:3], c0[:3]))
        n = (sum(a * a for a in c[:3]) * sum(a * a for a in c0[:3])) ** 0.5
        return math.degrees(math.acos(max(-1.0, min(1.0, dot / n)))) if c[3] > c0[3] else 0.0
    wait("the finger's drag turns the 3D view", lambda: turned() > 5, 5)
    timings["finger_drag_100px_turn_deg"] = round(turned(), 1)
    timings["finger_drag_to_frame_ms"] = round((time.monotonic() - t_touch) * 1000, 1)
    d0 = math.dist(driver.execute_script(cam_js)[:3], (0, 0, 0))
    driver.execute_cdp_cmd("Input.dispatchMouseEvent", {"type": "mouseWheel", "x": cx, "y": cy, "deltaX": 0, "deltaY": -500})
    wait("the wheel zooms the 3D view in", lambda: math.dist(driver.execute_script(cam_js)[:3], (0, 0, 0)) < 0.9 * d0, 5)
    d1 = math.dist(driver.execute_script(cam_js)[:3], (0, 0, 0))
    note(f"3D preview: a one-finger drag of 100 px turned the view {timings['finger_drag_100px_turn_deg']} deg "
         f"({timings['finger_drag_to_frame_ms']} ms from the touch to the frame, the CDP calls included); "
         f"the wheel zoomed from {d0:.0f} to {d1:.0f} mm from the target")
    driver.execute_async_script(VIEW_JS, "iso")
    effect("start_click_to_running", "btn-start", "state-interp", "contains", "running", timeout_s=10)
    wait("line 5 highlighted", lambda: text("line-no") == "5", 20)
    t_line = time.monotonic()
    f_line = driver.execute_script("return [window.hmiStats.status, performance.now()]")
    wait("the highlight moves to line 6", lambda: text("line-no") == "6", 20)
    f_end = driver.execute_script("return [window.hmiStats.status, performance.now()]")
    # The display rate while the program runs (no screenshot in between: one stalls the page).
    timings["display_rate_hz_running"] = round((f_end[0] - f_line[0]) / ((f_end[1] - f_line[1]) / 1000.0), 1)
    note(f"position display while running: {f_end[0] - f_line[0]} frames in {(f_end[1] - f_line[1]) / 1000:.2f} s"
         f" = {timings['display_rate_hz_running']} Hz")
    if timings["display_rate_hz_running"] < 20:
        fail(f"display rate while running {timings['display_rate_hz_running']} Hz < 20 Hz")
    # The highlight and the line number read in one frame: on a slow page the program
    # may be past line 6 by now, and the highlight must follow it there.
    hl, line_no = driver.execute_script(
        "const e = document.querySelector('#program-text div.current');"
        "return [e ? e.id : null, document.getElementById('line-no').textContent];")
    if not line_no.isdigit() or int(line_no) < 6 or hl != f"L{line_no}":
        fail(f"the highlighted program line is {hl} while line {line_no} runs (expected L{line_no}, from line 6 on)")
    note(f"highlight moved 5 -> 6 ({time.monotonic() - t_line:.1f} s: 40 mm at 10 mm/s)")
    # 6b. While it runs: the active codes and F and S at the running line (the dry run's
    #     interpreter), the offsets locked (the page says so, the API refuses), and the 3D
    #     preview's part already run growing along the path.
    codes = text("modal-codes") or ""
    for want in ("G1 ", "G17", "G21", "G54", "G90", "M3", "M8"):
        if want not in codes:
            fail(f"the active codes while line {text('line-no')} runs: '{codes}' has no {want}")
    if text("f-prog") != "600" or text("s-prog") != "6000":
        fail(f"F and S programmed show {text('f-prog')} and {text('s-prog')}, expected 600 and 6000")
    wait("the offsets locked", lambda: "a program runs" in (text("offsets-locked") or ""), 5)
    if driver.execute_script("return !document.getElementById('btn-set-offset').disabled"):
        fail("the offset's Set button is enabled while a program runs")
    n0 = n_results()
    driver.execute_script("send('set_offset', {system: 'G54', values: {X: 1}})")
    r = wait_result(n0, "set_offset refused", ok=False)
    if "a program runs" not in r["text"]:
        fail(f"set_offset while running: {r['text']}")
    d0 = driver.execute_script("return window.hmiStats.preview3dDone || 0")
    wait("the run part of the 3D path grows", lambda: driver.execute_script("return window.hmiStats.preview3dDone || 0") > d0 + 5, 5)
    note(f"running: codes '{codes}', F {text('f-prog')}/{text('f-act')}, S {text('s-prog')}/{text('s-act')}; "
         f"offsets locked ('{r['text']}'); 3D path run to point {driver.execute_script('return window.hmiStats.preview3dDone')}"
         f" of {driver.execute_script('return window.hmiStats.previewPoints')} ({driver.execute_script('return window.hmiStats.previewRapids')} rapid)")
    driver.execute_script("document.getElementById('left').scrollTop = 0; document.getElementById('right').scrollTop = 0;")
    shot("04-running")

    # 7. Hold: the feed shown drops to 0 and the position stands.
    effect("hold_click_to_feed_0", "btn-hold", "feed", "equals", "0", timeout_s=10)
    wait("held", lambda: state("interp") == "held", 10)
    y1 = num("dro-Y-act")
    s0 = driver.execute_script("return window.hmiStats.status")
    wait("0.5 s of status while held", lambda: driver.execute_script("return window.hmiStats.status") >= s0 + 12, 10)
    y2 = num("dro-Y-act")
    if abs(y2 - y1) > 0.005:
        fail(f"held, but Y moved from {y1} to {y2}")
    note(f"held: Y stands at {y2:.3f} ({abs(y2 - y1) * 1000:.1f} um over 12 status frames)")
    timings["held_motion_um"] = round(abs(y2 - y1) * 1000, 2)
    shot("05-held")
    effect("resume_click_to_feed", "btn-resume", "feed", "near", 600, 1.0, timeout_s=10)

    # 8. Feed override 50 %: the feed shown follows (600 -> 300 mm/min).
    effect("override_50_to_feed_300", "override:50", "feed", "near", 300, 3.0, timeout_s=10)
    if text("feed-override-cell") != "50 %":
        wait("the cell's override 50 %", lambda: text("feed-override-cell") == "50 %", 5)
    effect("override_100_to_feed_600", "override:100", "feed", "near", 600, 3.0, timeout_s=10)
    # 8b. The rapid override slider is enabled and sends RAPID_OVERRIDE (50 %, back to 100 %).
    if not driver.find_element(By.ID, "rapid-override").is_enabled():
        fail("the rapid override slider is disabled")
    for pct in (50, 100):
        n0 = n_results()
        driver.execute_script("const s = document.getElementById('rapid-override'); s.value = arguments[0];"
                              "s.dispatchEvent(new Event('input')); s.dispatchEvent(new Event('change'));", pct)
        wait_result(n0, "rapid_override sent", 10)
        # The cell reports it back (INTERP_STATE.rapid_override), shown beside the slider.
        wait("the cell's rapid override %d %%" % pct, lambda: text("rapid-override-cell") == "%d %%" % pct, 5)
    # 8c. The machine panel (a spindle, the I/O module io1 with the E-stop and the door):
    #     the program's M3 S6000 M8 shown; the spindle override slider sends
    #     SPINDLE_OVERRIDE (80 %: 4800 rpm commanded, back to 100 %); the safety chain
    #     and every I/O point by its config name with its value.
    wait("the spindle at 6000 rpm", lambda: text("spindle-dir") == "forward (M3)" and text("spindle-cmd") == "6000"
         and abs((num("spindle-actual") or 0) - 6000) < 150, 10)
    wait("flood coolant on", lambda: text("coolant-flood") == "on" and text("coolant-mist") == "off", 5)
    for pct, rpm in ((80, "4800"), (100, "6000")):
        n0 = n_results()
        driver.execute_script("const s = document.getElementById('spindle-override'); s.value = arguments[0];"
                              "s.dispatchEvent(new Event('input')); s.dispatchEvent(new Event('change'));", pct)
        wait_result(n0, "spindle_override sent", 10)
        wait("the cell's spindle override %d %%" % pct, lambda: text("spindle-override-cell") == "%d %%" % pct, 5)
        wait("the spindle commanded %s rpm" % rpm, lambda: text("spindle-cmd") == rpm, 5)
    for el_id, want in (("safety-estop", "E-stop ok"), ("safety-door", "door closed")):
        if text(el_id) != want:
            fail(f"the machine panel's {el_id} reads {text(el_id)!r}, expected {want!r}")
    io = driver.execute_script("return [...document.querySelectorAll('#io-body tr')].map("
                               "r => [...r.children].map(c => c.textContent));")
    rows = {r[0]: r for r in io}
    if len(io) != 5 or rows.get("estop_ok", [None] * 6)[1:5] != ["digital in", "1", "io1", "E-stop"] or \
            rows.get("coolant_flood", [None] * 6)[1:5] != ["digital out", "1", "io1", "M8 flood"] or \
            rows.get("lamp", [None] * 6)[1:6] != ["digital out", "0", "io1", "M62-M65 P0", "toggle"] or \
            rows.get("door_closed", [None] * 5)[4] != "door":
        fail(f"the I/O points on the page: {io}")
    note(f"machine panel: spindle {text('spindle-actual')} rpm {text('spindle-at-speed')}, load {text('spindle-load')} A,"
         f" override 80 % -> 4800 rpm and back, flood on, {len(io)} I/O points named, safety chain shown")
    driver.execute_script("document.getElementById('machine-panel').scrollIntoView({block: 'start'});")
    shot("05b-machine")

    # 9. Stop.
    effect("stop_click_to_stopped", "btn-stop", "state-program", "contains", "stopped", timeout_s=10)
    wait("the interpolator stands", lambda: state("interp") in ("idle", "done"), 10)
    # 9a. Coolant and an output from the machine panel (MDI M8, M9; M64, M65 P0): the
    #     STOP turned the flood off; the flood button turns it on and it stays on (an MDI
    #     line's end is no program end) until the off button; the lamp's toggle twice.
    wait("the flood off after STOP", lambda: text("coolant-flood") == "off", 10)
    for button, el, want in (("btn-coolant-flood", "coolant-flood", "on"), ("btn-coolant-off", "coolant-flood", "off")):
        n0 = n_results()
        driver.find_element(By.ID, button).click()
        wait_result(n0, "mdi started", 10)
        wait(f"{el} {want}", lambda: text(el) == want, 10)
    lamp = driver.execute_script("return [...document.querySelectorAll('#io-body tr')].findIndex(r => r.id === 'io-lamp');")
    for want in ("1", "0"):
        n0 = n_results()
        driver.find_element(By.ID, "io-toggle-lamp").click()
        wait_result(n0, "mdi started", 10)
        wait(f"the lamp reads {want}", lambda: text(f"io-value-{lamp}") == want, 10)
    note("machine panel: flood on and off, the lamp output on and off, each by MDI from the page")

    # 9b. Single block from the page: switched on (the cell confirms it in INTERP_STATE),
    #     the program loaded again; START runs one line and holds, each RESUME one more:
    #     three single steps, the highlight one line further each.
    def cell(path):
        return driver.execute_script("let v = window.hmiStats.last; for (const k of arguments[0]) v = v && v[k];"
                                     " return v === undefined ? null : v;", path)
    n0 = n_results()
    driver.find_element(By.ID, "sw-single-block").click()
    wait_result(n0, "single-block on sent")
    wait("single block on in the cell", lambda: cell(["interp", "single_block"]) is True, 10)
    n0 = n_results()
    driver.find_element(By.ID, "btn-load").click()
    wait_result(n0, "loaded")
    n0 = n_results()
    driver.find_element(By.ID, "btn-start").click()
    wait("the first line run, held", lambda: n_results() > n0 and state("interp") == "held" and text("line-no") != "—", 20)
    line0 = int(text("line-no"))
    steps = []
    for k in (1, 2, 3):
        t_step = time.monotonic()
        driver.find_element(By.ID, "btn-resume").click()
        wait(f"single step {k}", lambda: state("interp") == "held" and text("line-no") == str(line0 + k), 20)
        hl = driver.execute_script("const e = document.querySelector('#program-text div.current'); return e ? e.id : null;")
        if hl != f"L{line0 + k}":
            fail(f"single step {k}: highlighted {hl}, not L{line0 + k}")
        steps.append(round(time.monotonic() - t_step, 2))
    timings["single_steps_s"] = steps
    note(f"single block: held before line {line0}, then {line0 + 1}, {line0 + 2}, {line0 + 3} ({steps} s a step)")
    shot("06-single-block")
    n0 = n_results()
    driver.find_element(By.ID, "sw-single-block").click()
    wait_result(n0, "single-block off sent")
    wait("single block off in the cell", lambda: cell(["interp", "single_block"]) is False, 10)
    driver.find_element(By.ID, "btn-stop").click()
    wait("stopped again", lambda: state("program") == "stopped" and state("interp") in ("idle", "done"), 10)

    # 9c. Run from line 8 ("G1 X40" after the move to X0 Y10): the cell shows the approach
    #     and waits; START is refused until Confirm; then the path runs lines 8 and 9 and
    #     the program ends.
    driver.find_element(By.ID, "rfl-line").clear()
    driver.find_element(By.ID, "rfl-line").send_keys("8")
    n0 = n_results()
    t_rfl = time.monotonic()
    driver.find_element(By.ID, "btn-run-from-line").click()
    wait_result(n0, "loaded")
    wait("the approach shown", lambda: driver.execute_script(
        "return !document.getElementById('approach-box').hidden && !document.getElementById('btn-confirm').hidden"), 15)
    timings["run_from_line_click_to_approach_shown_ms"] = round((time.monotonic() - t_rfl) * 1000, 1)
    approach = text("approach")
    note(f"run from line 8: approach shown: {approach}")
    if text("approach-line") != "8":
        fail(f"the approach names line {text('approach-line')}, not 8")
    shot("06b-run-from-line-approach")
    n0 = n_results()
    driver.find_element(By.ID, "btn-start").click()
    wait_result(n0, "start refused", ok=False)
    if state("interp") == "running":
        fail("START before the confirm moved the machine")
    note(f"START before the confirm refused: {last_result()}")
    n0 = n_results()
    driver.find_element(By.ID, "btn-confirm").click()
    wait_result(n0, "confirm sent")
    wait("the confirm taken", lambda: driver.execute_script("return document.getElementById('btn-confirm').hidden"), 10)
    driver.find_element(By.ID, "btn-start").click()
    wait("line 9 runs", lambda: text("line-no") == "9", 60)
    wait("the program from line 8 done", lambda: state("program") == "done", 60)
    timings["run_from_line_total_s"] = round(time.monotonic() - t_rfl, 1)
    note(f"run from line 8 ran to its end ({timings['run_from_line_total_s']} s from the click)")

    # 10. MDI a slow move, a fault injected from outside during it (DRIVE_CMD DISABLE by
    #     cnc-ctl), the alarm shown; Reset from the page.
    driver.find_element(By.ID, "mdi-line").send_keys("G1 Y100 F300")
    n0 = n_results()
    driver.find_element(By.ID, "btn-mdi").click()
    wait_result(n0, "mdi started")
    wait("the MDI move", lambda: state("interp") == "running", 10)
    subprocess.run(CTL + ["--do", "disable"], check=True, timeout=20)
    t_inj = time.monotonic()
    wait("the fault alarm", lambda: driver.execute_script(
        "return document.querySelector('#alarms-body tr.fault') !== null"), 10)
    timings["injected_fault_to_alarm_shown_ms"] = round((time.monotonic() - t_inj) * 1000, 1)
    alarm = driver.execute_script("const r = document.querySelector('#alarms-body tr.fault'); return r.textContent;")
    note(f"alarm shown: {alarm}")
    wait("FAULT", lambda: state("interp") == "fault", 10)
    shot("07-alarm")
    n0 = n_results()
    effect("reset_click_to_interp_idle", "btn-reset", "state-interp", "contains", "idle", timeout_s=30)
    wait_result(n0, "reset:")
    wait("drives enabled again", lambda: all(text(f"dro-{a}-drive") == "enabled" for a in "XYZ"), 10)
    shot("08-reset")

    # The display rate over the session so far (the report's page below leaves it).
    st = driver.execute_script("return {n: window.hmiStats.status, ms: performance.now() - window.hmiStats.since,"
                               " min: window.hmiStats.minRate || 0};")
    timings["status_frames"] = st["n"]
    timings["display_rate_hz_mean"] = round(st["n"] / (st["ms"] / 1000.0), 1)
    timings["display_rate_hz_min_1s_incl_screenshots"] = st["min"]
    note(f"position display: {st['n']} frames in {st['ms'] / 1000:.1f} s = {timings['display_rate_hz_mean']} Hz mean, "
         f"lowest 1 s window {st['min']} Hz (screenshots stall the page)")

    # 11. Run analysis: the runs directory (this session's log, still being written), its
    #     summary, and its report made and opened (./cnc report's steps), machine untouched.
    driver.find_element(By.ID, "btn-runs").click()
    row = "#runs-body tr[data-log='cell.lcmlog']"
    wait("the session's run listed", lambda: driver.execute_script(f"return document.querySelector(\"{row}\") !== null"), 30)
    cells = driver.execute_script(f"return [...document.querySelector(\"{row}\").children].map(c => c.textContent)")
    note(f"run listed: {cells}")
    if "square.ngc" not in cells[3] or "MDI" not in cells[3]:
        fail(f"the run's programs should name square.ngc and the MDI lines: {cells[3]}")
    if not cells[4].split(" ")[0].isdigit() or int(cells[4].split(" ")[0]) < 3 or "fault" not in cells[4]:
        fail(f"the run's alarms should count the session's (a fault among them): {cells[4]}")
    n0 = n_results()
    t_rep = time.monotonic()
    driver.execute_script(f"document.querySelector(\"{row} button.make-report\").click()")
    wait_result(n0, "report of cell.lcmlog ready", timeout=90)
    timings["report_made_s"] = round(time.monotonic() - t_rep, 1)
    wait("the report link", lambda: driver.execute_script(
        f"return document.querySelector(\"{row} a.report-link\") !== null"), 20)
    shot("09-runs")
    # Playback of the run in the preview from its log, at 20x: the green dot goes along
    # the recorded path to its end; the machine is not involved (the interpolator stays idle).
    driver.execute_script("document.getElementById('play-speed').value = '20';")
    driver.execute_script(f"document.querySelector(\"{row} button.play-run\").click()")
    wait("the playback started", lambda: driver.execute_script("return (window.hmiStats.playbackFrames || 0) >= 10"), 30)
    shot("09b-playback")
    wait("the playback to its end", lambda: driver.execute_script("return window.hmiStats.playbackDone === true"), 60)
    pb = driver.execute_script("return [window.hmiStats.playbackFrames, document.getElementById('playback').textContent]")
    if pb[0] < 5:
        fail(f"playback drew {pb[0]} frames")
    if state("interp") not in ("idle", "done"):
        fail(f"the playback moved the machine? interpolator {state('interp')}")
    timings["playback_frames"] = pb[0]
    note(f"playback of the run at 20x: {pb[0]} frames, '{pb[1]}', interpolator {state('interp')}")
    href = driver.execute_script(f"return document.querySelector(\"{row} a.report-link\").href")
    driver.get(href)
    wait("the report's plots shown", lambda: driver.execute_script(
        "return [...document.images].filter(i => i.complete && i.naturalWidth > 0).length") >= 3, 20)
    imgs_ok = driver.execute_script(
        "return [...document.images].filter(i => i.complete && i.naturalWidth > 0).length")
    note(f"report opened from the page: {href}, {imgs_ok} plots, made in {timings['report_made_s']} s")
    shot("10-report")
    driver.back()
    wait("back on the page", lambda: text("conn") == "connected", 20)

    # 12. A second cnc-hmi with read_only_without_login (VIEW_URL): without a login the
    #     page shows the machine, every control disabled, and an action sent anyway is refused.
    if VIEW_URL:
        driver.delete_all_cookies()
        driver.get(VIEW_URL)
        wait("the view-only page", lambda: text("conn") == "connected" and text("who") == "view only", 20)
        wait("its status", lambda: num("dro-X-act") is not None, 10)
        disabled = driver.execute_script(
            "return [...document.querySelectorAll('[data-control]')].every(e => e.disabled)")
        if not disabled:
            fail("view only: some control is enabled")
        x_before = num("dro-X-act")
        r = driver.execute_async_script("""
          const done = arguments[0];
          const ws = new WebSocket(`ws://${location.host}/ws`);
          ws.onmessage = (ev) => { const m = JSON.parse(ev.data); if (m.t === 'result') done(m.text); };
          ws.onopen = () => ws.send(JSON.stringify({id: 1, action: 'jog', axis: 'X', value: 5}));
          setTimeout(() => done('no answer'), 5000);""")
        if r != "view only: log in to operate the machine":
            fail(f"view only: a jog sent anyway was answered '{r}'")
        s0 = driver.execute_script("return window.hmiStats.status")
        wait("0.5 s of status", lambda: driver.execute_script("return window.hmiStats.status") >= s0 + 12, 10)
        if abs((num("dro-X-act") or 1e9) - x_before) > 0.001:
            fail(f"view only: X moved from {x_before} to {text('dro-X-act')}")
        note(f"view only without login: controls disabled, a jog sent anyway refused ('{r}'), X stays {x_before:.3f}")
        shot("11-view-only")
finally:
    with open(os.path.join(OUT, "timings.json"), "w") as f:
        json.dump(timings, f, indent=1)
    driver.quit()
print(json.dumps(timings))
